"""``hasel tune`` (the core: offline loop, no ROS): the search, the score, the parameter file, the CLI."""
from __future__ import annotations

import json
import math

import numpy as np
import pytest

from hasel import paper
from hasel.cli import main
from hasel.errors import BadInputError
from hasel.loop import LoopConfig, run_closed_loop, step_reference
from hasel.pid import DualModeConfig, PidGains
from hasel.plantspec import make_actuator
from hasel.simulator import PlantSimulator
from hasel.tune import (GAIN_KEYS, PAPER_GAINS, _peak_demand, default_targets, evaluate, parse_targets, read_gains,
                        tune, write_gains)

SEQ, HOLD = [2.0, 4.0, 2.0], 0.6
#: integral-heavy and weakly proportional in both directions: the steps ring and never settle
BAD = {"kp_plus": 0.3, "ki_plus": 80.0, "kp_minus": 0.3, "ki_minus": 80.0}


def _nominal():
    return make_actuator("nominal")


def test_tune_improves_a_deliberately_bad_gain_set():
    res = tune(_nominal, start=BAD, sequence_mm=SEQ, hold_s=HOLD, max_evals=40)
    bad, good = res.start_eval, res.tuned_eval
    # the bad set rings: neither step settles within its hold, overshoot far beyond the target
    assert all(math.isnan(m.settling_s) for m in bad.steps)
    assert max(m.overshoot_pct for m in bad.steps) > 30.0
    # the tuned set settles every step inside the hold, with a small overshoot
    for m in good.steps:
        assert m.settling_s < 0.8 * HOLD, m
        assert m.overshoot_pct < 6.0, m
    assert good.score < 0.25 * bad.score
    assert good.peak_demand_kv <= paper.V_MAX_KV
    assert res.robust and res.moves and res.evaluations <= 40 + 2
    # the reported evaluation is reproduced by running the tuned gains again
    again = evaluate(_nominal, res.tuned, default_targets(), SEQ, HOLD)
    assert again.score == pytest.approx(good.score, rel=1e-12)


def test_tune_from_the_paper_gains_keeps_every_step_at_least_as_good():
    res = tune(lambda: make_actuator("truth:asymmetric_dynamics"), sequence_mm=SEQ, hold_s=HOLD, max_evals=25)
    assert res.start == PAPER_GAINS
    assert res.tuned_eval.score < res.start_eval.score
    for a, b in zip(res.tuned_eval.steps, res.start_eval.steps):
        assert a.settling_s <= b.settling_s + 0.002 and a.overshoot_pct <= b.overshoot_pct + 0.2


def _loop(kp: float, seq: list[float]):
    cfg = DualModeConfig(plus=PidGains(kp, 25.0, 0.0), minus=PidGains(kp, 25.0, 0.0))
    res = run_closed_loop(PlantSimulator(seed=1), step_reference(seq, 0.5), 0.5 * len(seq),
                          LoopConfig(pid=cfg))
    return res, cfg


def test_peak_demand_is_the_command_below_the_ceiling_and_beyond_it_above():
    res, cfg = _loop(1.15, [2.0, 3.0])
    req = res.requested_kv[np.isfinite(res.requested_kv)]
    assert req.max() < paper.V_MAX_KV
    assert _peak_demand(res, cfg) == pytest.approx(req.max(), abs=1e-9)
    # a stiff controller on a big step asks for more than the amplifier may give
    res, cfg = _loop(8.0, [0.0, 7.0])
    req = res.requested_kv[np.isfinite(res.requested_kv)]
    assert req.max() == pytest.approx(paper.V_MAX_KV)  # the request is clamped ...
    assert _peak_demand(res, cfg) > 40.0  # ... the demand was not


def test_a_design_demanding_more_than_9_kv_is_penalised():
    t = default_targets()
    ok = evaluate(_nominal, PAPER_GAINS, t, [0.0, 4.0], 0.5)
    stiff = evaluate(_nominal, {**PAPER_GAINS, "kp_plus": 8.0}, t, [0.0, 4.0], 0.5)
    assert ok.peak_demand_kv < paper.V_MAX_KV < stiff.peak_demand_kv
    assert stiff.score > ok.score + 10.0 * (stiff.peak_demand_kv - paper.V_MAX_KV) - 1.0


def test_gains_file_round_trip_and_refusals(tmp_path):
    g = {**PAPER_GAINS, "kp_plus": 2.0, "kd_minus": 0.004}
    path = write_gains(tmp_path / "g.yaml", g, "a comment\nsecond line")
    assert read_gains(path) == g
    text = path.read_text()
    assert text.startswith("# a comment\n# second line\npid_controller:\n  ros__parameters:\n")
    (tmp_path / "star.yaml").write_text("/**:\n  ros__parameters:\n    kp_minus: 3.0\n")
    assert read_gains(tmp_path / "star.yaml") == {"kp_minus": 3.0}
    bad = {"unknown": ("pid_controller:\n  ros__parameters:\n    kp: 1.0\n", "unknown parameter 'kp'"),
           "node": ("controller:\n  ros__parameters:\n    kp_plus: 1.0\n", "node 'controller'"),
           "neg": ("pid_controller:\n  ros__parameters:\n    ki_plus: -1.0\n", "outside the node's range"),
           "int": ("pid_controller:\n  ros__parameters:\n    ki_plus: 3\n", "written as a float (3.0)"),
           "text": ("pid_controller:\n  ros__parameters:\n    ki_plus: fast\n", "must be a finite number"),
           "nan": ("pid_controller:\n  ros__parameters:\n    ki_plus: .nan\n", "must be a finite number"),
           "yaml": ("pid_controller: [\n", "not valid YAML"),
           "flat": ("kp_plus: 1.0\n", "ros__parameters"),
           "empty": ("pid_controller:\n  ros__parameters: {}\n", "no gain"),
           "missing": (None, "no such file")}
    for name, (content, why) in bad.items():
        p = tmp_path / f"{name}.yaml"
        if content is not None:
            p.write_text(content)
        with pytest.raises(BadInputError) as err:
            read_gains(p)
        assert why in str(err.value) and "\n" not in str(err.value) and str(p) in str(err.value), (name, err.value)


def test_parse_targets():
    t = parse_targets("rise=0.05,relaxation.settling=0.3")
    assert (t.activation.rise_s, t.relaxation.rise_s) == (0.05, 0.05)
    assert t.relaxation.settling_s == 0.3 and t.activation.settling_s == 0.185
    assert t.activation.overshoot_pct == 6.0
    for bad in ("rise", "speed=1", "rise=-1", "rise=nan", "up.rise=1"):
        with pytest.raises(BadInputError):
            parse_targets(bad)


def test_cli_writes_a_gains_file_and_json(tmp_path, capsys):
    out, js = tmp_path / "gains.yaml", tmp_path / "tune.json"
    assert main(["tune", "--plant", "nominal", "--sequence", "2,4,2", "--hold", "0.6", "--max-evals", "6",
                 "--out", str(out), "--json", str(js)]) == 0
    text = capsys.readouterr().out
    assert "peak demand" in text and "settling (s)" in text and f"wrote {out}" in text
    doc = json.loads(js.read_text())
    assert read_gains(out) == doc["tuned"]["gains"] and set(doc["tuned"]["gains"]) == set(GAIN_KEYS)
    assert doc["tuned"]["score"] <= doc["start"]["score"]
    assert doc["tuned"]["peak_demand_kv"] <= paper.V_MAX_KV
    # an existing output is not replaced without --overwrite
    assert main(["tune", "--plant", "nominal", "--max-evals", "1", "--out", str(out)]) == 2


@pytest.mark.parametrize("argv, why", [
    (["--targets", "rise=0"], "--targets"),
    (["--plant", "nosuch"], "unknown plant"),
    (["--sequence", "2"], "--sequence"),
    (["--start", "missing.yaml"], "missing.yaml"),
])
def test_cli_bad_input_is_one_line_and_exit_2(tmp_path, capsys, argv, why):
    args = ["tune", "--plant", "nominal", "--out", str(tmp_path / "g.yaml"), *argv]
    assert main(args) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and why in err[0], err
    assert not (tmp_path / "g.yaml").exists()
