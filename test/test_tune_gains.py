"""Tuned gains in the graph: the parameter file of ``hasel tune`` loads into the real controller
node (``--params-file``), runs there as in the offline loop, and steps/compare use it (``--gains``)."""
from __future__ import annotations

import time

import numpy as np
import pytest
from rclpy.exceptions import InvalidParameterTypeException
from rclpy.parameter import Parameter

from hasel.cli import main as hasel_main
from hasel.errors import BadInputError
from hasel.loop import LoopConfig, run_closed_loop, step_reference
from hasel.pid import DualModeConfig, PidGains
from hasel.simulator import PlantSimulator
from hasel.tune import GAIN_KEYS, PAPER_GAINS, read_gains, write_gains
from hasel_control.controller_node import PidControllerNode
from hasel_sysid.graph import GraphConfig, NodeGraph

SEQ, HOLD = [2.0, 4.0, 6.0, 4.0, 2.0], 0.3
#: not the paper's in any gain, and different enough to change every step
GAINS = {"kp_plus": 1.6, "ki_plus": 20.0, "kd_plus": 0.001, "kp_minus": 1.5, "ki_minus": 15.0, "kd_minus": 0.0005}
PLUS, MINUS = PidGains(1.6, 20.0, 0.001), PidGains(1.5, 15.0, 0.0005)


@pytest.fixture()
def gains_file(tmp_path):
    return write_gains(tmp_path / "gains.yaml", GAINS, "test gains")


def _node_gains(node: PidControllerNode) -> dict[str, float]:
    return {k: node.get_parameter(k).value for k in GAIN_KEYS}


def test_params_file_loads_into_the_controller_node_and_runs_as_the_offline_loop(gains_file):
    made = {}

    def controller(ctx):
        made["ctl"] = PidControllerNode(context=ctx, cli_args=["--ros-args", "--params-file", str(gains_file)],
                                        parameter_overrides=[Parameter("use_sim_time", value=True)])
        return made["ctl"]

    cfg = GraphConfig(feedback="laser", sequence_mm=SEQ, hold_s=HOLD, seed=5, with_controller=False)
    with NodeGraph(cfg, extra_nodes=[controller]) as g:
        ctl = made["ctl"]
        assert _node_gains(ctl) == GAINS
        c = ctl.pid.config
        assert (c.plus, c.minus) == (PLUS, MINUS)
        end = time.monotonic() + 20
        while not (ctl.cmd_pub.get_subscription_count() and len(ctl.references) == len(SEQ)):
            assert time.monotonic() < end, "the controller did not connect"
            g.executor.spin_once(timeout_sec=0.02)
        g.run(HOLD * len(SEQ), wall_timeout_s=120)
        s = g.collector.samples()
        applied = np.array(g.collector.applied)
    pid = DualModeConfig(plus=PLUS, minus=MINUS)
    ref = run_closed_loop(PlantSimulator(seed=5), step_reference(SEQ, HOLD), HOLD * len(SEQ),
                          LoopConfig(feedback="laser", pid=pid))
    n = ref.command_kv.size
    np.testing.assert_allclose(applied[:n, 2], ref.command_kv, rtol=0, atol=1e-12)
    np.testing.assert_allclose(s["true_stroke_mm"], ref.true_stroke_mm, rtol=0, atol=1e-12)
    # and it is not the paper's loop
    paper_loop = run_closed_loop(PlantSimulator(seed=5), step_reference(SEQ, HOLD), HOLD * len(SEQ))
    assert np.max(np.abs(paper_loop.true_stroke_mm - ref.true_stroke_mm)) > 0.1


def test_node_wildcard_params_file_and_an_integer_gain(tmp_path):
    """``/**:`` works too; an integer gain is refused by the node and by read_gains alike."""
    import rclpy

    path = tmp_path / "star.yaml"
    path.write_text("/**:\n  ros__parameters:\n    kp_minus: 3.5\n")
    ctx = rclpy.Context()
    rclpy.init(context=ctx)
    try:
        node = PidControllerNode(context=ctx, cli_args=["--ros-args", "--params-file", str(path)])
        assert _node_gains(node) == {**PAPER_GAINS, "kp_minus": 3.5} == {**PAPER_GAINS, **read_gains(path)}
        node.destroy_node()
        path.write_text("/**:\n  ros__parameters:\n    kp_minus: 3\n")
        with pytest.raises(InvalidParameterTypeException):
            PidControllerNode(context=ctx, cli_args=["--ros-args", "--params-file", str(path)])
        with pytest.raises(BadInputError, match="written as a float"):
            read_gains(path)
    finally:
        rclpy.shutdown(context=ctx)


def test_steps_gains_option_runs_the_gains(gains_file, tmp_path):
    out = tmp_path / "steps.json"
    assert hasel_main(["steps", "--gains", str(gains_file), "--hold", str(HOLD), "--json", str(out)]) == 0
    import json

    doc = json.loads(out.read_text())
    assert doc["gains"] == GAINS
    ref = run_closed_loop(PlantSimulator(seed=0), step_reference(SEQ, HOLD), HOLD * len(SEQ),
                          LoopConfig(pid=DualModeConfig(plus=PLUS, minus=MINUS)))
    from hasel.metrics import steps_from_sequence

    want = steps_from_sequence(ref.sample_t_s, ref.true_stroke_mm, SEQ, HOLD)
    assert len(doc["steps"]) == len(want) == 4
    for got, m in zip(doc["steps"], want):  # the graph runs the file's gains as the loop runs them
        for key in ("rise_s", "settling_s", "overshoot_pct"):
            assert got[key] == pytest.approx(getattr(m, key), abs=1e-9), (key, got)
    assert want[0].overshoot_pct < 5.0 and all(m.settling_s < HOLD for m in want)


def test_compare_replays_with_the_gains_the_log_was_measured_with(gains_file, tmp_path):
    log = tmp_path / "run.mcap"
    assert hasel_main(["steps", "--gains", str(gains_file), "--hold", str(HOLD), "--seed", "4",
                       "--record", str(log)]) == 0
    with_gains, without = tmp_path / "with.json", tmp_path / "without.json"
    assert hasel_main(["compare", str(log), "--plant", "nominal", "--gains", str(gains_file),
                       "--json", str(with_gains)]) == 0
    assert hasel_main(["compare", str(log), "--plant", "nominal", "--json", str(without)]) == 0
    import json

    a, b = json.loads(with_gains.read_text()), json.loads(without.read_text())
    assert a["gains"] == GAINS and b["gains"] == PAPER_GAINS
    # the same plant and gains as the log: the laser's noise floor (about 0.002); the paper's gains: far off
    assert a["plants"][0]["stroke_nrmse"] < 0.01
    assert b["plants"][0]["stroke_nrmse"] > 5 * a["plants"][0]["stroke_nrmse"]


BAD = {"unknown key": ("pid_controller:\n  ros__parameters:\n    kp_plus: 1.0\n    gain: 2.0\n",
                       "unknown parameter 'gain'"),
       "malformed": ("pid_controller:\n  ros__parameters: [kp_plus\n", "not valid YAML"),
       "not a number": ("pid_controller:\n  ros__parameters:\n    kp_plus: high\n", "must be a finite number")}


@pytest.mark.parametrize("command", ["steps", "compare"])
@pytest.mark.parametrize("case", sorted(BAD))
def test_bad_gains_file_is_one_line_and_exit_2(tmp_path, capsys, command, case):
    text, why = BAD[case]
    path = tmp_path / "bad.yaml"
    path.write_text(text)
    log = tmp_path / "log.csv"
    log.write_text("t_s,reference_mm,stroke_mm,voltage_kv\n0,2,2,1\n1,4,4,3\n2,4,4,3\n")
    argv = (["steps", "--hold", "0.1"] if command == "steps" else ["compare", str(log), "--plant", "nominal"])
    assert hasel_main(argv + ["--gains", str(path)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith(f"hasel {command}: error: gains file {path}: ") and why in err[0], err
