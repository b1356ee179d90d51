"""Diagnosis that does not invent effects: sampling conventions, coloured noise, generalisation, ambiguity,
unusable models. Effect-free logs come from the independent simulator's calibration logs (hasel_bench.othersim)."""
from __future__ import annotations

import json
import subprocess
import sys

import numpy as np
import pytest

from hasel.diagnose import DiagnoseOptions, diagnose
from hasel.diagnose.augment import EffectFit, Pipeline
from hasel.diagnose.core import DiagnosisFailed, _generalise
from hasel.diagnose.prep import LinearSim, prepare
from hasel.diagnose.setup_stages import timing_stage
from hasel.diagnose.significance import _alike, block_test
from hasel.effects.heldout import block_labels
from hasel_bench.othersim import make_free_case


def _diagnose_file(path):
    d = np.load(path)
    return diagnose(d["t_s"], d["voltage_kv"], d["stroke_mm"], units=("kV", "mm"),
                    model={"num": d["num"].tolist(), "den": d["den"].tolist()})


@pytest.mark.parametrize("convention,offset,noise,lag", [
    ("zoh", 0.0, "white", 0.0),        # the plant's own convention: nothing to shift
    ("foh", 0.0, "white", -0.5),       # a first-order hold leads a held input by half a sample
    ("centred", 0.3, "white", -0.2),   # mid-sample output, 0.3 samples late
    ("zoh", -0.4, "coloured", -0.4),   # a fractional clock offset under coloured noise
])
def test_effect_free_logs_name_nothing_and_report_the_timing(tmp_path, convention, offset, noise, lag):
    c = make_free_case(0, 11, str(tmp_path), design="chirp", rate_hz=1000.0, convention=convention,
                       offset_samples=offset, noise=noise, duration_s=20.0)
    v = _diagnose_file(c.path)
    assert v.names == []
    assert v.timing_offset["original_samples"] == pytest.approx(lag, abs=0.15)
    assert "not a delay" in v.timing_offset["note"]
    assert v.to_json()["usable"] is True


def test_a_closed_loop_log_with_sensor_wander_names_nothing(tmp_path):
    c = make_free_case(1, 8008, str(tmp_path), design="closed_loop", rate_hz=1000.0, noise="wander",
                       duration_s=30.0)
    v = _diagnose_file(c.path)
    assert v.names == []
    assert v.noise["trust"].startswith("low")  # the wander makes the spectral floor a lower bound
    assert any("slow part" in n for n in v.noise["trust_notes"])  # the same reason, as a list for readers


def test_a_held_out_block_test_ignores_coloured_noise_but_not_a_real_change():
    rng = np.random.default_rng(2)
    n, nb = 6000, 40
    labels = np.repeat(np.arange(nb), n // nb)
    from scipy import signal
    noise = signal.lfilter([0.05], [1.0, -0.95], rng.standard_normal(n))  # strongly coloured
    fit_to_noise = noise + 0.3 * signal.lfilter([0.05], [1.0, -0.95], rng.standard_normal(n))
    assert block_test(noise, fit_to_noise, labels) < 2.0  # "explaining" noise does not generalise
    effect = 0.5 * np.sin(np.arange(n) / 30.0)
    assert block_test(noise + effect, noise, labels) > 4.0


def _free_pipe(tmp_path):
    c = make_free_case(2, 21, str(tmp_path), design="multisine", rate_hz=500.0, convention="zoh",
                       offset_samples=0.0, noise="white", duration_s=30.0)
    d = np.load(c.path)
    prep = prepare(d["t_s"], d["voltage_kv"], d["stroke_mm"])
    timing_stage(prep, d["num"], d["den"], 0.0, lambda m: None)
    return Pipeline(prep, d["num"], d["den"])


def test_an_effect_that_does_not_generalise_is_dropped_with_its_numbers(tmp_path):
    pipe = _free_pipe(tmp_path)
    y_fi = pipe.prep.stacked("y", "hold")
    norm = float(np.sum((y_fi - y_fi.mean()) ** 2))

    def final_sse(eff):
        e = pipe.residuals(eff, "hold")
        return float(e @ e)

    wrong = {"time_delay": EffectFit("time_delay", "input", (0.02,))}  # 20 ms on a log without delay
    kept, dropped = _generalise(pipe, wrong, {"time_delay": (0.4, None)}, final_sse, norm, ("kV", "mm"),
                                lambda m: None)
    assert kept == {}
    (d,) = dropped
    assert d["name"] == "time_delay" and "did not generalise" in d["reason"]
    assert d["final_nrmse_with"] > d["final_nrmse_without"]
    assert d["validation_gap_removed"] == 0.4
    assert d["exercised_by_heldout"] and "do not exercise" not in d["reason"]
    # a clip the final held-out input never reaches changes nothing there: said so, not called a failure
    idle = {"saturation": EffectFit("saturation", "input:upper", (1e3,))}
    kept, dropped = _generalise(pipe, idle, {"saturation": (0.9, None)}, final_sse, norm, ("kV", "mm"),
                                lambda m: None)
    (d,) = dropped
    assert not d["exercised_by_heldout"] and "do not exercise it" in d["reason"]
    assert d["final_nrmse_with"] == pytest.approx(d["final_nrmse_without"], rel=1e-9)


def test_two_explanations_that_score_alike_are_reported_with_the_separating_experiment(tmp_path):
    pipe = _free_pipe(tmp_path)
    labels = block_labels(pipe.prep, "valid")
    rng = np.random.default_rng(4)
    e_old = pipe.residuals({}, "valid") + 0.05 * np.sin(np.arange(labels.size) / 7.0)
    explained = 0.045 * np.sin(np.arange(labels.size) / 7.0)
    # two explanations of the same part, each off by its own independent error of one size
    e_a = e_old - explained + 0.003 * rng.standard_normal(labels.size)
    e_b = e_old - explained + 0.003 * rng.standard_normal(labels.size)
    m0 = float(np.mean(e_old ** 2))
    gain = 1 - float(np.mean(e_a ** 2)) / m0
    results = [(float(np.mean(e_a ** 2)), 5, "static_nonlinearity", None, 0.0, e_a, {"static_nonlinearity": None}),
               (float(np.mean(e_b ** 2)), 4, "sensor_nonlinearity", None, 0.0, e_b, {"sensor_nonlinearity": None})]
    a = _alike(results, {"static_nonlinearity": None}, e_a, m0, gain, labels, DiagnoseOptions(), lambda m: m)
    assert a["chosen"] == "static_nonlinearity" and a["alternative"] == "sensor_nonlinearity"
    assert a["gap_removed"]["alternative"] > 0.9 * a["gap_removed"]["chosen"]
    assert "above the resonance" in a["experiment"]
    # a clearly worse alternative is not "alike"
    e_c = e_old - 0.02 * np.sin(np.arange(labels.size) / 7.0)
    results[1] = (float(np.mean(e_c ** 2)), 4, "sensor_nonlinearity", None, 0.0, e_c, {"sensor_nonlinearity": None})
    assert _alike(results, {"static_nonlinearity": None}, e_a, m0, gain, labels, DiagnoseOptions(),
                  lambda m: m) is None


def test_a_model_marked_unusable_fails_with_exit_1_and_a_json(tmp_path):
    rate = 200.0
    t = np.arange(4000) / rate
    u = np.repeat(np.random.default_rng(1).uniform(0, 2, 40), 100)
    y = LinearSim([2.0], [0.1, 1.0], rate).run(u)
    with pytest.raises(DiagnosisFailed) as err:
        diagnose(t, u, y, model={"num": [2.0], "den": [0.1, 1.0], "usable": False, "reasons": ["fit 12 %"]})
    assert err.value.payload["usable"] is False and "fit 12 %" in err.value.payload["reasons"]
    data = tmp_path / "log.csv"
    data.write_text("t_s,voltage_kv,stroke_mm\n" + "\n".join(f"{a},{b},{c}" for a, b, c in zip(t, u, y)) + "\n")
    model = tmp_path / "model.json"
    model.write_text(json.dumps({"num": [2.0], "den": [0.1, 1.0], "usable": False, "reasons": ["fit 12 %"]}))
    out = tmp_path / "v.json"
    p = subprocess.run([sys.executable, "-m", "hasel.cli", "diagnose", str(data), "--model", str(model),
                        "--json", str(out)], capture_output=True, text=True)
    assert p.returncode == 1
    assert "Traceback" not in p.stderr and p.stderr.strip().splitlines()[-1].startswith("hasel diagnose: failed:")
    assert json.loads(out.read_text())["usable"] is False


def test_a_model_far_off_the_data_fails_its_own_check():
    rate = 200.0
    t = np.arange(4000) / rate
    u = np.repeat(np.random.default_rng(1).uniform(0, 2, 40), 100)
    y = LinearSim([2.0], [0.1, 1.0], rate).run(u) + 0.01 * np.random.default_rng(2).standard_normal(t.size)
    with pytest.raises(DiagnosisFailed, match="fails its own check.*gain and sign agree"):
        # the right gain and sign (the scale check passes: 0.73 below 0.4 Hz) but 0.4 s late on 0.5 s levels
        diagnose(t, u, y, model={"num": [2.0], "den": [0.1, 1.0], "delay_s": 0.4},
                 options=DiagnoseOptions(max_effects=0))
