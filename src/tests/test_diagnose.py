"""Gap diagnosis: preparation, simulation, noise floor, error model, and verdicts on truth-plant logs."""
from __future__ import annotations

import json
import math

import numpy as np
import pytest
from scipy import signal

from hasel import paper
from hasel.diagnose import DiagnoseOptions, diagnose
from hasel_bench.blind import excitation
from hasel.diagnose.linfit import fit_linear
from hasel.diagnose.prep import (LinearSim, dominant_time_constant_s, estimate_noise, excited_band_hz, nrmse, prepare,
                                 rest_start)
from hasel.diagnose.where import model_error_model
from hasel.effects import EFFECT_NAMES, TruthActuator, from_name
from hasel.errors import BadInputError
from hasel.lti import tf_freqresp
from hasel.plant import amplifier_filter_tf


def _nominal() -> tuple[np.ndarray, np.ndarray]:
    an, ad = amplifier_filter_tf()
    num, den = paper.plant_tf()
    return np.polymul(an, num), np.polymul(ad, den)


def _log(effects, seed: int, noise_mm: float = 0.005):
    rng = np.random.default_rng(seed)
    u = excitation(rng, quick=True)
    act = TruthActuator(effects)
    act.reset(float(u[0]))
    z = act.measure_mm(act.run(u).stroke_mm)
    return np.arange(u.size) / act.rate_hz, u, z + noise_mm * rng.standard_normal(u.size)


def test_nrmse_definition():
    y = np.array([1.0, 2.0, 3.0, 4.0])
    assert nrmse(y, y) == 0.0
    assert nrmse(y, np.full(4, y.mean())) == pytest.approx(1.0)
    assert nrmse(y, y + 0.5) == pytest.approx(0.5 * 2 / math.sqrt(5))


def test_prepare_rate_split_and_blocks():
    t = np.arange(200_000) / 10_000.0
    u = signal.chirp(t, 0.1, t[-1], 10.0)
    p = prepare(t, u, u)
    r = p.records[0]
    assert 150.0 <= p.rate_hz <= 500.0 and p.rate_hz * p.decimation == pytest.approx(10_000.0)
    # three disjoint parts: training, validation (choices), final (reported)
    parts = np.vstack([r.train, r.valid, r.hold]).astype(int)
    assert np.all(parts.sum(axis=0) == 1)
    assert 0.6 < r.train.mean() < 0.75 and 0.12 < r.valid.mean() < 0.22 and 0.12 < r.hold.mean() < 0.22
    # block means: exactly the mean of each group of original samples
    np.testing.assert_allclose(r.u[:3], u[:3 * p.decimation].reshape(3, -1).mean(axis=1))
    # no two non-training blocks touch: every non-training run is bordered by training samples
    d = np.diff(np.concatenate([[0], (~r.train).astype(int), [0]]))
    for s0, s1 in zip(np.flatnonzero(d == 1), np.flatnonzero(d == -1)):  # [s0, s1) a non-training run
        assert r.valid[s0:s1].all() or r.hold[s0:s1].all()
    # a separate held-out log is the final part; the first log keeps one block in three to validate
    p2 = prepare(t, u, u, heldout=(t, u, u))
    r0, r1 = p2.records
    assert r1.hold.all() and not r1.valid.any() and not r0.hold.any()
    assert 0.25 < r0.valid.mean() < 0.4 and np.all(r0.train ^ r0.valid)


def test_prepare_keeps_the_whole_log_when_a_lower_whole_rate_allows():
    # a 50 s, 2 kHz chirp to 40 Hz: the cap of 60 000 working samples asks for 1.2 kHz, which is no whole
    # factor of 2 kHz; rounding the factor down kept 2 kHz and cut the log after 30 s (its last operating
    # level lost). Factor 2 (1 kHz, above 8 x the band's top) keeps all 50 s
    fs = 2000.0
    t = np.arange(100_000) / fs
    u = 4.0 + np.sin(2 * np.pi * (0.5 + 0.39 * t) * t)
    p = prepare(t, u, u, max_samples=60_000)
    assert p.decimation == 2 and p.info["truncated_to_s"] is None
    assert p.records[0].t_s[-1] - p.records[0].t_s[0] == pytest.approx(50.0, abs=0.01)
    # where no whole factor at or above 8 x the band's top fits the cap, the lowest such rate is used and the
    # log is cut there, and says so
    q_min_rate = int(fs // (8 * excited_band_hz(u, fs)))
    p2 = prepare(t, u, u, max_samples=20_000)
    assert p2.decimation == q_min_rate and p2.records[0].u.size == 20_000
    assert p2.info["truncated_to_s"] == pytest.approx(20_000 * q_min_rate / fs, rel=1e-3)


def test_an_unsettled_start_is_simulated_from_the_rest_its_output_shows():
    # a closed loop's log: the controller commands 9 kV at the first sample while the stroke is still 0 mm (the
    # plant at rest at 0 kV before). Simulated at rest with its first input, the model starts 12 mm off
    num, den = _nominal()
    rate = 1000.0
    rng = np.random.default_rng(3)
    u = np.concatenate([np.full(50, 9.0), np.repeat(rng.uniform(1.0, 6.0, 40), 250)])
    t = np.arange(u.size) / rate
    y = LinearSim(num, den, rate).run(np.concatenate([[0.0], u]))[1:] + 0.005 * rng.standard_normal(u.size)
    p = prepare(t, u, y, heldout=(t, u, y), target_rate_hz=rate)
    tau = dominant_time_constant_s(den)
    notes = rest_start(p, num, den)
    assert [n["record"] for n in notes] == [0, 1]
    assert all(abs(n["level"]) < 0.01 and n["first_input"] == 9.0 for n in notes)
    assert notes[0]["left_out_s"] == pytest.approx(3 * tau, abs=2 / rate)
    for r in p.records:
        # one sample before the log at the level found, then the log; the first three time constants in no score
        assert r.u.size == u.size + 1 and r.u[0] == notes[0]["level"] and r.u[1] == 9.0
        scored = r.train | r.valid | r.hold
        assert not scored[:int(3 * tau * rate)].any() and scored[int(3 * tau * rate) + 2:].mean() > 0.6
    e = p.records[1].y - p.sim(num, den).run(p.records[1].u)
    assert np.sqrt(np.mean(e[p.records[1].hold] ** 2)) < 0.01   # down to the noise: no start artefact left
    # a log that starts settled (or whose first output agrees with rest at its first input) is left alone
    y2 = LinearSim(num, den, rate).run(u) + 0.005 * rng.standard_normal(u.size)
    p2 = prepare(t, u, y2, target_rate_hz=rate)
    assert rest_start(p2, num, den) == [] and p2.records[0].u.size == u.size


def test_prepare_rejects_unusable_logs():
    with pytest.raises(BadInputError, match="at least 50"):
        prepare(np.arange(10.0), np.arange(10.0), np.arange(10.0))
    with pytest.raises(BadInputError, match="one length"):
        prepare(np.arange(100.0), np.arange(99.0), np.arange(100.0))


def test_linear_sim_matches_the_frequency_response():
    num, den = [5.0, 40.0], np.polymul([1.0, 4.0], [1.0, 6.0, 225.0])
    rate, f = 400.0, 1.7
    t = np.arange(int(40 * rate)) / rate
    u = np.sin(2 * np.pi * f * t)
    g = tf_freqresp(num, den, [f])[0]
    tail = t > 20
    # zero-order hold by default: each sample held over its interval, the output taken at its start,
    # i.e. the response of a sine delayed by half a sample (the hold's lag) at the sample instants
    y = LinearSim(num, den, rate).run(u)
    ref = abs(g) * np.sin(2 * np.pi * f * (t - 0.5 / rate) + np.angle(g))
    assert np.max(np.abs(y[tail] - ref[tail])) < 2e-3 * abs(g)
    # taken half a sample into the interval (centred samples, block means), there is no lag at all
    y_c = LinearSim(num, den, rate, offset=0.5).run(u)
    ref_c = abs(g) * np.sin(2 * np.pi * f * t + np.angle(g))
    assert np.max(np.abs(y_c[tail] - ref_c[tail])) < 2e-3 * abs(g)
    assert np.max(np.abs(y[tail] - ref_c[tail])) > 5e-3 * abs(g)  # the two conventions differ measurably


def test_noise_estimate_of_white_noise_on_a_smooth_signal(rng=None):
    rng = np.random.default_rng(5)
    t = np.arange(40_000) / 1000.0
    smooth = np.sin(2 * np.pi * 0.7 * t) + 0.3 * np.sin(2 * np.pi * 3.1 * t)
    for sigma in (0.01, 0.1):
        var, method = estimate_noise(smooth + sigma * rng.standard_normal(t.size), 1000.0, 3.1)
        assert method == "spectral"
        assert math.sqrt(var) == pytest.approx(sigma, rel=0.1)


def test_model_error_model_recovers_a_linear_difference():
    rng = np.random.default_rng(3)
    rate = 200.0
    u = signal.lfilter([1.0], [1.0, -0.9], rng.standard_normal(20_000))
    g1, g2 = ([10.0], [1.0, 10.0]), ([12.0], [1.0, 10.0])  # 20 % more gain
    r = LinearSim(*g2, rate).run(u) - LinearSim(*g1, rate).run(u) + 0.01 * rng.standard_normal(u.size)
    f = np.array([0.2, 1.0, 3.0])
    mem = model_error_model(u, r, rate, 60, f)
    expect = np.abs(tf_freqresp(*g2, f) - tf_freqresp(*g1, f))
    np.testing.assert_allclose(mem["mag"], expect, rtol=0.1)
    assert all(mem["significant"]) and mem["linear_share"] > 0.95


def test_linear_fit_recovers_a_second_order_model():
    rng = np.random.default_rng(11)
    rate = 100.0
    t = np.arange(6000) / rate
    u = np.repeat(rng.uniform(-1, 1, 60), 100)
    num, den = [0.0, 30.0], [1.0, 4.0, 25.0]
    y = LinearSim(num, den, rate).run(u) + 0.7 + 1e-3 * rng.standard_normal(u.size)  # an offset too
    p = prepare(t, u, y)
    n2, d2, info = fit_linear(p, max_order=3)
    assert info["order"] == 2
    np.testing.assert_allclose(np.sort_complex(np.roots(d2)), np.sort_complex(np.roots(den)), rtol=0.02)
    assert n2[-1] / d2[-1] == pytest.approx(30.0 / 25.0, rel=0.02)  # the offset is not in the model


def test_no_effect_names_nothing_and_reaches_the_floor():
    t, u, y = _log([], seed=21)
    v = diagnose(t, u, y, model=_nominal())
    assert v.effects == []
    assert v.heldout["nrmse_nominal"] < 1.3 * v.noise_floor_nrmse


@pytest.mark.parametrize("effect,seed", [
    (from_name("time_delay", delay_s=0.012), 22),
    (from_name("static_nonlinearity", kind="electrostatic", strength=0.4), 23),
    (from_name("hysteresis", half_width_kv=0.3, h_sat_kv=0.5), 24),
])
def test_single_effect_is_named_first_and_the_gap_shrinks(effect, seed):
    t, u, y = _log([effect], seed=seed)
    v = diagnose(t, u, y, model=_nominal(), units=("kV", "mm"))
    assert v.names[0] == effect.name
    h = v.heldout
    assert (h["nrmse_nominal"] - h["nrmse_augmented"]) / (h["nrmse_nominal"] - v.noise_floor_nrmse) > 0.7
    if effect.name == "time_delay":
        assert v.effects[0]["params"]["delay_s"] == pytest.approx(0.012, rel=0.15)


def test_verdict_json_has_the_promised_shape():
    t, u, y = _log([from_name("sensor_nonlinearity", bow_mm=0.4)], seed=25)
    v = diagnose(t, u, y, model={"num": list(_nominal()[0]), "den": list(_nominal()[1])})
    out = json.loads(json.dumps(v.to_json(), default=float))
    assert {"effects", "where", "heldout", "noise_floor_nrmse"} <= set(out)
    assert {"nrmse_nominal", "nrmse_augmented"} <= set(out["heldout"])
    for e in out["effects"]:
        assert e["name"] in EFFECT_NAMES and {"params", "evidence", "nrmse_after"} <= set(e)
    assert {"frequency", "time", "level", "direction", "amplitude"} <= set(out["where"])
    assert out["effects"][0]["name"] == "sensor_nonlinearity"
    ex = v.export
    assert set(ex) == {"t_s", "measured", "nominal", "augmented"} and ex["t_s"].size == v.heldout["n_samples"]
    assert nrmse(ex["measured"], ex["augmented"]) == pytest.approx(v.heldout["nrmse_augmented"], rel=1e-9)


def test_the_models_own_delay_is_part_of_the_nominal():
    t, u, y = _log([from_name("time_delay", delay_s=0.01)], seed=26)
    num, den = _nominal()
    v = diagnose(t, u, y, model={"num": list(num), "den": list(den), "delay_s": 0.01})
    assert "time_delay" not in v.names


def test_bad_models_are_bad_input():
    t, u, y = _log([], seed=27)
    with pytest.raises(BadInputError, match="stable"):
        diagnose(t, u, y, model=([1.0], [1.0, -2.0]))
    with pytest.raises(BadInputError, match="'num' and 'den'"):
        diagnose(t, u, y, model={"num": [1.0]})
    with pytest.raises(BadInputError, match="identify must be"):
        diagnose(t, u, y, options=DiagnoseOptions(identify="magic"))


def test_change_between_repeats_is_noise_for_the_nominal_and_a_trend_with_drift():
    from hasel.signals import protocol_schedule

    sched = protocol_schedule([3.0, 5.0], kind="paper", repeats=3, duration_s=5.0)
    rng = np.random.default_rng(9)
    out = {}
    for name, effects in (("nominal", []), ("drift", [from_name("charge_drift", tau_s=30.0, gain_loss_per_kv=0.02)])):
        act = TruthActuator(effects)
        act.reset(0.0)
        y = act.run(sched.command_kv).stroke_mm + 0.003 * rng.standard_normal(sched.t_s.size)
        v = diagnose(sched.t_s, sched.command_kv, y, model=_nominal(), options=DiagnoseOptions(max_effects=1))
        out[name] = v.where["time"]["repeats"]
    assert out["nominal"]["period_s"] == pytest.approx(5.0, rel=1e-3)
    assert out["nominal"]["over_noise"] == pytest.approx(1.0, abs=0.25)  # an independent check of the floor
    assert out["drift"]["over_noise"] > 5.0 and out["drift"]["mean_change_per_period"] < 0  # the gain drains


def test_flat_extremes_find_a_clip_and_not_quantised_noise():
    from hasel.diagnose.prep import flat_extremes

    rng = np.random.default_rng(4)
    t = np.arange(4000) / 100.0
    y = 5.0 + 6.0 * np.sin(2 * np.pi * 0.1 * t) + 0.05 * rng.standard_normal(t.size)
    clipped = np.minimum(y, 10.0)
    found = flat_extremes(clipped)
    assert set(found) == {"upper"} and found["upper"][0] == 10.0
    assert found["upper"][1].sum() == np.sum(y >= 10.0)
    assert flat_extremes(np.round(y / 0.01) * 0.01) == {}  # quantised noise spreads over many values


def test_an_output_clip_is_named_saturation_at_the_measured_value():
    # a first-order system whose sensor clips at 1.2: the output piles up there while the model goes beyond
    rng = np.random.default_rng(6)
    rate = 200.0
    t = np.arange(int(60 * rate)) / rate
    u = np.repeat(rng.uniform(0.0, 1.6, 60), int(rate))
    num, den = [2.0], [1.0, 2.0]
    y = np.minimum(LinearSim(num, den, rate).run(u), 1.2) + 0.005 * rng.standard_normal(t.size)
    y = np.minimum(y, 1.2)
    v = diagnose(t, u, y, model=(num, den), options=DiagnoseOptions(max_effects=1))
    assert v.names[0] == "saturation"
    p = v.effects[0]["params"]
    assert p["acts_on"] == "output" and p["upper"] == pytest.approx(1.2)
    assert v.heldout["nrmse_augmented"] < 0.3 * v.heldout["nrmse_nominal"]


def test_drift_is_told_from_a_static_map_by_the_change_between_repeats():
    # the offsets rise with time, so the drift's level part looks like a static map; between repeats
    # of the excitation (same input), only a drift changes the output
    from hasel.signals import protocol_schedule

    sched = protocol_schedule([2.0, 4.0, 6.0], kind="paper", repeats=3, duration_s=4.0)
    rng = np.random.default_rng(12)
    act = TruthActuator([from_name("static_nonlinearity", kind="electrostatic", strength=0.3),
                         from_name("charge_drift", tau_s=20.0, gain_loss_per_kv=0.01, offset_mm_per_kv=0.05)])
    act.reset(0.0)
    y = act.run(sched.command_kv).stroke_mm + 0.003 * rng.standard_normal(sched.t_s.size)
    v = diagnose(sched.t_s, sched.command_kv, y, model=_nominal(), units=("kV", "mm"))
    assert {"static_nonlinearity", "charge_drift"} <= set(v.names[:2])
    assert v.where["time"]["repeats"]["over_noise"] > 3.0


def test_a_fallback_nominal_is_flagged_when_identify_refuses_the_log():
    """Without --model, a log that hasel.ident refuses (a stroke clip at 4 mm and a strong input map make
    no linear model pass its checks) falls back to the internal fit: the verdict must say so, first."""
    from hasel.diagnose.core import Verdict
    from hasel.diagnose.setup_stages import _identify
    from hasel.diagnose.report import verdict_lines

    rng = np.random.default_rng(31)
    u = excitation(rng, quick=True)
    act = TruthActuator([from_name("saturation", kind="stroke", limit_mm=4.0),
                         from_name("static_nonlinearity", kind="electrostatic", strength=0.6)])
    act.reset(float(u[0]))
    y = act.measure_mm(act.run(u).stroke_mm) + 0.005 * rng.standard_normal(u.size)
    _, _, src = _identify(prepare(np.arange(u.size) / act.rate_hz, u, y), DiagnoseOptions(), lambda m: None)
    assert src["source"] == "identified from the log"
    assert "failed its own checks" in src["details"]["note"]
    assert src["training_nrmse_with_offset"] > 0.2  # the fit it falls back to misses a fifth of the output
    assert "fallback" in src["warning"] and "--model" in src["warning"]
    v = Verdict(effects=[], where={}, heldout={"nrmse_nominal": 0.3, "nrmse_augmented": 0.3, "gap_shrink": 0.0},
                noise_floor_nrmse=0.01, model=src, rounds=[], working_rate_hz=1000.0)
    assert verdict_lines(v)[0] == "warning: " + src["warning"]
