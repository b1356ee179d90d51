"""The ``load_mass`` family's damping form (``model:damp``): a load that changes the mount's damping.

A payload's mount can change the damping of the actuator's resonance without the inertia change the
two older forms describe (``model``: frequency and damping ratio fall together; ``model:zeta``:
frequency lowered, damping ratio kept). The logs here are the paper's plant P(s) whose two resonance
pairs (122.2 rad/s, damping ratio 0.94) have their damping ratio multiplied by ``m`` and their
frequency by ``f`` (static gain kept), written here from the transfer function (scipy's ZOH), not
with the library's load code: the form of ``bench/tune_diag/multi2.py``'s ``damping`` load.
On the library before this form the first log was named nothing (the load family's best fit was the
nominal: ``RESULT-h-triples.md``, case 07).
"""
from __future__ import annotations

import designs
import numpy as np
import pytest
from scipy import signal

from hasel import paper
from hasel.diagnose import diagnose
from hasel.effects.base import EffectFit
from hasel.effects.registry import FAMILIES

RATE_HZ = 500.0


def _damped_plant(f: float, m: float) -> tuple[np.ndarray, np.ndarray]:
    """P(s) (kV -> mm) with the resonance pairs' frequency times ``f`` and damping ratio times ``m``."""
    num, _ = paper.plant_tf()
    w0 = paper.P_NOTCH_RAD_S
    z0 = 230.0 / (2.0 * w0)
    w = f * w0
    quad = [1.0, 2.0 * z0 * m * w, w * w]
    den = np.polymul(np.polymul([1.0, 18.85], [1.0, 56.55]), np.polymul(quad, quad))
    return num * (w / w0) ** 4, den


def _log(f: float, m: float, seed: int, noise_mm: float = 0.004, dur_s: float = 16.0):
    """:func:`designs.multisine_through` the damped plant at this file's rate."""
    return designs.multisine_through(_damped_plant(f, m), seed, RATE_HZ, 0.0, noise_mm, dur_s)


def test_the_damping_form_is_the_truths_plant():
    """``model:damp`` with ``mu = 1/f^2 - 1`` and ``delta = m`` is the damped plant (the same denominator up to
    the DC scaling, the same response to 1e-9)."""
    f, m = 0.9, 2.2  # overdamped: the damping ratio 2.07, the pairs become real poles
    num0, den0 = paper.plant_tf()
    fit = EffectFit("load_mass", "model:damp", (1.0 / f ** 2 - 1.0, 1.0, m))
    num1, den1 = FAMILIES["load_mass"].transform(num0, den0, fit)
    num2, den2 = _damped_plant(f, m)
    w = np.geomspace(1.0, 3000.0, 200)
    h1 = signal.freqs(num1, den1, w)[1]
    h2 = signal.freqs(num2, den2, w)[1]
    assert np.max(np.abs(h1 - h2) / np.abs(h2).max()) < 1e-9
    assert FAMILIES["load_mass"].param_names(fit) == ("mass_ratio", "gain_factor", "damping_factor")
    sag = EffectFit("load_mass", "model:damp:sag", (0.2, 1.0, 0.5, -0.1))
    assert FAMILIES["load_mass"].param_names(sag)[-1] == "offset"
    lo, hi = FAMILIES["load_mass"].bounds(None, sag)
    assert lo[2] == 0.25 and hi[2] == 4.0 and hi[3] == 0.0


@pytest.mark.parametrize("f,m,seed", [(0.93, 0.45, 1), (0.95, 2.0, 2)])
def test_a_damping_shift_is_named_a_load_with_its_damping_factor(f, m, seed):
    """A less (x0.45) and a more (x2.0) damped mount, frequency 5-7 % lower: named ``load_mass`` alone, of the
    damping form, its damping factor within 15 % of the truth and its frequency factor within 4 %."""
    t, u, y, model = _log(f, m, seed)
    v = diagnose(t, u, y, model=model, units=("kV", "mm"))
    assert v.names == ["load_mass"]
    p = next(e for e in v.effects if e["name"] == "load_mass")["params"]
    assert "damp" in p["variant"].split(":")
    assert abs(p["damping_factor"] / m - 1.0) < 0.15
    assert abs(p["resonance_factor"] / f - 1.0) < 0.04
    assert abs(p["damping_ratio_loaded"] - 0.941 * p["damping_factor"]) < 1e-3


def test_a_delay_is_not_taken_for_a_damping_load():
    """A pure 6 ms delay on the nominal plant: named ``time_delay``, no load (the freer load form does not take
    the delay's phase)."""
    t, u, y, model = _log(1.0, 1.0, 3)
    n = int(round(0.006 * RATE_HZ))
    _, u2, _, _ = _log(1.0, 1.0, 3)
    b, a, _ = signal.cont2discrete(paper.plant_tf(), 1.0 / RATE_HZ, method="zoh")
    b = np.ravel(b)
    ud = np.concatenate([np.full(n, u2[0]), u2[:-n]])
    y = signal.lfilter(b, a, ud, zi=signal.lfilter_zi(b, a) * ud[0])[0]
    rng = np.random.default_rng(3)
    lsb = 10.0 * 3.0 / 4096
    y = np.round((y + 0.004 * rng.standard_normal(y.size)) / lsb) * lsb
    v = diagnose(t, u2, y, model=model, units=("kV", "mm"))
    assert v.names == ["time_delay"]
