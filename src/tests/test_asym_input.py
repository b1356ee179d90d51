"""The input-side form of ``asymmetric_dynamics``: a direction-dependent lag of the voltage before the dynamics."""
from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest

from hasel import paper
from hasel.diagnose import diagnose
from hasel.diagnose.prep import LinearSim
from hasel.effects.asymmetric import INPUT
from hasel.effects.base import SLOT_ORDER, EffectFit, run_chunked
from hasel.effects.operators import asymmetric_lag
from hasel.effects.registry import FAMILIES
from hasel_bench.blind import excitation


def test_the_input_lag_sits_before_the_input_map_and_runs_in_chunks():
    fit = EffectFit("asymmetric_dynamics", INPUT, (0.003, 0.05))
    assert SLOT_ORDER["saturation:slew"] < fit.slot < SLOT_ORDER["static_nonlinearity:input"]
    fam = FAMILIES["asymmetric_dynamics"]
    assert fam.param_names(fit) == ("tau_rising_s", "tau_falling_s")
    sc = SimpleNamespace(u_c=3.0, u_s=2.0, y_c=4.0, y_s=3.0)
    x = np.concatenate([np.zeros(100), np.full(300, 5.0), np.zeros(300)])
    whole = run_chunked(fam.stage(fit, sc, 1e-3), x, x.size)
    np.testing.assert_array_equal(run_chunked(fam.stage(fit, sc, 1e-3), x, 5), whole)
    # the law: rising with 3 ms, falling with 50 ms (first order each way)
    np.testing.assert_allclose(whole, asymmetric_lag(x, 1e-3, 0.003, 0.05, 0.0), atol=1e-12)
    assert whole[100 + 15] > 4.9 and 1.5 < whole[400 + 50] < 2.0


def test_a_voltage_that_discharges_slowly_is_named_on_the_input_side():
    # an amplifier that charges the actuator with 3 ms and lets it discharge with 50 ms: the stroke is P(s) of
    # that voltage. Named asymmetric_dynamics, the lag on the input, both time constants recovered
    rng = np.random.default_rng(4)
    rate = 1000.0
    num, den = paper.plant_tf()
    u = excitation(rng, quick=True, rate_hz=rate)
    v = asymmetric_lag(u, 1.0 / rate, 0.003, 0.05, float(u[0]))
    y = LinearSim(num, den, rate).run(v) + 0.005 * rng.standard_normal(u.size)
    t = np.arange(u.size) / rate
    verdict = diagnose(t, u, y, model=(num, den))
    names = [e["name"] for e in verdict.effects]
    assert names == ["asymmetric_dynamics"]
    p = verdict.effects[0]["params"]
    assert p["variant"] == INPUT
    assert p["tau_rising_s"] == pytest.approx(0.003, rel=0.3) and p["tau_falling_s"] == pytest.approx(0.05, rel=0.15)
    assert verdict.heldout["nrmse_augmented"] < 0.2 * verdict.heldout["nrmse_nominal"]
