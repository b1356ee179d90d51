"""The direction-dependent lags' fast kernel (multiple shooting, then an exact repair) computes the
plain per-sample recursion: to 1e-12 for the generic form, bit for bit for the truth form's laws."""
from __future__ import annotations

import math

import numpy as np
import pytest

from hasel.effects import operators
from hasel.effects.asymmetric import lag
from hasel.effects.operators import asymmetric_lag, exp_level_lag

N = 3 * operators._MIN_SHOOT + 17  # long enough for the shooting kernel, not a whole number of segments


def _per_sample(x, dt, tau_up, z0, falling_share):
    """The rise-or-fall recursion one sample at a time: ``z += d a``, ``a`` from ``tau_up`` while
    rising, ``falling_share(z)`` while falling."""
    a_up = -math.expm1(-dt / tau_up) if tau_up > 0 else 1.0
    z, out = z0, []
    for xi in x:
        d = xi - z
        z += d * (a_up if d > 0.0 else falling_share(z))
        out.append(z)
    return np.array(out)


def _truth_definition(x, dt, tau_up, tau_dn, z0, level_dependence=0.0, level_ref=1.0):
    """``asymmetric_lag`` as its docstring states it, one sample at a time."""
    def falling_share(z):
        if level_dependence == 0.0:
            return -math.expm1(-dt / tau_dn) if tau_dn > 0 else 1.0
        tau = tau_dn * (1.0 + level_dependence * max(0.0, 1.0 - z / level_ref))
        return dt / (tau + dt) if tau > 0 else 1.0
    return _per_sample(x, dt, tau_up, z0, falling_share)


def _generic_definition(x, dt, tau_up, tau_dn, k, y_c, y_s, z0):
    """The generic lag: ``tau_dn exp(k clip((z - y_c) / y_s, -2, 2))`` while falling."""
    def falling_share(z):
        w = min(max((z - y_c) / y_s, -2.0), 2.0)
        return dt / (tau_dn * math.exp(k * w) + dt)
    return _per_sample(x, dt, tau_up, z0, falling_share)


def _signal(rng, kind):
    """Random walks, noisy chirps (many reversals) and slow steps (long falling runs)."""
    t = np.arange(N) * 1e-3
    if kind == "walk":
        return np.cumsum(rng.normal(size=N)) * rng.uniform(0.01, 0.3)
    if kind == "chirp":
        f = 0.2 + 20.0 * t / t[-1]
        return 3.0 + 2.0 * np.sin(2 * np.pi * np.cumsum(f) * 1e-3) + 0.05 * rng.normal(size=N)
    levels = rng.uniform(-1.0, 8.0, size=N // 700 + 1)
    return np.repeat(levels, 700)[:N] + 1e-3 * rng.normal(size=N)


CASES = [(kind, seed) for kind in ("walk", "chirp", "steps") for seed in range(3)]


@pytest.mark.parametrize("kind,seed", CASES)
def test_truth_lag_is_the_recursion_bit_for_bit(kind, seed):
    rng = np.random.default_rng(100 + seed)
    x = _signal(rng, kind)
    taus = [(0.0, 0.08), (0.003, 0.2), (0.02, 0.0), (0.0, 0.0), (0.5, 0.004)]
    for tau_up, tau_dn in taus:
        for level_dependence in (0.0, 0.5, 3.0):
            z0 = float(x[0]) + float(rng.normal())
            got = asymmetric_lag(x, 1e-3, tau_up, tau_dn, z0, level_dependence=level_dependence, level_ref=8.0)
            ref = _truth_definition(x.tolist(), 1e-3, tau_up, tau_dn, z0, level_dependence, 8.0)
            # the same operations in the same order as one sample at a time
            assert np.array_equal(got, ref), (tau_up, tau_dn, level_dependence, np.max(np.abs(got - ref)))


@pytest.mark.parametrize("kind,seed", CASES)
def test_generic_lag_is_the_recursion_to_1e_12(kind, seed):
    rng = np.random.default_rng(200 + seed)
    x = _signal(rng, kind)
    scale = float(np.max(np.abs(x)))
    for tau_up, tau_dn, k in [(0.0, 0.08, 0.0), (0.0, 0.08, 2.3), (1e-10, 0.3, -3.0), (0.004, 0.02, 1.0),
                              (0.0, 0.0, 1.5), (0.01, 0.5, -0.7)]:
        y_c, y_s = float(np.mean(x)), float(np.std(x)) + 0.1
        z0 = float(x[0])
        got = lag(x, 1e-3, (tau_up, tau_dn, k), y_c, y_s)
        ref = (_truth_definition(x.tolist(), 1e-3, tau_up, tau_dn, z0) if k == 0.0
               else _generic_definition(x.tolist(), 1e-3, tau_up, tau_dn, k, y_c, y_s, z0))
        np.testing.assert_allclose(got, ref, rtol=0, atol=1e-12 * scale)
        # the operator itself and its one-sample-at-a-time form agree too
        if k != 0.0:
            direct = exp_level_lag(x, 1e-3, tau_up, tau_dn, k, y_c, y_s, z0)
            loop = operators.exp_level_lag_loop(x, 1e-3, tau_up, tau_dn, k, y_c, y_s, z0)
            np.testing.assert_allclose(direct, loop, rtol=0, atol=1e-12 * scale)


def test_short_and_long_signals_give_the_same_lag_in_chunks():
    """A plant stepping in short chunks (the loop) and one long call (the shooting kernel) agree."""
    rng = np.random.default_rng(7)
    x = _signal(rng, "chirp")
    whole = asymmetric_lag(x, 1e-3, 0.0, 0.08, level_dependence=0.5, level_ref=8.0)
    z, parts = float(x[0]), []
    for i in range(0, N, 50):
        part = asymmetric_lag(x[i:i + 50], 1e-3, 0.0, 0.08, z, level_dependence=0.5, level_ref=8.0)
        z = float(part[-1])
        parts.append(part)
    assert np.array_equal(np.concatenate(parts), whole)


def test_shooting_kernel_settles_in_few_sweeps(monkeypatch):
    """The sweeps do the work (not the one-sample-at-a-time repair): count the repaired steps."""
    rng = np.random.default_rng(9)
    x = _signal(rng, "chirp")
    calls = []
    real = operators._FallingLaw.scalar

    def counting(self, z):
        calls.append(z)
        return real(self, z)

    monkeypatch.setattr(operators._FallingLaw, "scalar", counting)
    out = exp_level_lag(x, 1e-3, 0.0, 0.08, 1.2, 3.0, 2.0)
    ref = _generic_definition(x.tolist(), 1e-3, 0.0, 0.08, 1.2, 3.0, 2.0, float(x[0]))
    np.testing.assert_allclose(out, ref, rtol=0, atol=1e-12 * float(np.max(np.abs(x))))
    assert len(calls) < N // 4


def test_play_from_its_turning_points_is_the_full_scan_bit_for_bit():
    """The play operator filled in from its turning points gives the full clamp scan's floats."""
    rng = np.random.default_rng(21)
    for trial in range(120):
        n = int(rng.integers(3, 4000))
        t = np.arange(n)
        kind = trial % 4
        if kind == 0:
            x = 3.0 * np.sin(t * rng.uniform(0.001, 0.1))
        elif kind == 1:  # a random walk (many reversals: the plain scan)
            x = np.cumsum(rng.normal(size=n))
        elif kind == 2:  # flat steps inside the runs
            x = np.round(5.0 * np.sin(t * 0.01), 1)
        else:
            x = np.sin(t * 0.02) + 0.01 * rng.normal(size=n)
        r = rng.uniform(0.0, 1.5, size=5) if trial % 2 else float(rng.uniform(0.0, 1.0))
        y0 = None if trial % 3 == 0 else float(3.0 * rng.normal())
        start = float(x[0]) if y0 is None else y0
        full = operators._play_scan(x, np.atleast_1d(r)[:, None], start)
        got = operators.play(x, r, y0)
        assert np.array_equal(got, full[0] if np.ndim(r) == 0 else full), trial
    # and against the recursion itself, one sample at a time
    x = 2.0 * np.sin(np.arange(3000) * 0.013) + np.sin(np.arange(3000) * 0.0021)
    y, ref = 0.4, []
    for xi in x:
        y = min(max(y, xi - 0.3), xi + 0.3)
        ref.append(y)
    np.testing.assert_array_equal(operators.play(x, 0.3, 0.4), ref)
