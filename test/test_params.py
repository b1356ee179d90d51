"""Parameters: loaded from a YAML file, validated with ranges and reasons."""
from __future__ import annotations

from pathlib import Path

import pytest
import rclpy
from rclpy.context import Context
from rclpy.exceptions import InvalidParameterValueException
from rclpy.parameter import Parameter

from hasel_control.amplifier_node import HvAmplifierNode
from hasel_control.controller_node import PidControllerNode

CONFIG = Path(__file__).resolve().parents[1] / "hasel_control" / "config" / "loop.yaml"


@pytest.fixture
def ctx():
    c = Context()
    rclpy.init(context=c)
    yield c
    rclpy.try_shutdown(context=c)


def test_shipped_yaml_loads_the_papers_setup(ctx):
    pid = PidControllerNode(context=ctx, cli_args=["--ros-args", "--params-file", str(CONFIG)])
    amp = HvAmplifierNode(context=ctx, cli_args=["--ros-args", "--params-file", str(CONFIG)])
    assert pid.pid.config.plus.kp == 1.15 and pid.pid.config.minus.ki == 26.0
    assert amp.limits.v_max_kv == 9.0
    pid.destroy_node()
    amp.destroy_node()


def test_yaml_can_lower_but_not_raise_the_ceiling(ctx, tmp_path):
    low = tmp_path / "low.yaml"
    low.write_text("hv_amplifier:\n  ros__parameters:\n    v_max_kv: 7.5\n")
    amp = HvAmplifierNode(context=ctx, cli_args=["--ros-args", "--params-file", str(low)])
    assert amp.limits.v_max_kv == 7.5
    amp.destroy_node()
    high = tmp_path / "high.yaml"
    high.write_text("hv_amplifier:\n  ros__parameters:\n    v_max_kv: 12.0\n")
    with pytest.raises(InvalidParameterValueException):
        HvAmplifierNode(context=ctx, cli_args=["--ros-args", "--params-file", str(high)])


def test_controller_rejects_unsafe_runtime_changes_with_reason(ctx):
    pid = PidControllerNode(context=ctx)
    res = pid.set_parameters([Parameter("v_max_kv", value=9.5)])
    assert not res[0].successful
    res = pid.set_parameters([Parameter("anti_windup", value="magic")])
    assert not res[0].successful and "anti_windup" in res[0].reason
    res = pid.set_parameters([Parameter("kp_plus", value=2.0)])
    assert res[0].successful and pid.pid.config.plus.kp == 2.0
    pid.destroy_node()
