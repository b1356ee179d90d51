"""End-to-end identification of the simulated actuator (hasel.ident.identify) and its input checks."""
from __future__ import annotations

import json

import numpy as np
import pytest

from hasel import paper
from hasel.errors import BadInputError
from hasel.ident import IdentResult, identify
from hasel.lti import tf_freqresp
from hasel.plant import NominalActuator, NominalConfig, amplifier_filter_tf
from hasel.sensors import LaserConfig, LaserSensor
from hasel.signals import protocol_schedule

F_CHECK = np.geomspace(0.1, 15.0, 300)   # the issue's accuracy band


def _campaign(offsets, seed, config=None):
    """The paper's chirp protocol (Table I) at 10 kHz through the nominal actuator, read by the laser."""
    sch = protocol_schedule(offsets_kv=offsets, precondition_s=2.0)
    act = NominalActuator(config)
    act.reset(0.0)
    out = act.run(sch.command_kv)
    laser = LaserSensor(LaserConfig(), np.random.default_rng(seed)).measure(out.stroke_mm)
    return sch, out, laser


def _errors(model, num, den):
    r = model.freqresp(F_CHECK) / tf_freqresp(num, den, F_CHECK)
    return float(np.max(np.abs(20 * np.log10(np.abs(r))))), float(np.max(np.abs(np.degrees(np.angle(r)))))


@pytest.fixture(scope="module")
def campaign():
    return _campaign([2.0, 4.0], seed=0)


@pytest.fixture(scope="module")
def from_applied(campaign) -> IdentResult:
    sch, out, laser = campaign
    return identify(sch.t_s, out.applied_kv, laser, input_name="voltage_kv", output_name="stroke_mm")


def test_recovers_the_papers_plant_within_the_issue_tolerance(from_applied):
    """Amplifier voltage -> laser stroke (the paper's measured pair) is P(s): 1 dB, 5 deg, static gain 2 %."""
    num, den = paper.plant_tf()
    r = from_applied
    db, deg = _errors(r.model, num, den)
    assert db < 1.0 and deg < 5.0
    p0 = num[-1] / den[-1]
    assert r.model.dc_gain == pytest.approx(p0, rel=0.02)
    assert float(r.static_map.slope(3.0)) == pytest.approx(p0, rel=0.02)
    assert np.all(np.real(r.model.poles) < 0)
    # what it actually achieves on this clean simulation (measured 0.16 dB / 0.22 deg), inside the tolerance
    assert db < 0.3 and deg < 1.0
    assert r.usable and r.reasons == []
    assert [round(p.mean_input) for p in r.points] == [2, 4]
    assert r.estimator == "periodic_fft" and r.points[0].period_s == pytest.approx(20.0, abs=1e-4)


def test_command_input_includes_the_amplifier_filter(campaign):
    """Commanded voltage -> stroke is the amplifier's 500 Hz filter times P(s); still within 1 dB / 5 deg of P."""
    sch, out, laser = campaign
    r = identify(sch.t_s, sch.command_kv, laser, input_name="voltage_kv", output_name="stroke_mm")
    num, den = paper.plant_tf()
    an, ad = amplifier_filter_tf()
    db_chain, deg_chain = _errors(r.model, np.polymul(num, an), np.polymul(den, ad))
    # the output-error fit runs at about 250 Hz, where the 500 Hz filter is only a small lag (measured
    # 0.42 dB / 4.0 deg from the chain, 0.42 dB / 1.8 deg from P)
    assert db_chain < 0.6 and deg_chain < 5.0
    db_p, deg_p = _errors(r.model, num, den)
    assert db_p < 1.0 and deg_p < 5.0
    lag = -np.degrees(np.angle(tf_freqresp(an, ad, [15.0])[0]))
    assert 1.5 < lag < 3.0


def test_dependence_verdict_validation_and_model_json(from_applied):
    r = from_applied
    assert r.dependence.verdict == "independent" and r.dependence.p_value > 0.01
    assert r.validation is not None and r.validation.compare_fit_pct > 95.0
    assert all(p.compare_fit_pct > 95.0 for p in r.points)
    # the held-out part is every third block of each operating point, spread over all of it
    for p in r.points:
        span = p.segment.end_s - p.segment.start_s
        assert p.t_holdout_s[0] < p.segment.start_s + 0.4 * span and p.t_holdout_s[-1] > p.segment.end_s - 0.4 * span
        assert 0.25 < p.t_holdout_s.size / (span * r.analysis_rate_hz) < 0.4
    m = json.loads(json.dumps(r.to_model_json(), allow_nan=False))
    np.testing.assert_allclose(m["num"], r.model.num)
    np.testing.assert_allclose(m["den"], r.model.den)
    assert m["den"][0] == 1.0 and len(m["poles"]) == len(m["den"]) - 1 and len(m["zeros"]) == len(m["num"]) - 1
    assert m["static_gain"] == pytest.approx(m["num"][-1] / m["den"][-1])
    assert m["units"]["input"] == "kV" and m["units"]["output"] == "mm"
    assert m["offset_dependence"]["verdict"] == "independent"
    assert m["static_map"]["degree"] == 1 and len(m["operating_points"]) == 2
    assert m["validation"]["compare_fit_pct"] == pytest.approx(r.validation.compare_fit_pct)
    assert m["vs_paper"]["max_db"] < 1.0 and m["frequency_band_hz"][0] < 0.1


def test_offset_dependent_dynamics_are_detected():
    """Two operating points from plants whose gain differs by 25 %: the test must say dependent."""
    s1, o1, y1 = _campaign([2.0], seed=1)
    num, den = paper.plant_tf()
    s2, o2, y2 = _campaign([4.0], seed=2, config=NominalConfig(num=tuple(1.25 * num), den=tuple(den)))
    t = np.concatenate([s1.t_s, s1.t_s[-1] + 1e-4 + s2.t_s])
    r = identify(t, np.concatenate([o1.applied_kv, o2.applied_kv]), np.concatenate([y1, y2]),
                 input_name="voltage_kv", output_name="stroke_mm", order=(4, 5), holdout_fraction=0.0)
    assert r.dependence.verdict == "dependent"
    assert r.dependence.spread_db == pytest.approx(20 * np.log10(1.25), abs=0.3)
    assert r.validation is None


@pytest.mark.parametrize("mutate, match", [
    (lambda t, u, y: (t[:50], u[:50], y[:50]), "too short"),
    (lambda t, u, y: (t, np.where(np.arange(u.size) == 500, np.nan, u), y), "non-finite"),
    (lambda t, u, y: (np.where(np.arange(t.size) == 300, t[299], t), u, y), "not strictly increasing"),
    (lambda t, u, y: (t, np.full(u.size, 2.0), y), "constant"),
    (lambda t, u, y: (t, u, y[:-1]), "one length"),
])
def test_bad_inputs_raise_one_clear_error(mutate, match):
    t = np.arange(0, 10, 0.001)
    u = np.sin(2 * np.pi * 3 * t)
    y = 0.5 * u
    with pytest.raises(BadInputError, match=match):
        identify(*mutate(t, u, y))


def test_bad_options_raise():
    t = np.arange(0, 10, 0.001)
    u = np.sin(2 * np.pi * 3 * t)
    with pytest.raises(BadInputError, match="unknown identify option"):
        identify(t, u, u, bandwidth=3)
    with pytest.raises(BadInputError, match="holdout_fraction"):
        identify(t, u, u, holdout_fraction=0.95)


def test_operating_points_that_saturate_the_laser_are_left_out():
    """At 7 kV +- 1 kV the stroke passes the laser ADC's 9.9 mm full scale: that point is set aside."""
    sch, out, laser = _campaign([3.0, 7.0], seed=3)
    assert np.max(out.stroke_mm) > 9.9 and np.max(laser) < 9.9
    r = identify(sch.t_s, out.applied_kv, laser, input_name="voltage_kv", output_name="stroke_mm", order=(4, 5))
    assert [round(p.mean_input) for p in r.points] == [3]
    assert any("clipped" in s.reason and round(s.level) == 7 for s in r.skipped)
    assert any("left out" in n for n in r.notes)
    kept = identify(sch.t_s, out.applied_kv, laser, input_name="voltage_kv", output_name="stroke_mm", order=(4, 5),
                    exclude_clipped=False)
    assert [round(p.mean_input) for p in kept.points] == [3, 7]
    # the clipped point's residual asks for a much lower gain (with two points the calibrated rank test has
    # little power; the corrections, means over 16 sub-blocks, show it: measured 0.068 apart)
    g = [po["gain_correction"] for po in kept.dependence.to_json()["per_offset"]]
    assert g[0] - g[1] > 0.05 and abs(g[0]) < 0.01
