"""The ``load_mass`` family's anti-resonance (``model:notch``) and pole-zero pair (``model:pair``) forms.

A load may move P(s)'s anti-resonance (the counter-motion of its mount) or add a lightly damped pole-zero pair
below the resonance (a payload swinging on its mount). The forms that move or add pole pairs fit neither: on
``bench/tune_diag/forms3.py`` seed 1 both were named nothing at 10-18x the noise floor. The truths here are
written from the transfer functions (scipy's ZOH through :func:`designs.multisine_through`), not with the
library's load code.
"""
from __future__ import annotations

import math

import designs
import numpy as np
import pytest
from scipy import signal

from hasel import paper
from hasel.diagnose import diagnose
from hasel.effects import load
from hasel.effects.base import EffectFit
from hasel.effects.registry import FAMILIES

RATE_HZ = 500.0
F_RES_HZ = paper.P_NOTCH_RAD_S / (2.0 * math.pi)


def _pair_plant(f_hz: float, zp: float, ratio: float, zz: float) -> tuple[np.ndarray, np.ndarray]:
    """P(s) (kV -> mm) times ``(wp/wz)^2 (s^2 + 2 zz wz s + wz^2) / (s^2 + 2 zp wp s + wp^2)``,
    ``wp = 2 pi f_hz``, ``wz = ratio wp``."""
    num, den = paper.plant_tf()
    wp = 2.0 * math.pi * f_hz
    wz = ratio * wp
    g = (wp / wz) ** 2
    return np.polymul(num, [g, g * 2.0 * zz * wz, g * wz * wz]), np.polymul(den, [1.0, 2.0 * zp * wp, wp * wp])


def _notch_plant(k: float, zn: float) -> tuple[np.ndarray, np.ndarray]:
    """P(s) with its undamped zero pair ``s^2 + w^2`` replaced by ``(s^2 + 2 zn (k w) s + (k w)^2) / k^2``."""
    num, den = paper.plant_tf()
    w = paper.P_NOTCH_RAD_S
    q, r = np.polydiv(num, [1.0, 0.0, w * w])
    assert np.max(np.abs(r)) < 1e-6 * np.max(np.abs(num))
    return np.polymul(q, [1.0 / (k * k), 2.0 * zn * w / k, w * w]), den


def _log(plant, seed: int, noise_mm: float = 0.004, dur_s: float = 16.0):
    """:func:`designs.multisine_through` at this file's rate."""
    return designs.multisine_through(plant, seed, RATE_HZ, 0.0, noise_mm, dur_s)


@pytest.mark.parametrize("variant,theta,truth", [
    ("model:pair", (0.0, 1.0, 6.0, 0.06, 1.25, 0.1), lambda: _pair_plant(6.0, 0.06, 1.25, 0.1)),
    ("model:notch", (0.0, 1.0, 0.75, 0.12), lambda: _notch_plant(0.75, 0.12)),
])
def test_the_forms_are_the_truths_plants_and_run_in_chunks(variant, theta, truth):
    """Each form with ``mu`` 0 and ``kappa`` 1 is the truth's transfer function (to 1e-9 of its peak), keeps the
    static gain, names its parameters, and its stage run in two chunks (state carried) gives the whole run."""
    fam = FAMILIES["load_mass"]
    num0, den0 = paper.plant_tf()
    fit = EffectFit("load_mass", variant, theta)
    num1, den1 = fam.transform(num0, den0, fit)
    num2, den2 = truth()
    w = np.geomspace(1.0, 3000.0, 300)
    h1, h2 = signal.freqs(num1, den1, w)[1], signal.freqs(num2, den2, w)[1]
    assert np.max(np.abs(h1 - h2)) < 1e-9 * np.abs(h2).max()
    assert num1[-1] / den1[-1] == pytest.approx(num0[-1] / den0[-1], rel=1e-12)
    names = fam.param_names(fit)
    assert len(names) == len(theta) and names[:2] == ("mass_ratio", "gain_factor")

    class Scales:
        num, den = num0, den0

    u = 4.0 + np.sin(np.arange(900) / 9.0)
    assert designs.chunked_gap(lambda: fam.stage(fit, Scales(), 2e-3), u, 311) < 1e-12


def test_the_bounds_follow_the_model():
    """The pair's pole frequency is bounded by the resonance (0.1-1.0 x), its damping ratios 0.01-0.3; the notch's
    factor 0.5-2, its damping ratio 0-0.5."""
    fam = FAMILIES["load_mass"]

    class Ctx:
        num, den = paper.plant_tf()

    lo, hi = fam.bounds(Ctx(), EffectFit("load_mass", "model:pair", (0.0, 1.0, 6.0, 0.06, 1.25, 0.1)))
    assert lo[2] == pytest.approx(0.1 * F_RES_HZ, rel=1e-6) and hi[2] == pytest.approx(F_RES_HZ, rel=1e-6)
    assert (lo[3], hi[3], lo[4], hi[4]) == (load.PAIR_ZETA_MIN, load.PAIR_ZETA_MAX, 0.6, 1.6)
    lo, hi = fam.bounds(Ctx(), EffectFit("load_mass", "model:notch", (0.0, 1.0, 0.75, 0.1)))
    assert (lo[2], hi[2], lo[3], hi[3]) == (0.5, 2.0, 0.0, 0.5)


@pytest.mark.parametrize("f_hz,zp,ratio,zz,seed", [(6.0, 0.06, 1.25, 0.1, 11), (9.0, 0.08, 0.8, 0.05, 12)])
def test_an_added_pair_is_named_a_load_with_its_frequency(f_hz, zp, ratio, zz, seed):
    """A pole-zero pair at 6 Hz (zero above it) and at 9 Hz (zero below it), 0.3 and 0.46 of the resonance: named
    ``load_mass`` alone, of the pair form, its pole and zero frequencies within 5 %."""
    t, u, y, model = _log(_pair_plant(f_hz, zp, ratio, zz), seed)
    v = diagnose(t, u, y, model=model, units=("kV", "mm"))
    assert v.names == ["load_mass"]
    p = next(e for e in v.effects if e["name"] == "load_mass")["params"]
    assert p["variant"].startswith("model:pair")
    assert abs(p["pair_hz"] / f_hz - 1.0) < 0.05
    assert abs(p["pair_zero_hz"] / (f_hz * ratio) - 1.0) < 0.05
    words = next(e for e in v.effects if e["name"] == "load_mass")["evidence"]
    assert f"poles at {p['pair_hz']:.3g} Hz" in words and "mass ratio" not in words, words
    assert v.heldout["nrmse_augmented"] < 0.3 * v.heldout["nrmse_nominal"]


def test_a_moved_antiresonance_is_named_a_load():
    """P(s)'s anti-resonance at 0.75 of its frequency with a damping ratio of 0.12: named ``load_mass`` alone,
    of the notch form, the factor within 0.05 and the held-out error cut by more than two thirds."""
    t, u, y, model = _log(_notch_plant(0.75, 0.12), 13)
    v = diagnose(t, u, y, model=model, units=("kV", "mm"))
    assert v.names == ["load_mass"]
    p = next(e for e in v.effects if e["name"] == "load_mass")["params"]
    assert p["variant"].startswith("model:notch")
    assert abs(p["zero_factor"] - 0.75) < 0.05
    assert v.heldout["nrmse_augmented"] < 0.33 * v.heldout["nrmse_nominal"]


@pytest.mark.parametrize("delay_s,seed", [(0.0, 14), (0.008, 15)])
def test_no_pair_or_notch_on_an_effect_free_or_a_delayed_log(delay_s, seed):
    """An effect-free log is named nothing; an 8 ms delay ``time_delay`` alone (a delay moves no magnitude)."""
    num, den = paper.plant_tf()
    t, u, y, model = designs.multisine_through((num, den), seed, RATE_HZ, delay_s, 0.004, 16.0)
    v = diagnose(t, u, y, model=model, units=("kV", "mm"))
    assert v.names == ([] if delay_s == 0 else ["time_delay"])


def test_the_pair_goes_into_the_simulator_through_a_plant_file(tmp_path):
    """The verdict of the 6 Hz pair exported as a plant file, read back (its parameters named as the form's) and
    built as the simulator's actuator: driven at the pair's frequency (10 kHz, the amplifier's filter included), its
    stroke swings the pair's gain times the nominal actuator's, ``|H(j w)|`` of the written pair (3.28), within 5 % (found 0.03 %)."""
    from hasel.plantfile import export_plant, read_plant

    t, u, y, model = _log(_pair_plant(6.0, 0.06, 1.25, 0.1), 11)
    v = diagnose(t, u, y, model=model, units=("kV", "mm"))
    m = read_plant(export_plant(v, tmp_path / "pair.json"))
    load_entry = next(e for e in m.effects if e.name == "load_mass")
    assert load_entry.variant == "model:pair" and abs(load_entry.params["pair_hz"] - 6.0) < 0.3
    wp, wz = 2 * math.pi * 6.0, 2 * math.pi * 7.5
    s = 2j * math.pi * 6.0
    h = (wp / wz) ** 2 * (s * s + 2 * 0.1 * wz * s + wz * wz) / (s * s + 2 * 0.06 * wp * s + wp * wp)
    assert designs.swing_over_nominal(m, 6.0) == pytest.approx(abs(h), rel=0.05)
