"""Fast checks of the verify2 generator and simulator (pytest; no hasel code involved)."""
import json
import os
import sys

import numpy as np
import pytest
from scipy import io as sio
from scipy import signal

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import gen  # noqa: E402
import plant  # noqa: E402


def test_dc_gain_equals_p0_for_every_plant():
    """A constant input settles at P(0) * v for the nominal and every load form."""
    n0, d0 = plant.paper_tf()
    g0 = plant.dc_gain(n0, d0)
    assert g0 == pytest.approx(10.836 * 50.27 * 62.83 * 628.3 / (18.85 * 56.55 * 122.2 ** 2),
                               rel=1e-12)
    for mu, form in [(0.0, "a"), (0.45, "a"), (0.6, "b"), (0.5, "c")]:
        num, den = plant.paper_tf(mu, form)
        lti = plant.LTI(plant.zoh_sections(num, den, 1e-3), 0.0)
        y = lti.run(np.full(20000, 4.0))          # 20 s at 1 kHz from rest at 0 kV
        assert y[-1] == pytest.approx(4.0 * g0, rel=1e-6)


def test_zoh_simulation_matches_continuous_step_response():
    """The discretised plant reproduces scipy's continuous step response at the samples."""
    num, den = plant.paper_tf()
    dt = 1e-3
    lti = plant.LTI(plant.zoh_sections(num, den, dt), 0.0)
    y = lti.run(np.ones(2000))
    t = np.arange(2000) * dt
    _, yc = signal.step((num, den), T=t)
    assert np.max(np.abs(y - yc)) < 1e-6


def test_load_moves_the_resonance_down():
    """The load forms lower the double-pole frequency by 1/sqrt(1+mu)."""
    for mu, form in [(0.45, "a"), (0.6, "b")]:
        _, den = plant.paper_tf(mu, form)
        wn = np.sort(np.abs(np.roots(den)))[-1]
        assert wn == pytest.approx(122.2 / np.sqrt(1 + mu), rel=1e-4)


def test_delay_form_delays():
    """An input delay of d shifts the whole response by d, exactly on the fine grid."""
    fs = 1000.0
    des = gen.random_steps_design(np.random.default_rng(0), 5.0)
    t, u, y0, _ = gen.sim_open([], des, fs, "zoh", 0.0)
    e = {"name": "time_delay", "form": "a", "params": {"delay_s": 0.004}}
    _, _, y1, _ = gen.sim_open([e], des, fs, "zoh", 0.0)
    np.testing.assert_allclose(y1[4:], y0[:-4], atol=1e-9)
    assert np.max(np.abs(y1 - y0)) > 0.05


def test_skew_and_centred_conventions_shift_the_output():
    """A +0.5-sample output skew equals sampling half a sample later (a 2 kHz ZOH run)."""
    des = gen.random_steps_design(np.random.default_rng(1), 3.0)
    t1, _, y1, sk = gen.sim_open([], des, 1000.0, "skew", 0.5)
    assert sk == 0.5
    t2 = np.arange(int(round(des.t * 2000))) / 2000
    u2 = np.repeat(des(t1), 2)[:len(t2)]
    y2, _ = plant.simulate_open([], t2, des, u2, "zoh", 0.0, 8)
    np.testing.assert_allclose(y1[:-1], y2[1::2][:len(y1) - 1], atol=1e-9)


def test_noise_levels():
    """Coloured noise has the requested rms; wander adds a slow component."""
    rng = np.random.default_rng(3)
    e, fc = gen.make_noise(rng, 20000, 1000.0, "coloured", 0.01, 0.0)
    assert np.std(e) == pytest.approx(0.01, rel=1e-6) and 2 <= fc <= 20
    w, _ = gen.make_noise(rng, 20000, 1000.0, "white", 0.01, 0.02)
    assert np.std(w) > 0.015


def test_files_parse_and_labels_complete(tmp_path):
    """A small corpus: CSV/MAT/MCAP files parse back to the logged samples, labels complete."""
    b = gen.Builder(str(tmp_path), 5)
    b.diag("d_csv", "single", [("hysteresis", "a")], 200, train="prbs", held="random_steps",
           train_s=12, held_s=6)
    b.diag("d_mat", "effect_free", [], 200, fmt="mat", train="multisine", train_s=12, held_s=6)
    b.diag("d_mcap", "near_floor", [("time_delay", "a")], 200, fmt="mcap", train="log_chirp",
           train_s=12, held_s=6, target_ratio=0.5)
    b.ident("i_cl", "closed_loop_steps", 200)
    for cid in ["d_csv", "d_mat", "d_mcap", "i_cl"]:
        lab = json.load(open(tmp_path / "labels" / (cid + ".json")))
        for k in ["id", "kind", "category", "rate_hz", "noise", "convention", "format", "args",
                  "closed_loop"]:
            assert k in lab, (cid, k)
        cdir = tmp_path / "cases" / cid
        assert (cdir / lab["files"]["train"]).exists()
        if lab["kind"] == "diagnose":
            for k in ["effects", "truth_names", "effect_rms_over_noise", "timing_offset_samples",
                      "design_train", "design_heldout"]:
                assert k in lab, (cid, k)
            for e in lab["effects"]:
                assert e["name"] in gen.NAMES and e["form"] in "abc" and e["params"]
            m = json.load(open(cdir / "model.json"))
            num, den = plant.paper_tf()
            np.testing.assert_allclose(m["num"], num)
            np.testing.assert_allclose(m["den"], den)
            assert "--model" in lab["args"] and "--heldout" in lab["args"]
    d = np.loadtxt(tmp_path / "cases" / "d_csv" / "train.csv", delimiter=",", skiprows=1)
    assert d.shape[1] == 3 and np.allclose(np.diff(d[:, 0]), 0.005)
    mat = sio.loadmat(tmp_path / "cases" / "d_mat" / "train.mat")
    assert mat["t_s"].shape == mat["voltage_kv"].shape == mat["stroke_mm"].shape
    from mcap_ros2.reader import read_ros2_messages
    vals = {}
    for m in read_ros2_messages(str(tmp_path / "cases" / "d_mcap" / "train.mcap")):
        vals.setdefault(m.channel.topic, []).append(m.ros_msg.data)
    assert set(vals) == {"/rig/voltage_kv", "/rig/stroke_mm"}
    assert len(vals["/rig/voltage_kv"]) == len(vals["/rig/stroke_mm"]) >= 11 * 200
    lab = json.load(open(tmp_path / "labels" / "d_mcap.json"))
    assert 0.2 <= lab["effect_rms_over_noise"] <= 1.0
    lab = json.load(open(tmp_path / "labels" / "d_csv.json"))
    assert lab["effect_rms_over_noise"] >= 5.0
