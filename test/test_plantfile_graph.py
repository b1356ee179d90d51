"""Plant-model files through the node graph: identify -> file -> plant node -> steps, and refusals."""
from __future__ import annotations

import json
import os
import subprocess
from pathlib import Path

import numpy as np
import pytest

from hasel import paper
from hasel.cli import main as hasel_main
from hasel.loop import LoopConfig, run_closed_loop, step_reference
from hasel.metrics import steps_from_sequence
from hasel.plantfile import PlantFileError, read_plant
from hasel.plantspec import from_file, make_actuator
from hasel.signals import protocol_schedule
from hasel.simulator import PlantSimulator
from hasel_sysid.chirp import run_chirp
from hasel_sysid.graph import GraphConfig, NodeGraph

ROOT = Path(__file__).resolve().parents[1]
HASEL = str(ROOT / ".venv" / "bin" / "hasel")
SEQ, HOLD = [2.0, 4.0, 6.0, 4.0, 2.0], 0.4


@pytest.fixture(scope="module")
def model_json(tmp_path_factory):
    """MODEL.json identified from the nominal plant's chirp campaign, recorded through the graph."""
    d = tmp_path_factory.mktemp("plantfile")
    log = d / "chirp.mcap"
    run_chirp(protocol_schedule([4.0], repeats=3, precondition_s=0.5), str(log), seed=3, quiet=True)
    path = d / "model.json"
    assert hasel_main(["identify", str(log), "--json", str(path)]) == 0
    return path


def _graph(plant: str, seed: int = 11):
    with NodeGraph(GraphConfig(feedback="laser", sequence_mm=SEQ, hold_s=HOLD, seed=seed, variant=plant)) as g:
        g.run(HOLD * len(SEQ), wall_timeout_s=120)
        return g.collector.samples(), np.array(g.collector.applied)


def _core(actuator, seed: int = 11):
    return run_closed_loop(PlantSimulator(actuator, seed=seed, strain_curve=getattr(actuator, "strain_curve", None)),
                           step_reference(SEQ, HOLD), HOLD * len(SEQ), LoopConfig(feedback="laser"))


def test_identified_model_file_runs_in_the_graph_as_in_core_sample_for_sample(model_json):
    s, applied = _graph(str(model_json))
    ref = _core(from_file(str(model_json)))
    n = ref.command_kv.size
    np.testing.assert_allclose(applied[:n, 2], ref.command_kv, rtol=0, atol=1e-9)
    np.testing.assert_allclose(s["true_stroke_mm"], ref.true_stroke_mm, rtol=0, atol=1e-9)
    np.testing.assert_allclose(s["voltage_kv"], ref.applied_kv, rtol=0, atol=1e-9)
    # the identified model is the nominal plant: its closed-loop steps agree with the paper's P(s)'s
    nom = _core(None)
    m_file = steps_from_sequence(ref.sample_t_s, ref.true_stroke_mm, SEQ, HOLD)
    m_nom = steps_from_sequence(nom.sample_t_s, nom.true_stroke_mm, SEQ, HOLD)
    for a, b in zip(m_file, m_nom):
        assert a.rise_s == pytest.approx(b.rise_s, rel=0.02)
        assert a.settling_s == pytest.approx(b.settling_s, rel=0.02, abs=2e-3)
        assert a.overshoot_pct == pytest.approx(b.overshoot_pct, rel=0.02, abs=0.2)


def test_file_with_truth_effects_runs_the_same_numbers_as_the_truth_spec(tmp_path):
    spec = "truth:asymmetric_dynamics(tau_relax_s=0.06)+time_delay(delay_s=0.004)"
    num, den = paper.plant_tf()
    path = tmp_path / "truth.json"
    path.write_text(json.dumps({"format": "hasel-plant", "version": 1, "num": list(num), "den": list(den),
                                "units": {"input": "kV", "output": "mm"},
                                "effects": [{"name": "time_delay", "params": {"delay_s": 0.004}},
                                            {"name": "asymmetric_dynamics", "params": {"tau_relax_s": 0.06}}]}))
    s_file, a_file = _graph(str(path))
    s_spec, a_spec = _graph(spec)
    np.testing.assert_array_equal(s_file["true_stroke_mm"], s_spec["true_stroke_mm"])
    np.testing.assert_array_equal(a_file[:, 2], a_spec[:, 2])
    # and different from the nominal plant's
    assert np.max(np.abs(s_file["true_stroke_mm"] - _core(make_actuator("nominal")).true_stroke_mm)) > 0.05


BAD = {
    "unstable": ({"num": [1.0], "den": [1.0, -2.0]}, "not stable"),
    "improper": ({"num": [1.0, 2.0, 3.0], "den": [1.0, 1.0]}, "not proper"),
    "nan": ({"num": [float("nan")], "den": [1.0, 1.0]}, "non-finite"),
    "unknown_effect": ({"num": [1.0], "den": [1.0, 1.0], "effects": [{"name": "backlash", "params": {}}]},
                       "unknown effect"),
    "unknown_param": ({"num": [1.0], "den": [1.0, 1.0],
                       "effects": [{"name": "time_delay", "params": {"delay_ms": 4}}]}, "no parameter delay_ms"),
    "units": ({"num": [1.0], "den": [1.0, 1.0], "units": {"input": "kV", "output": "in"}}, "output unit 'in'"),
}


def _bad_file(tmp_path, key):
    obj, _ = BAD[key]
    obj = {"units": {"input": "kV", "output": "mm"}, **obj}
    path = tmp_path / f"{key}.json"
    path.write_text(json.dumps(obj))  # NaN is written as the JSON extension NaN
    return path


@pytest.mark.parametrize("key", sorted(BAD))
def test_malformed_file_is_refused_by_steps_and_by_the_node_with_the_same_line(tmp_path, key, capsys):
    import rclpy
    from rclpy.parameter import Parameter
    from sim_plant.plant_node import PlantNode

    path = _bad_file(tmp_path, key)
    with pytest.raises(PlantFileError) as err:
        read_plant(path)
    line = str(err.value)
    assert "\n" not in line and BAD[key][1] in line and str(path) in line
    assert hasel_main(["steps", "--plant", str(path), "--hold", "0.1"]) == 2
    err_lines = capsys.readouterr().err.strip().splitlines()
    assert len(err_lines) == 1 and err_lines[0].endswith(f"error: {line}"), err_lines
    ctx = rclpy.Context()
    rclpy.init(context=ctx)
    try:
        with pytest.raises(PlantFileError) as node_err:  # refused while being built: no publisher exists yet
            PlantNode(context=ctx, parameter_overrides=[Parameter("model_file", value=str(path))])
        assert str(node_err.value) == line
    finally:
        rclpy.shutdown(context=ctx)


def test_the_plant_node_process_exits_2_with_one_line_on_a_malformed_file(tmp_path):
    path = _bad_file(tmp_path, "unstable")
    env = {k: v for k, v in os.environ.items() if k != "HASEL_ROS_ENV_READY"}
    node = subprocess.run([HASEL, "env", "--", str(ROOT / "install" / "sim_plant/lib/sim_plant/plant"),
                           "--ros-args", "-p", f"model_file:={path}"], capture_output=True, text=True, timeout=60,
                          env=env)
    assert node.returncode == 2, node.stderr
    assert node.stderr.strip().splitlines() == [f"error: {read_plant_error(path)}"]


def read_plant_error(path) -> str:
    """The reader's one line for ``path``."""
    try:
        read_plant(path)
    except PlantFileError as err:
        return str(err)
    raise AssertionError(f"{path} was accepted")
