"""hasel.pid: the discretisation the paper states, bumpless switching, anti-windup."""
from __future__ import annotations

import math

import numpy as np
import pytest

from hasel import paper
from hasel.errors import BadInputError, UnsafeParameterError
from hasel.pid import DualModeConfig, DualModePid, PidGains


def test_paper_gains_are_defaults():
    cfg = DualModeConfig()
    assert (cfg.plus.kp, cfg.plus.ki, cfg.plus.kd) == paper.C_PLUS
    assert (cfg.minus.kp, cfg.minus.ki, cfg.minus.kd) == paper.C_MINUS
    assert cfg.period_s == 0.005


def test_trapezoidal_integral_and_backward_derivative_by_hand():
    cfg = DualModeConfig(plus=PidGains(2.0, 10.0, 0.01), v_max_kv=9.0)
    pid = DualModePid(cfg)
    errors = [0.5, 1.0, 0.75]
    i_kv, e_prev = 0.0, None
    for e in errors:
        out = pid.update(e, 0.0)
        ep = e if e_prev is None else e_prev
        i_kv += 10.0 * 0.005 * (e + ep) / 2
        expected = 2.0 * e + i_kv + 0.01 * (e - ep) / 0.005
        assert out.output_kv == pytest.approx(expected, rel=1e-12)
        assert out.i_kv == pytest.approx(i_kv, rel=1e-12)
        e_prev = e


def test_mode_follows_sign_of_error():
    pid = DualModePid()
    assert pid.update(2.0, 1.0).mode == 1
    assert pid.update(2.0, 2.0).mode == 1  # e = 0 belongs to C+
    assert pid.update(2.0, 3.0).mode == -1


def test_switch_is_bumpless_for_the_integral():
    pid = DualModePid(DualModeConfig(plus=PidGains(1.0, 25.0, 0.0), minus=PidGains(1.0, 80.0, 0.0)))
    for _ in range(50):
        pid.update(3.0, 2.0)  # build up integral in C+
    before = pid.i_kv
    out = pid.update(3.0, 3.0 + 1e-9)  # tiny negative error: switch to C-
    assert out.mode == -1
    # the integral moves only by Ki- Ts (e_k + e_{k-1})/2, not by a rescaling with Ki-/Ki+
    assert out.i_kv == pytest.approx(before + 80.0 * 0.005 * (1.0 - 1e-9) / 2, rel=1e-9)
    assert abs(out.i_kv - before) < 0.2


@pytest.mark.parametrize("strategy", ["conditional_integration", "back_calculation"])
def test_anti_windup_limits_integrator_growth(strategy):
    pid = DualModePid(DualModeConfig(anti_windup=strategy))
    for _ in range(2000):  # 10 s against an unreachable reference
        out = pid.update(50.0, 1.0)
    assert out.output_kv == 9.0 and out.saturated
    assert out.i_kv < 12.0  # stays near the limit instead of winding up
    none = DualModePid(DualModeConfig(anti_windup="none"))
    for _ in range(2000):
        o2 = none.update(50.0, 1.0)
    assert o2.i_kv > 1000.0  # the unprotected integrator winds up


def test_non_finite_inputs_hold_and_give_zero():
    pid = DualModePid()
    pid.update(3.0, 2.0)
    i_before = pid.i_kv
    for bad in (math.nan, math.inf, -math.inf):
        out = pid.update(3.0, bad)
        assert out.output_kv == 0.0 and pid.i_kv == i_before
        out = pid.update(bad, 2.0)
        assert out.output_kv == 0.0


def test_output_always_within_limits_for_random_inputs():
    rng = np.random.default_rng(3)
    pid = DualModePid()
    for r, z in rng.normal(0, 1e3, size=(3000, 2)):
        out = pid.update(float(r), float(z))
        assert 0.0 <= out.output_kv <= 9.0


def test_unsafe_or_bad_configuration_is_rejected_with_reason():
    with pytest.raises(UnsafeParameterError, match="9.0 kV"):
        DualModeConfig(v_max_kv=10.0)
    with pytest.raises(BadInputError, match="kp must be >= 0"):
        PidGains(-1.0, 1.0, 0.0)
    with pytest.raises(BadInputError, match="anti_windup"):
        DualModeConfig(anti_windup="magic")
