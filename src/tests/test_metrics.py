"""hasel.metrics: step metrics against closed forms, and the NRMSE."""
from __future__ import annotations

import math

import numpy as np
import pytest

from hasel.errors import BadInputError
from hasel.metrics import nrmse, reference_starts, robust_sd, step_metrics, steps_from_sequence


def test_first_order_rise_and_settling_closed_form():
    tau = 0.05
    t = np.arange(0, 2, 1e-4)
    y = 2.0 + 2.0 * (1 - np.exp(-(t - 0.5) / tau)) * (t >= 0.5)
    m = step_metrics(t, y, 0.5, 2.0, 2.0, 4.0)
    assert m.mode == "activation"
    assert m.rise_s == pytest.approx(tau * math.log(9), rel=1e-3)  # 10-90 % of a lag
    assert m.settling_s == pytest.approx(tau * math.log(20), abs=2e-4)  # 5 % band
    assert m.overshoot_pct == 0.0


def test_relaxation_with_overshoot():
    t = np.arange(0, 1, 1e-4)
    wn, zeta = 40.0, 0.3
    wd = wn * math.sqrt(1 - zeta**2)
    s = 1 - np.exp(-zeta * wn * t) * (np.cos(wd * t) + zeta / math.sqrt(1 - zeta**2) * np.sin(wd * t))
    y = 6.0 - 2.0 * s
    m = step_metrics(t, y, 0.0, 1.0, 6.0, 4.0)
    assert m.mode == "relaxation"
    assert m.overshoot_pct == pytest.approx(100 * math.exp(-zeta * math.pi / math.sqrt(1 - zeta**2)), rel=1e-3)


def test_never_reached_gives_nan():
    t = np.arange(0, 1, 1e-3)
    m = step_metrics(t, np.full(t.size, 2.0), 0.0, 1.0, 2.0, 12.0)
    assert math.isnan(m.rise_s) and math.isnan(m.settling_s)
    assert m.to_json()["rise_s"] is None


def test_nrmse_is_normalised_by_the_spread_about_the_mean_not_the_range():
    y = np.array([0.0, 1.0, 2.0, 3.0, 14.0])  # mean 4, sum of squares about it 130, range 14
    err = np.array([1.0, -1.0, 1.0, -1.0, 0.0])
    assert nrmse(y, y) == 0.0
    assert nrmse(y, np.full(5, y.mean())) == pytest.approx(1.0)
    # ||err|| = 2, ||y - mean|| = sqrt(130); by the range it would be 2 / (sqrt(5) * 14)
    assert nrmse(y, y + err) == pytest.approx(2.0 / math.sqrt(130.0), rel=1e-15)
    assert nrmse(y + 100.0, y + 100.0 + err) == nrmse(y, y + err)  # an offset changes nothing
    assert nrmse(np.full(4, 2.0), np.zeros(4)) == math.inf
    # bias-free: a constant offset of the simulation costs nothing, the rest counts as before
    assert nrmse(y, y + 0.7, bias_free=True) < 1e-15 and nrmse(y, y + 0.7) > 0.1
    assert nrmse(y, y + err + 0.7, bias_free=True) == pytest.approx(nrmse(y, y + err), rel=1e-14)


@pytest.mark.parametrize("a, b", [(np.zeros(3), np.zeros(4)), (np.zeros((2, 2)), np.zeros((2, 2))), ([], [])])
def test_nrmse_refuses_arrays_that_do_not_pair(a, b):
    with pytest.raises(BadInputError, match="1-D arrays of one length"):
        nrmse(a, b)


def test_the_callers_share_one_nrmse():
    from hasel import compare
    from hasel.diagnose import prep
    from hasel.ident import validation

    assert compare.nrmse is prep.nrmse is validation.nrmse is nrmse


def test_uneven_holds_window_each_step_at_its_own_start():
    """A rig's test need not hold its steps evenly: each step is judged from its own start to the next."""
    starts = reference_starts(3, [0.5, 1.5, 0.25])
    assert starts.tolist() == [0.0, 0.5, 2.0, 2.25]
    t = np.arange(0.0, 2.25, 1e-3)
    # first-order responses with different time constants per step, each restarting at its step
    y = np.where(t < 0.5, 2.0, np.where(t < 2.0, 2.0 + 2.0 * (1 - np.exp(-(t - 0.5) / 0.1)),
                                         4.0 - 1.0 * (1 - np.exp(-(t - 2.0) / 0.02))))
    a, b = steps_from_sequence(t, y, [2.0, 4.0, 3.0], [0.5, 1.5, 0.25])
    assert a.rise_s == pytest.approx(0.1 * math.log(9), abs=2e-3)
    assert b.rise_s == pytest.approx(0.02 * math.log(9), abs=2e-3) and b.mode == "relaxation"
    # one hold for all gives the windows of the evenly held test
    assert reference_starts(3, 0.5).tolist() == [0.0, 0.5, 1.0, 1.5]


@pytest.mark.parametrize("holds, words", [([0.5, 0.5], "3 references need 3 holds"),
                                          ([0.5, -1.0, 0.5], "positive finite"),
                                          ([0.5, math.nan, 0.5], "positive finite")])
def test_bad_holds_are_refused(holds, words):
    with pytest.raises(BadInputError, match=words):
        reference_starts(3, holds)


def test_robust_sd_is_the_normal_sd_and_ignores_steps():
    """robust_sd: 0.5 mm of normal noise reads 0.5 mm within 3 %, and still does with 2 % of the samples
    replaced by 40 mm steps (np.std reads those as ~5.7 mm)."""
    rng = np.random.default_rng(3)
    x = rng.normal(2.0, 0.5, 20_000)
    assert abs(robust_sd(x) - 0.5) < 0.015
    x[rng.choice(x.size, 400, replace=False)] += 40.0
    assert np.std(x) > 5.0
    assert abs(robust_sd(x) - 0.5) < 0.03
