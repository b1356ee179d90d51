"""A smooth end stop of the stroke is a saturation, not a sensor curve.

An end stop leaves most of the range straight and flattens one end; a sensor's calibration curve
bends the whole range. Both act after the dynamics, so the data tell them apart by the shape of the
bend only. The logs are written here from P(s) (scipy's ZOH, `designs._simulate`) and a ``tanh`` knee
(not the library's exponential stop), or a bow over the whole range for the control.
"""
from __future__ import annotations

import numpy as np
import pytest
from scipy import signal

import designs
from hasel import paper
from hasel.diagnose import diagnose
from hasel.effects.base import EffectFit
from hasel.effects.saturation import end_stop, stop_map

RATE_HZ = 1000.0


def _stroke(seed: int, dur_s: float = 40.0) -> tuple[np.ndarray, np.ndarray]:
    """Random voltage levels (2-6.5 kV, held 20-200 ms) and P(s)'s stroke (mm)."""
    u = designs.random_levels(np.random.default_rng(seed), int(dur_s * RATE_HZ), 2.0, 6.5)
    return u, designs._simulate(u, RATE_HZ)


def _model() -> dict:
    num, den = paper.plant_tf()
    return {"num": num.tolist(), "den": den.tolist()}


def test_the_stop_is_a_line_up_to_the_knee_and_flattens_towards_its_limit():
    z = np.linspace(0.0, 12.0, 1201)
    y = end_stop(z, 7.0, 0.5)
    assert np.allclose(y[z <= 7.0], z[z <= 7.0], rtol=0, atol=1e-12)
    assert y.max() < 7.5 and y[-1] > 7.5 - 1e-4  # approaches knee + room, never beyond
    slope = np.gradient(y, z)
    assert abs(slope[700] - 1.0) < 0.02 and np.all(np.diff(slope[700:]) <= 1e-9)  # no kink, ever flatter
    low = end_stop(z, 3.0, 0.5, upper=False)
    assert np.allclose(low[z >= 3.0], z[z >= 3.0], rtol=0, atol=1e-12) and low.min() > 2.5
    f = EffectFit("saturation", "output:stop_upper", (7.0, 0.5, 2.0, -1.0))
    assert np.allclose(stop_map(z, f), 2.0 * y - 1.0)


@pytest.mark.parametrize("seed,knee_mm,room_mm", [(1, 6.6, 0.5), (2, 6.2, 0.9)])
def test_a_tanh_end_stop_of_the_stroke_is_named_saturation(seed, knee_mm, room_mm):
    rng = np.random.default_rng(100 + seed)
    u, z = _stroke(seed)
    y = np.where(z <= knee_mm, z, knee_mm + room_mm * np.tanh((z - knee_mm) / room_mm))
    y = y + 0.005 * rng.standard_normal(y.size)
    v = diagnose(np.arange(u.size) / RATE_HZ, u, y, model=_model(), units=("kV", "mm"))
    assert v.names == ["saturation"]
    p = v.effects[0]["params"]
    assert p["variant"] == "output:stop_upper"
    # the stop's limit is where the tanh knee goes (knee + room), within a third of the room
    assert abs(p["limit"] - (knee_mm + room_mm)) < room_mm / 3
    assert v.heldout["gap_shrink"] > 0.9


def test_a_bow_over_the_whole_range_stays_a_sensor_curve():
    rng = np.random.default_rng(7)
    u, z = _stroke(3)
    y = z + 0.35 * np.sin(np.pi * z / 9.0) + 0.005 * rng.standard_normal(z.size)
    v = diagnose(np.arange(u.size) / RATE_HZ, u, y, model=_model(), units=("kV", "mm"))
    assert v.names == ["sensor_nonlinearity"]


def test_beside_a_load_the_stop_leaves_the_load_most_of_what_is_left():
    """The independent simulator's tanh stroke knee (5.8 mm, 0.4 mm room) and a heavier mode at 500 Hz
    (``test_diagnose_combos``'s log): with the hard clip the knee left 19 times the floor's energy and the
    load removed 45 % of it; the stop leaves the load 80 %."""
    from hasel_bench.othersim import ForeignEffect, excitation, simulate

    rng = np.random.default_rng(4)
    u, _ = excitation(rng, 500.0, short=True)
    effs = [ForeignEffect("saturation", "soft_stroke", {"knee_mm": 5.8, "room_mm": 0.4}),
            ForeignEffect("load_mass", "heavier_mode", {"mass_ratio": 1.1})]
    y = simulate(u, 500.0, effs) + 0.004 * rng.standard_normal(u.size)
    v = diagnose(np.arange(u.size) / 500.0, u, y, model=_model(), units=("kV", "mm"))
    assert v.names == ["saturation", "load_mass"]
    assert v.effects[0]["params"]["variant"] == "output:stop_upper"
    second = next(r for r in v.rounds if r.get("round") == 2)
    assert second["gain"] > 0.7
    assert v.heldout["gap_shrink"] > 0.97


@pytest.mark.parametrize("seed,noise", [(5, "white"), (6, "ar1")])
def test_hard_stops_at_both_ends_with_noise_after_them_are_one_saturation(seed, noise):
    """The stroke clipped hard at both ends (its 12 % and 88 % quantiles), the sensor's noise after the clip (white,
    or AR(1) with a 10 Hz corner: nothing piles on one measured value): named ``saturation`` alone, of the two-sided
    output form, both limits within 0.05 mm, the held-out gap cut by more than 80 %. Before the form one end was
    fitted and the other left (``forms3.py`` seed 1, ``zstop2``: shrink 0.12)."""
    rng = np.random.default_rng(200 + seed)
    u, z = _stroke(seed)
    lo, hi = np.quantile(z, [0.12, 0.88])
    e = rng.standard_normal(z.size)
    if noise == "ar1":
        a = np.exp(-2 * np.pi * 10.0 / RATE_HZ)
        e = signal.lfilter([np.sqrt(1 - a * a)], [1.0, -a], e)
    y = np.clip(z, lo, hi) + 0.005 * e
    v = diagnose(np.arange(u.size) / RATE_HZ, u, y, model=_model(), units=("kV", "mm"))
    assert v.names == ["saturation"]
    p = v.effects[0]["params"]
    assert p["variant"] == "output:both"
    assert abs(p["lower"] - lo) < 0.05 and abs(p["upper"] - hi) < 0.05
    assert v.heldout["gap_shrink"] > 0.8
