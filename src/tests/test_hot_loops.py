"""The effect families' hot loops, made faster, still compute their definitions (to 1e-12)."""
from __future__ import annotations

import math
from types import SimpleNamespace

import numpy as np

from hasel.effects.asymmetric import lag
from hasel.effects.fitkit import POLY_RIDGE, _poly_ls, monomials
from hasel.effects.operators import asymmetric_lag


def _lag_definition(y, dt, theta, y_c, y_s, z0):
    """The direction-dependent lag as its docstring states it, one sample at a time."""
    tau_up, tau_dn, k = theta
    z, out = z0, []
    for x in y:
        if x - z > 0:
            z += (x - z) * -math.expm1(-dt / tau_up) if tau_up > 0 else (x - z)
        else:
            w = min(max((z - y_c) / y_s, -2.0), 2.0)
            z += (x - z) * dt / (tau_dn * math.exp(k * w) + dt)
        out.append(z)
    return np.array(out)


def test_lags_follow_their_definitions():
    rng = np.random.default_rng(11)
    for trial in range(8):
        y = np.cumsum(rng.normal(size=int(rng.integers(2, 1000)))) * rng.uniform(0.01, 3.0)
        theta = (float(rng.uniform(0.0, 0.2)), float(rng.uniform(0.0, 0.5)), float(rng.uniform(-3, 3)))
        y_c, y_s, z0 = float(rng.normal()), float(rng.uniform(0.1, 5.0)), float(y[0])
        np.testing.assert_allclose(lag(y, 1e-3, theta, y_c, y_s), _lag_definition(y, 1e-3, theta, y_c, y_s, z0),
                                   rtol=1e-12, atol=1e-12)
        # constant time constants: the operator's closed-form step per direction
        a_up, a_dn = (-math.expm1(-1e-3 / t) if t > 0 else 1.0 for t in theta[:2])
        z, ref = z0, []
        for x in y:
            z += (x - z) * (a_up if x > z else a_dn)
            ref.append(z)
        np.testing.assert_allclose(asymmetric_lag(y, 1e-3, theta[0], theta[1]), ref, rtol=1e-12, atol=1e-12)


def test_polynomial_least_squares_is_the_ridge_solution_of_its_chosen_degree():
    rng = np.random.default_rng(12)
    n = 4000
    x = rng.normal(size=n)
    train = rng.random(n) > 0.3
    truth = 0.4 * np.tanh(x) ** 3 - 0.2 * np.tanh(x)
    rec = SimpleNamespace(y=truth + 0.01 * rng.normal(size=n), train=train)
    ctx = SimpleNamespace(prep=SimpleNamespace(records=[rec]), max_degree=5,
                          stages=lambda effects, ri: {"y": np.zeros(n)})
    w = _poly_ls(ctx, {}, lambda ri, st: monomials(np.tanh(x), 6))
    # the same weights from the normal equations written out, at the degree it chose
    A = np.column_stack(monomials(np.tanh(x), w.size))[train]
    s = np.sqrt((A * A).sum(axis=0))
    An = A / s
    G = An.T @ An
    ref = np.linalg.solve(G + POLY_RIDGE * np.trace(G) / w.size * np.eye(w.size), An.T @ rec.y[train]) / s
    np.testing.assert_allclose(w, ref, rtol=1e-10, atol=1e-12)
    assert w.size in (2, 4, 6) and abs(w[3] - 0.4) < 0.05  # the cubic found
