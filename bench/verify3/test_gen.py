"""Checks that the verify3 generator does what its labels say (units: kV, mm, s).

Run: .venv/bin/hasel env -- .venv/bin/python -m pytest -q bench/verify3/test_gen.py
"""
import json
import os
import sys

import numpy as np
import pytest
from scipy import io as sio
from scipy import signal

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import gen  # noqa: E402
import plant as P  # noqa: E402
import score  # noqa: E402


def _lsim(v, fs, interp):
    """Reference simulation of P(s) with scipy's lsim (interp False: zoh, True: foh)."""
    num, den = P.paper_tf()
    sys_ = signal.lti(num, den)
    t = np.arange(len(v)) / fs
    x0 = np.linalg.solve(-sys_.to_ss().A, sys_.to_ss().B[:, 0] * v[0])
    _, y, _ = signal.lsim(sys_, v, t, X0=x0, interp=interp)
    return y


@pytest.mark.parametrize("conv,interp", [("zoh", False), ("foh", True)])
def test_linear_block_matches_scipy_lsim(conv, interp):
    """The self-made discretisation equals scipy.signal.lsim to 1e-6 mm."""
    fs = 500
    rng = np.random.default_rng(1)
    v = gen.rand_levels(fs, rng, dur=6.0)
    v = v + 0.5 * np.sin(2 * np.pi * 7 * np.arange(len(v)) / fs)
    y = P.Linear(*P.paper_tf(), 1 / fs, conv).run(v)
    yr = _lsim(v, fs, interp)
    assert np.max(np.abs(y - yr)) < 1e-6


def test_centred_is_half_sample_later_zoh():
    """'centred' = the zoh response read half a sample later (fine-grid check)."""
    fs, up = 200, 10
    rng = np.random.default_rng(2)
    v = gen.rand_levels(fs, rng, dur=4.0)
    yc = P.Linear(*P.paper_tf(), 1 / fs, "centred").run(v)
    # fine zoh simulation, input held on [k - 1/2, k + 1/2) samples
    vf = np.repeat(v, up)
    vf = np.concatenate([vf[up // 2:], np.full(up // 2, v[-1])])
    yf = P.Linear(*P.paper_tf(), 1 / (fs * up), "zoh").run(vf)
    assert np.max(np.abs(yc[:-1] - yf[::up][:-1])) < 1e-6


def test_fractional_delay_exact():
    """A pure delay of 2.4 samples equals a fine-grid shift of 24 fine samples."""
    fs, up = 200, 10
    v = gen.rand_levels(fs, np.random.default_rng(3), dur=4.0)
    yd = P.Linear(*P.paper_tf(), 1 / fs, "zoh", skew=-2.4).run(v)
    vf = np.repeat(v, up)
    vf = np.concatenate([np.full(24, v[0]), vf[:-24]])
    yf = P.Linear(*P.paper_tf(), 1 / (fs * up), "zoh").run(vf)
    assert np.max(np.abs(yd - yf[::up])) < 1e-6


def test_dc_gain_and_paper_numbers():
    """P(s) of eq. (17): static gain 1.351 mm/kV, notch at 19.45 Hz."""
    num, den = P.paper_tf()
    assert abs(P.dc_gain(num, den) - 1.3509) < 1e-3
    assert abs(P.freq_resp(num, den, [122.2 / (2 * np.pi)])[0]) < 1e-9
    assert abs(P.dc_gain(*P.loaded_tf()) - 1.3509) < 1e-3
    assert abs(P.dc_gain(*P.third_pair_tf()) - 1.3509) < 1e-3


@pytest.fixture(scope="module")
def corpus(tmp_path_factory):
    """A small generated corpus: a few cases of each kind."""
    out = str(tmp_path_factory.mktemp("v3"))
    gen.main(["--out", out, "--only", "id14,id18,fr02,fr07,si06,si08,nf02,pa01"])
    return out


def _load(out, cid, kind="train"):
    d = np.loadtxt(os.path.join(out, "cases", cid, kind + ".csv"), delimiter=",", skiprows=1)
    with open(os.path.join(out, "labels", cid + ".json")) as fh:
        return d[:, 0], d[:, 1], d[:, 2], json.load(fh)


def test_effect_free_matches_plant_to_noise(corpus):
    """Effect-free logs: y - P(s) v (lsim, zoh) is white noise of the labelled std."""
    for cid in ("id14", "fr02"):
        t, v, y, lab = _load(corpus, cid)
        assert lab["effects"] == []
        r = y - _lsim(v, lab["fs"], False)
        assert abs(np.std(r) - lab["noise"]["white"]) < 0.1 * lab["noise"]["white"]
        assert abs(np.mean(r)) < 3 * lab["noise"]["white"] / np.sqrt(len(r)) * 3


def test_coloured_noise_case_is_coloured(corpus):
    """fr07 carries AR(1) noise: residual lag-10 autocorrelation well above white."""
    t, v, y, lab = _load(corpus, "fr07")
    r = y - _lsim(v, lab["fs"], False)
    r = r - r.mean()
    ac = np.dot(r[:-10], r[10:]) / np.dot(r, r)
    assert lab["noise"]["colour"] > 0 and ac > 0.5


def test_formats_round_trip(corpus):
    """CSV, MAT and MCAP hold the same samples (MCAP: Float64 per sample, log time)."""
    from mcap_ros2.reader import read_ros2_messages
    t, v, y, lab = _load(corpus, "fr02")
    m = sio.loadmat(os.path.join(corpus, "cases", "fr02", "train.mat"))
    assert np.allclose(m["t_s"].ravel(), t) and np.allclose(m["voltage_kv"].ravel(), v)
    assert np.allclose(m["stroke_mm"].ravel(), y)
    vin, vout, tin = [], [], []
    for msg in read_ros2_messages(os.path.join(corpus, "cases", "fr02", "train.mcap")):
        if msg.channel.topic == gen.IN_TOPIC:
            vin.append(msg.ros_msg.data)
            tin.append(msg.log_time_ns)
        elif msg.channel.topic == gen.OUT_TOPIC:
            vout.append(msg.ros_msg.data)
    assert np.allclose(vin, v, atol=1e-6) and np.allclose(vout, y, atol=1e-6)
    assert np.allclose((np.array(tin) - gen.MCAP_T0_NS) * 1e-9, t, atol=1e-7)
    with open(os.path.join(corpus, "cases", "fr02", "model.json")) as fh:
        mod = json.load(fh)
    assert np.allclose(mod["num"], P.paper_tf()[0]) and np.allclose(mod["den"], P.paper_tf()[1])
    case = json.load(open(os.path.join(corpus, "cases", "fr02", "case.json")))
    assert "effects" not in case and "category" not in case


@pytest.mark.parametrize("form", sorted(gen.FORMS))
def test_each_form_visibly_changes_output(form):
    """Every effect form at strength 1 moves the output by > 3x the 0.01 mm noise
    (rms) on random level steps 1-8 kV or on two paper chirps (3 and 6 kV), and its
    family is a tool name."""
    assert gen.FORMS[form][0] in score.TOOL_NAMES
    r = max(gen.effect_rms(dict(fs=500, design=d, forms=[form]), 11, None)
            for d in ("rlev", "paper1x2"))
    assert r > 0.03


def test_singles_well_above_floor():
    """Every single-effect case moves its training output by >= 5x the noise std."""
    for c in gen.case_table():
        if c["cat"] == "single" and c["fs"] <= 1000:
            assert gen.effect_rms(c, 5, None) / 0.01 >= 5, c["id"]


def test_near_floor_is_near_floor(corpus):
    """nf02's effect rms is within 15 % of its target multiple of the noise."""
    lab = json.load(open(os.path.join(corpus, "labels", "nf02.json")))
    assert 0.6 < lab["effect_rms_over_white_sigma"] < 0.8


def test_hysteresis_makes_a_loop():
    """Bouc-Wen: on a slow triangle, v_eff on the way up is below v_eff down."""
    b = P.BoucWen()
    v = np.concatenate([np.linspace(2, 7, 500), np.linspace(7, 2, 500)])
    b.reset(v[0])
    u = np.array([b.step(x) for x in v])
    up, dn = u[250], u[750]  # both at 4.5 kV
    assert dn - up > 0.3


def test_hard_stop_piles_samples(corpus):
    """si08 (hard stop at 8.2 mm): many noise-free samples sit on the stop."""
    t, v, y, lab = _load(corpus, "si08")
    assert lab["effects"][0]["form"] == "sat_hardstop"
    assert np.mean(y > 8.2 + 0.05) < 0.001 and np.mean(np.abs(y - 8.2) < 0.03) > 0.05


def test_closed_loop_tracks_reference(corpus):
    """id18 (closed loop, random references): stroke settles on each reference."""
    t, v, y, lab = _load(corpus, "id18")
    assert lab["closed_loop"] and v.min() >= 0 and v.max() <= 9
    hold = int(1.5 * lab["fs"])
    ends = y[hold - 20::hold][:10]
    assert np.all(np.diff(ends) != 0) and np.std(y) > 0.5


def test_scorer_matching():
    """Precision/recall matching: a name counts once, alternatives accepted."""
    truth = [dict(accept=["saturation", "static_nonlinearity"]), dict(accept=["time_delay"])]
    assert score.match(["static_nonlinearity", "time_delay", "saturation"], truth) == (2, 2)
    assert score.match(["load_mass"], truth) == (0, 0)
    e = score.ident_error({"num": list(P.paper_tf()[0]), "den": list(P.paper_tf()[1])})
    assert e["max_db"] < 1e-9 and e["max_deg"] < 1e-9
    assert score.offset_verdict({"offset_dependence": {"p_value": 0.01}})[0] is True
    assert score.offset_verdict({"x": {"offset_dependence": "independent (p = 0.4)"}})[0] is False


def test_scorer_flag_and_shrink():
    """Flag heuristic finds a 'did not generalise' list; shrink = 1 - aug/nom."""
    v = {"effects": [], "heldout": {"nrmse_nominal": 0.2, "nrmse_augmented": 0.05},
         "did_not_generalise": [{"name": "hysteresis"}]}
    assert score.flagged(v) == "/did_not_generalise"
    assert abs(score.shrink(v)[0] - 0.75) < 1e-12
    assert score.flagged({"effects": [], "did_not_generalise": []}) is None
