"""Sensor faults through the running graph: spikes, dropout, stuck sensor (lockstep, simulated time)."""
from __future__ import annotations

import math

import numpy as np
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus
from rclpy.node import Node
from rclpy.parameter import Parameter

from hasel_ros.rosutil import from_stamp, topic_qos
from hasel_msgs.msg import Stroke
from hasel_sysid.graph import GraphConfig, NodeGraph


class FaultInjector(Node):
    """Sits between /laser/stroke and the controller, corrupting samples by a rule of time."""

    def __init__(self, rule, **kw) -> None:
        super().__init__("fault_injector", **kw)
        self.rule = rule
        self.pub = self.create_publisher(Stroke, "/faulty/stroke", topic_qos("/laser/stroke"))
        self.create_subscription(Stroke, "/laser/stroke", self.on_sample, topic_qos("/laser/stroke"))
        self.diags: list[tuple[float, int, str]] = []
        self.create_subscription(DiagnosticArray, "/diagnostics", self.on_diag, topic_qos("/diagnostics"))

    def on_sample(self, msg: Stroke) -> None:
        z = self.rule(from_stamp(msg.header.stamp), msg.stroke_mm)
        if z is None:
            return  # dropped
        out = Stroke(stroke_mm=z, source=msg.source)
        out.header = msg.header
        self.pub.publish(out)

    def on_diag(self, msg: DiagnosticArray) -> None:
        for st in msg.status:
            self.diags.append((from_stamp(msg.header.stamp), int.from_bytes(st.level, "little"), st.message))


def run_with(rule, duration, seq=(4.0,), hold=10.0):
    holder = []

    def make(ctx):
        holder.append(FaultInjector(rule, context=ctx, parameter_overrides=[Parameter("use_sim_time", value=True)]))
        return holder[0]

    cfg = GraphConfig(feedback="laser", sequence_mm=list(seq), hold_s=hold, seed=4,
                      controller_params={"feedback_topic": "/faulty/stroke"},
                      plant_params={"lockstep_timeout_s": 0.005})
    with NodeGraph(cfg, extra_nodes=[make]) as g:
        g.run(duration, wall_timeout_s=120)
        s = g.collector.samples()
        applied = np.array(g.collector.applied)
        states = list(g.collector.states)
        diags = list(holder[0].diags)
    return s, applied, states, diags


def test_single_sample_spikes_are_rejected_counted_and_harmless():
    spike_times = {round(0.5 + 0.1 * k, 3) for k in range(5)}
    s, applied, states, _ = run_with(lambda t, z: z + 8.0 if round(t, 3) in spike_times else z, 1.2)
    assert max(st.rejected_samples for st in states) == 5
    late = s["t_s"] > 1.0
    assert np.max(np.abs(s["true_stroke_mm"][late] - 4.0)) < 0.05  # tracking undisturbed


def test_dropout_zero_kv_within_three_periods_error_and_bumpless_resume():
    s, applied, states, diags = run_with(lambda t, z: None if 0.6 <= t < 0.8 else z, 1.2)
    # last sample before the dropout is at 0.595 s; 0 kV no later than three periods after it
    zero = applied[(applied[:, 2] == 0.0) & (applied[:, 0] > 0.595)]
    assert zero.size and zero[0, 0] <= 0.595 + 3 * 0.005 + 0.005 + 1e-9
    errs = [d for d in diags if d[1] == int.from_bytes(DiagnosticStatus.ERROR, "little") and "stale" in d[2]]
    assert errs and 0.6 <= errs[0][0] <= 0.62
    held = [st.i_term_kv for st in states if 0.6 <= from_stamp(st.header.stamp) < 0.8]
    assert held and max(held) - min(held) < 1e-12  # integrator held during the dropout
    first = next(st for st in states if from_stamp(st.header.stamp) >= 0.8 and math.isfinite(st.error_mm))
    assert abs(first.d_term_kv) < 1e-9  # no derivative kick on resume
    assert np.max(np.abs(s["true_stroke_mm"][s["t_s"] > 1.1] - 4.0)) < 0.1  # control resumed


def test_a_long_dropout_is_restated_each_second_and_cleared_once():
    # a monitor matched after the transition must still see the fault (diagnostic_updater's habit)
    s, applied, states, diags = run_with(lambda t, z: None if 0.6 <= t < 2.9 else z, 3.2)
    error = int.from_bytes(DiagnosticStatus.ERROR, "little")
    errs = [t for t, level, msg in diags if level == error and "stale" in msg]
    assert len(errs) == 3, errs
    assert 0.6 <= errs[0] <= 0.62
    np.testing.assert_allclose(np.diff(errs), 1.0, atol=0.0051)  # said again each second, to a tick
    ok = [t for t, level, msg in diags if level == 0 and "feedback ok" in msg]
    assert len(ok) == 1 and 2.9 <= ok[0] <= 2.92  # the gate takes a few samples to trust a new level
    # the transitions alone carry a ControllerState: one stale, one back
    marks = [st.input_stale for st in states if math.isnan(st.measured_mm)]
    assert marks == [True, False]


def test_stuck_sensor_is_detected_and_ends_in_zero_kv():
    frozen = {}

    def rule(t, z):
        if t >= 0.5:
            return frozen.setdefault("z", z)  # the sensor freezes while the reference moves
        return z

    s, applied, states, diags = run_with(rule, 1.0, seq=(2.0, 5.0), hold=0.5)
    stuck = [d for d in diags if "stuck" in d[2]]
    assert stuck, diags
    assert applied[-1, 2] == 0.0
    assert np.all(applied[:, 2] <= 9.0)
