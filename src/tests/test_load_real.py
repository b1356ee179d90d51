"""The ``load_mass`` family's viscous form (``model:real``): the model's real poles slowed or sped.

A viscous load (a damper, a thicker liquid, a softer mount) slows P(s)'s overdamped modes, its real poles at
3 Hz and 9 Hz; the forms that move or add pole pairs and zeros fit it only as heavier resonances beside a
spurious hysteresis (``bench/tune_diag/forms3.py`` seed 1, ``slowpoles``: 10x the noise floor left). The truths
here are written from P(s)'s factors (scipy's ZOH through :func:`designs.multisine_through`), not with the
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


def _viscous_plant(k: float) -> tuple[np.ndarray, np.ndarray]:
    """P(s) (kV -> mm) with its real poles 18.85 and 56.55 rad/s times ``k`` and the numerator times ``k^2`` (the
    static gain kept)."""
    num, _ = paper.plant_tf()
    quad = np.array([1.0, 230.0, paper.P_NOTCH_RAD_S ** 2])
    den = np.polymul(np.polymul([1.0, 18.85 * k], [1.0, 56.55 * k]), np.polymul(quad, quad))
    return num * k * k, den


def test_the_form_is_the_truths_plant_keeps_the_static_gain_and_runs_in_chunks():
    """The form with ``mu`` 0, ``kappa`` 1 and factor 0.6 is the written plant (to 1e-9 of its peak), keeps the
    static gain, names its parameters, is bounded 0.25-4, and its stage run in two chunks gives the whole run."""
    fam = FAMILIES["load_mass"]
    num0, den0 = paper.plant_tf()
    fit = EffectFit("load_mass", "model:real", (0.0, 1.0, 0.6))
    num1, den1 = fam.transform(num0, den0, fit)
    num2, den2 = _viscous_plant(0.6)
    w = np.geomspace(1.0, 3000.0, 300)
    h1, h2 = signal.freqs(num1, den1, w)[1], signal.freqs(num2, den2, w)[1]
    assert np.max(np.abs(h1 - h2)) < 1e-9 * np.abs(h2).max()
    assert num1[-1] / den1[-1] == pytest.approx(num0[-1] / den0[-1], rel=1e-12)
    assert fam.param_names(fit) == ("mass_ratio", "gain_factor", "pole_factor")

    class Scales:
        num, den = num0, den0

    lo, hi = fam.bounds(Scales(), fit)
    assert (lo[2], hi[2]) == (0.25, 4.0)
    u = 4.0 + np.sin(np.arange(900) / 9.0)
    assert designs.chunked_gap(lambda: fam.stage(fit, Scales(), 2e-3), u, 311) < 1e-12


def test_an_integrator_and_complex_poles_are_kept():
    """Only nonzero real poles move: ``1 / (s (s + 2) (s^2 + 2 s + 5))`` with factor 3 is ``3 / (s (s + 6) (s^2 + 2 s
    + 5))`` (its gain at low frequency, the ``s`` coefficient, kept)."""
    den = np.polymul(np.polymul([1.0, 0.0], [1.0, 2.0]), [1.0, 2.0, 5.0])
    got = load.scale_real_poles(den, 3.0)
    want = np.polymul(np.polymul([1.0, 0.0], [1.0, 6.0]), [1.0, 2.0, 5.0]) / 3.0
    assert np.allclose(got, want, rtol=1e-9, atol=1e-12)


@pytest.mark.parametrize("k,seed", [(0.6, 21), (1.6, 22)])
def test_a_viscous_load_is_named_a_load_with_its_factor(k, seed):
    """Real poles slowed to 0.6 (and sped to 1.6) of P(s)'s: named ``load_mass`` alone, of the viscous form, the
    factor within 5 % and the held-out error cut by more than two thirds."""
    t, u, y, model = designs.multisine_through(_viscous_plant(k), seed, RATE_HZ, 0.0, 0.004, 16.0)
    v = diagnose(t, u, y, model=model, units=("kV", "mm"))
    assert v.names == ["load_mass"]
    p = next(e for e in v.effects if e["name"] == "load_mass")["params"]
    assert p["variant"].startswith("model:real")
    assert abs(p["pole_factor"] / k - 1.0) < 0.05
    assert p["real_poles_loaded_hz"][0] == pytest.approx(18.85 / (2 * math.pi) * p["pole_factor"], rel=1e-3)
    words = next(e for e in v.effects if e["name"] == "load_mass")["evidence"]
    assert f"the real poles {'slowed' if k < 1 else 'sped'} (a viscous load)" in words, words
    assert v.heldout["nrmse_augmented"] < 0.33 * v.heldout["nrmse_nominal"]


def test_the_viscous_load_goes_into_the_simulator_through_a_plant_file(tmp_path):
    """The verdict of the 0.6 load exported as a plant file, read back and built as the simulator's actuator:
    driven at 6 Hz (10 kHz, the amplifier's filter included), its stroke swings the written plant's gain over the
    nominal's, ``|H(j w)|`` ratio 0.53, within 5 %."""
    from hasel.plantfile import export_plant, read_plant

    t, u, y, model = designs.multisine_through(_viscous_plant(0.6), 21, RATE_HZ, 0.0, 0.004, 16.0)
    v = diagnose(t, u, y, model=model, units=("kV", "mm"))
    m = read_plant(export_plant(v, tmp_path / "viscous.json"))
    entry = next(e for e in m.effects if e.name == "load_mass")
    assert entry.variant.startswith("model:real") and abs(entry.params["pole_factor"] - 0.6) < 0.03
    num, den = paper.plant_tf()
    s = 2j * math.pi * 6.0
    num2, den2 = _viscous_plant(0.6)
    ratio = abs(np.polyval(num2, s) / np.polyval(den2, s)) / abs(np.polyval(num, s) / np.polyval(den, s))
    assert 0.4 < ratio < 0.7
    assert designs.swing_over_nominal(m, 6.0) == pytest.approx(ratio, rel=0.05)
