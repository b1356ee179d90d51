"""A load beside a delay: the delay chosen first must not leave the load only a raised resonance.

The log: the paper's plant P(s) with one of its two resonance pairs lowered to ``f`` of its frequency
(damping ratio kept, static gain kept) behind a 3rd-order Pade all-pass of a transport delay, written
here from the transfer functions (scipy's ZOH), not with the library's load or delay code. A delay
fitted first takes up the load's phase lag too and comes out long; beside it the load family's best fit
raised the resonance, which a load cannot do, and the load was not named (``bench/tune_diag/loads.py``
seed 3, load_07: ``RESULT-h-ldlow.md``).
"""
from __future__ import annotations

import numpy as np
import pytest
from scipy import signal

import designs
from hasel import paper
from hasel.diagnose import diagnose

RATE_HZ = 1000.0


def _pade3(delay_s: float) -> tuple[np.ndarray, np.ndarray]:
    """3rd-order Pade all-pass of exp(-s delay_s)."""
    d = delay_s
    num = [-d ** 3 / 120.0, d ** 2 / 10.0, -d / 2.0, 1.0]
    den = [d ** 3 / 120.0, d ** 2 / 10.0, d / 2.0, 1.0]
    return np.array(num), np.array(den)


def _plant(f: float, delay_s: float) -> tuple[np.ndarray, np.ndarray]:
    """P(s) (kV -> mm) with one resonance pair's frequency times ``f`` (damping ratio kept), then the delay."""
    num0, den0 = paper.plant_tf()
    poles = list(np.roots(den0))
    one = max(poles, key=lambda p: p.imag)  # one pole of a resonance pair (both pairs are equal)
    for p in (one, np.conj(one)):  # that pair out; the other pair and the real poles stay
        poles.remove(min(poles, key=lambda q: abs(q - p)))
    den = np.real(np.poly(poles + [f * one, f * np.conj(one)])) * den0[0]
    num = num0 * den[-1] / den0[-1]  # static gain kept
    pn, pd = _pade3(delay_s)
    return np.polymul(num, pn), np.polymul(den, pd)


def _log(f: float, delay_s: float, seed: int, dur_s: float = 40.0, noise_mm: float = 0.005):
    """Random voltage levels (2-6 kV, held 20-200 ms each), white noise on the stroke."""
    rng = np.random.default_rng(seed)
    n = int(dur_s * RATE_HZ)
    u = designs.random_levels(rng, n, 2.0, 6.0)
    b, a, _ = signal.cont2discrete(_plant(f, delay_s), 1.0 / RATE_HZ, method="zoh")
    b = np.ravel(b)
    y = signal.lfilter(b, a, u, zi=signal.lfilter_zi(b, a) * u[0])[0] + noise_mm * rng.standard_normal(n)
    num, den = paper.plant_tf()
    return np.arange(n) / RATE_HZ, u, y, {"num": num.tolist(), "den": den.tolist()}


@pytest.mark.parametrize("f,delay_s,seed", [(0.72, 0.0124, 1), (0.8, 0.02, 2)])
def test_a_load_beside_a_pade_delay_is_named_with_it(f, delay_s, seed):
    t, u, y, model = _log(f, delay_s, seed)
    v = diagnose(t, u, y, model=model, units=("kV", "mm"))
    assert set(v.names) == {"load_mass", "time_delay"}
    p = next(e for e in v.effects if e["name"] == "load_mass")["params"]
    assert p["resonance_factor"] < 1.0  # lowered, as a load does
    d = next(e for e in v.effects if e["name"] == "time_delay")["params"]
    assert abs(d["delay_s"] - delay_s) < 0.3 * delay_s
