"""Static map fit and time-domain validation helpers (hasel.ident.staticmap, hasel.ident.validation)."""
from __future__ import annotations

import numpy as np
import pytest
from scipy import signal

from hasel.errors import BadInputError
from hasel.ident.staticmap import fit_static_map
from hasel.ident.tffit import TFModel
from hasel.ident.validation import compare_fit, nrmse, simulate


def test_static_map_degree_by_leave_one_out():
    rng = np.random.default_rng(0)
    v = np.arange(2.0, 8.0)
    quad = 0.1 * v**2 + 0.5 * v + 0.2
    sm = fit_static_map(v, quad + 1e-4 * rng.standard_normal(v.size))
    assert sm.degree == 2
    np.testing.assert_allclose(sm.coefficients, [0.1, 0.5, 0.2], atol=5e-3)
    assert float(sm.slope(3.0)) == pytest.approx(1.1, abs=0.01)
    line = fit_static_map(v, 1.35 * v + 1e-3 * rng.standard_normal(v.size))
    assert float(line.slope(4.5)) == pytest.approx(1.35, abs=0.005)
    assert line.loo_by_degree[0] > 10 * line.loo_by_degree[1]
    # six noisy points: leave-one-out picks the true degree most of the time, not always
    lin = [fit_static_map(v, 1.35 * v + 1e-3 * rng.standard_normal(v.size)).degree for _ in range(60)]
    sq = [fit_static_map(v, quad + 1e-3 * rng.standard_normal(v.size)).degree for _ in range(60)]
    assert lin.count(1) >= 45 and min(lin) == 1
    assert sq.count(2) >= 45 and min(sq) == 2
    assert fit_static_map([2.0, 4.0], [1.0, 3.0]).coefficients == pytest.approx([1.0, -1.0])
    one = fit_static_map([3.0], [4.0])
    assert one.degree == 0 and float(one(10.0)) == pytest.approx(4.0)
    with pytest.raises(BadInputError, match="finite"):
        fit_static_map([1.0, np.nan], [1.0, 2.0])


def test_nrmse_and_compare_fit():
    y = np.array([1.0, 2.0, 3.0, 4.0])
    assert nrmse(y, y) == 0.0 and compare_fit(y, y) == 100.0
    assert nrmse(y, np.full(4, y.mean())) == pytest.approx(1.0)
    assert compare_fit(y, y + 0.1) == pytest.approx(100 * (1 - 0.2 / np.sqrt(5.0)))
    with pytest.raises(BadInputError, match="one length"):
        nrmse(y, y[:3])


def test_simulate_matches_lsim_of_the_continuous_model():
    model = TFModel(num=np.array([50.0]), den=np.array([1.0, 7.0, 50.0]))
    rate = 1000.0
    t = np.arange(0, 3, 1 / rate)
    u = np.sin(2 * np.pi * 2.0 * t) * (t > 0.1)
    _, ref, _ = signal.lsim((model.num, model.den), u, t, interp=True)   # linear interpolation of u
    y = simulate(model, u, rate)
    assert np.max(np.abs(y - ref)) < 2e-3 * np.max(np.abs(ref))
    delayed = simulate(TFModel(model.num, model.den, delay_s=0.05), u, rate)
    np.testing.assert_allclose(delayed[50:], y[:-50], atol=1e-12)
