"""Checks of the verification corpus's generator (run by hand: pytest bench/verify)."""
from __future__ import annotations

import json
import sys
from pathlib import Path

import numpy as np
import pytest
from scipy import signal

sys.path.insert(0, str(Path(__file__).resolve().parent))
import gen  # noqa: E402
import plant as pl  # noqa: E402


def _ss_zoh(num, den, dt, u):
    """Reference: the discretised state-space loop, sample by sample."""
    A, B, C, D = signal.tf2ss(num, den)
    Ad, Bd, Cd, _, _ = signal.cont2discrete((A, B, C, D), dt, method="zoh")
    x = np.zeros((Ad.shape[0], 1))
    y = np.empty(u.size)
    for i, v in enumerate(u):
        y[i] = (Cd @ x)[0, 0]
        x = Ad @ x + Bd * v
    return y


def test_paper_tf_static_gain_and_load_keeps_it():
    num, den = pl.paper_tf()
    assert pl.dc_gain(num, den) == pytest.approx(1.3509, abs=2e-4)
    for form, r in (("pole_shift", 0.75), ("same_damper", 0.8)):
        n2, d2 = gen._nominal_tf([("load_mass", form, {"pole_scale": r})])
        assert pl.dc_gain(n2, d2) == pytest.approx(pl.dc_gain(num, den), rel=1e-9)
        # the double pole moved down by the factor r
        wp = np.sort(np.abs(np.roots(d2)))[-1]
        assert wp == pytest.approx(pl.P_W * r, rel=0.05)


def test_linear_stage_matches_state_space_in_chunks():
    num, den = pl.paper_tf()
    u = np.random.default_rng(1).normal(3.0, 1.0, 2000)
    lin = pl.Linear(num, den, 1e-3)
    y = np.concatenate([lin.run(u[:700]), lin.run(u[700:])])
    ref = _ss_zoh(num, den, 1e-3, u)
    assert np.max(np.abs(y - ref)) < 1e-6 * np.max(np.abs(ref))


def test_effect_free_log_reproduced_by_nominal_model_to_noise(tmp_path):
    fs = 500.0
    rng = np.random.default_rng(3)
    d = gen.Design("paper_chirp", [2, 4], seg_s=10.0)
    u = gen.build_input(d, fs, rng)
    y = gen.run_open(fs, u, []) + gen.make_noise("white", u.size, fs, rng)
    # The exact nominal model, simulated independently (state-space ZOH), leaves noise only.
    num, den = pl.paper_tf()
    r = y - _ss_zoh(num, den, 1 / fs, u)
    assert np.std(r) == pytest.approx(gen.NOISE_MM, rel=0.1)
    assert abs(np.mean(r)) < 3 * gen.NOISE_MM / np.sqrt(u.size) * 10


def test_steady_state_is_static_gain():
    fs = 1000.0
    u = np.full(8000, 5.0)
    y = gen.run_open(fs, u, [])
    assert y[-1] == pytest.approx(5.0 * pl.dc_gain(*pl.paper_tf()), rel=1e-4)


@pytest.mark.parametrize("name", list(gen.FORMS))
def test_every_effect_form_changes_the_log(name):
    fs = 500.0
    rng = np.random.default_rng(5)
    u = gen.build_input(gen.Design("linear_chirp", [3, 5], seg_s=8.0), fs, rng)
    y0 = gen.run_open(fs, u, [])
    for i in range(len(gen.FORMS[name])):
        eff = gen._fill_levels([gen._eff(name, i)], u, y0)
        y1 = gen.run_open(fs, u, eff)
        assert np.sqrt(np.mean((y1 - y0) ** 2)) > 2 * gen.NOISE_MM, (name, i)


def test_conventions_and_timing_offset_differ_by_a_fraction_of_a_sample():
    fs = 200.0
    rng = np.random.default_rng(7)
    u = gen.build_input(gen.Design("multisine", [4], seg_s=10.0), fs, rng)
    z = gen.run_open(fs, u, [])
    for conv, off in (("foh", 0.0), ("centred", 0.0), ("zoh", 0.5)):
        y = gen.run_open(fs, u, [], conv, off)
        d = np.sqrt(np.mean((y - z) ** 2))
        assert 1e-4 < d < 0.3, (conv, off, d)
    # a first-order hold leads a zero-order hold by about half a sample
    yf = gen.run_open(fs, u, [], "foh", 0.0)
    yh = gen.run_open(fs, u, [], "zoh", 0.5)
    assert np.std(yf - yh) < 0.2 * np.std(yf - z)
    # centred hold = zoh sampled half a sample later (both on the fine grid)
    yc = gen.run_open(fs, u, [], "centred", 0.0)
    yz = gen.run_open(fs, u, [], "zoh", 0.5)
    assert np.max(np.abs(yc - yz)) < 1e-6


def test_transport_delay_shifts_the_output():
    fs = 1000.0
    u = np.concatenate([np.zeros(100), np.full(900, 3.0)])
    y0 = gen.run_open(fs, u, [])
    y1 = gen.run_open(fs, u, [("time_delay", "transport", {"delay_s": 0.02})])
    assert np.max(np.abs(y1[20:] - y0[:-20])) < 1e-9


def test_play_operator_is_rate_independent():
    p = pl.Play([0.3], [1.0], 0.0)
    x = np.concatenate([np.linspace(0, 2, 50), np.linspace(2, 0, 50)])
    slow = pl.Play([0.3], [1.0], 0.0).run(np.repeat(x, 7))[::7]
    fast = p.run(x)
    assert np.allclose(slow, fast)
    assert fast[49] == pytest.approx(1.7) and fast[-1] == pytest.approx(0.3)


def test_closed_loop_tracks_reference():
    fs = 1000.0
    rng = np.random.default_rng(2)
    ref = np.concatenate([np.full(3000, 2.0), np.full(3000, 5.0)])
    u, y = gen.run_closed(fs, [], ref, rng)
    assert np.mean(y[2500:3000]) == pytest.approx(2.0, abs=0.05)
    assert np.mean(y[5500:]) == pytest.approx(5.0, abs=0.05)
    assert u.max() <= 9.0 and u.min() >= 0.0


def test_generation_is_deterministic_and_writes_labels_apart(tmp_path):
    a, b = tmp_path / "a", tmp_path / "b"
    for root in (a, b):
        gen.main(["--out", str(root), "--only", "free00,single06"])
    ids = sorted(q.stem for q in (a / "labels").glob("*.json"))
    assert len(ids) == 2
    for cid in ids:
        la = json.loads((a / "labels" / f"{cid}.json").read_text())
        assert la == json.loads((b / "labels" / f"{cid}.json").read_text())
        fa = (a / "cases" / cid / la["train"]["file"]).read_bytes()
        assert fa == (b / "cases" / cid / la["train"]["file"]).read_bytes()
        # the analysis folder holds no truth
        assert not any("truth" in p.name or "label" in p.name for p in (a / "cases" / cid).iterdir())


def test_fine_grid_agrees_with_coarse_grid_and_sections():
    """A held input run on a 40 kHz grid and sampled every 40th step equals the same
    input run at 1 kHz (both exact for piecewise-constant input), and the chunked
    second-order sections of the closed loop agree with both."""
    num, den = pl.paper_tf()
    u = np.random.default_rng(4).normal(4.0, 1.0, 3000)
    ref = _ss_zoh(num, den, 1e-3, u)
    fine = pl.Linear(num, den, 1e-3 / 40).run(np.repeat(u, 40))[::40]
    assert np.max(np.abs(fine - ref)) < 1e-7
    lin = pl.Linear(num, den, 1e-3, mode="sos")
    sos = np.concatenate([lin.run(u[i:i + 5]) for i in range(0, u.size, 5)])
    assert np.max(np.abs(sos - ref)) < 1e-6
    with pytest.raises(ValueError):
        pl.Linear(num, den, 1e-4, mode="sos")
