"""The amplifier node across the node boundary: property-based tests of the HV envelope."""
from __future__ import annotations

import math
import time

import numpy as np
import pytest
import rclpy
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from diagnostic_msgs.msg import DiagnosticArray
from rclpy.context import Context
from rclpy.executors import SingleThreadedExecutor
from rclpy.parameter import Parameter

from hasel_control.amplifier_node import HvAmplifierNode
from hasel_ros.rosutil import to_stamp, topic_qos
from hasel_msgs.msg import SampleBatch, VoltageCommand

pytestmark = pytest.mark.wallclock  # asserts on wall-clock timing: run alone (Makefile)


class Harness:
    """An amplifier node and a test node in their own context, spun on demand."""

    def __init__(self) -> None:
        from rclpy.experimental import EventsExecutor

        self.ctx = Context()
        rclpy.init(context=self.ctx)
        self.amp = HvAmplifierNode(context=self.ctx)
        self.node = rclpy.create_node("amp_probe", context=self.ctx)
        self.pub = self.node.create_publisher(VoltageCommand, "/amp/command", topic_qos("/amp/command"))
        self.bpub = self.node.create_publisher(SampleBatch, "/amp/command_batch", topic_qos("/amp/command_batch"))
        self.ppub = self.node.create_publisher(VoltageCommand, "/amp/precondition", topic_qos("/amp/precondition"))
        self.got: list[VoltageCommand] = []
        self.batches: list[SampleBatch] = []
        self.node.create_subscription(VoltageCommand, "/amp/applied", self.got.append, topic_qos("/amp/applied"))
        self.node.create_subscription(SampleBatch, "/amp/applied_batch", self.batches.append,
                                      topic_qos("/amp/applied_batch"))
        self.ex = EventsExecutor(context=self.ctx)
        self.ex.add_node(self.amp)
        self.ex.add_node(self.node)
        for _ in range(500):
            if self.pub.get_subscription_count() and self.amp.applied_pub.get_subscription_count():
                break
            self.ex.spin_once(timeout_sec=0.01)

    def send(self, kv: float) -> VoltageCommand:
        """Publish one request and return the amplifier's answer to it (matched by stamp:
        the watchdog may publish its own 0 kV messages in between, on wall time)."""
        self.seq = getattr(self, "seq", 0) + 1
        msg = VoltageCommand(requested_kv=kv)
        msg.header.stamp.sec = self.seq
        self.pub.publish(msg)
        for _ in range(500):
            self.ex.spin_once(timeout_sec=0.01)
            for m in reversed(self.got):
                if m.header.stamp.sec == self.seq and m.reason != VoltageCommand.REASON_WATCHDOG:
                    return m
        raise AssertionError("no applied command came back")

    def close(self) -> None:
        self.ex.shutdown()
        self.amp.destroy_node()
        self.node.destroy_node()
        rclpy.try_shutdown(context=self.ctx)


@pytest.fixture(scope="module")
def harness():
    h = Harness()
    yield h
    h.close()


@settings(max_examples=2000, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(kv=st.floats(allow_nan=True, allow_infinity=True, width=64))
def test_no_request_leaves_the_envelope(harness, kv):
    out = harness.send(kv)
    assert 0.0 <= out.applied_kv <= 9.0
    if not math.isfinite(kv):
        assert out.applied_kv == 0.0 and out.reason == VoltageCommand.REASON_NONFINITE
    elif 0.0 <= kv <= 9.0:
        assert out.applied_kv == kv and not out.clamped
    else:
        assert out.clamped


def test_batches_are_limited_sample_by_sample(harness):
    rng = np.random.default_rng(0)
    req = np.concatenate([rng.normal(5, 10, 46), [np.nan, np.inf, -np.inf, 1e300]])
    n = len(harness.batches)
    harness.bpub.publish(SampleBatch(sample_period_s=1e-4, voltage_kv=req.tolist()))
    for _ in range(200):
        harness.ex.spin_once(timeout_sec=0.01)
        if len(harness.batches) > n:
            break
    out = np.asarray(harness.batches[-1].voltage_kv)
    assert out.shape == req.shape and out.min() >= 0.0 and out.max() <= 9.0
    np.testing.assert_array_equal(out[-4:], [0.0, 0.0, 0.0, 9.0])


def test_precondition_is_the_only_way_below_zero(harness):
    msg = VoltageCommand(requested_kv=-1.0)
    msg.header.stamp.sec = 10**6
    harness.ppub.publish(msg)
    for _ in range(500):
        harness.ex.spin_once(timeout_sec=0.01)
        if any(m.header.stamp.sec == 10**6 for m in harness.got):
            break
    out = next(m for m in harness.got if m.header.stamp.sec == 10**6)
    assert out.applied_kv == -1.0 and out.reason == VoltageCommand.REASON_PRECONDITION
    assert harness.send(-1.0).applied_kv == 0.0  # the ordinary path clamps at v_min = 0


def test_unsafe_parameters_are_rejected_with_the_reason(harness):
    res = harness.amp.set_parameters([Parameter("v_max_kv", value=12.0)])
    assert not res[0].successful and "9" in res[0].reason
    res = harness.amp.set_parameters([Parameter("v_min_kv", value=-1.0)])
    assert not res[0].successful
    assert harness.amp.limits.v_max_kv == 9.0 and harness.amp.limits.v_min_kv == 0.0
    ok = harness.amp.set_parameters([Parameter("v_max_kv", value=6.0)])
    assert ok[0].successful
    assert harness.send(8.0).applied_kv == 6.0
    harness.amp.set_parameters([Parameter("v_max_kv", value=9.0)])


def test_shutdown_commands_zero_kv(harness):
    harness.send(6.0)
    harness.amp.on_shutdown()
    for _ in range(200):
        harness.ex.spin_once(timeout_sec=0.01)
        if harness.got[-1].reason == VoltageCommand.REASON_SHUTDOWN:
            break
    assert harness.got[-1].applied_kv == 0.0 and harness.got[-1].reason == VoltageCommand.REASON_SHUTDOWN


def test_requests_queued_while_the_node_was_starved_do_not_outlive_the_watchdog():
    """The node starved of CPU past its watchdog timeout (as on a loaded machine when the controller
    dies): its executor takes the ready timer first, sends 0 kV, then finds the requests that queued
    meanwhile. They were measured before the trip and stay at 0 kV; the first request measured after
    the trip resumes. The executor is ``ros2 run``'s (SingleThreadedExecutor), on wall time."""
    ctx = Context()
    rclpy.init(context=ctx)
    amp = HvAmplifierNode(context=ctx)
    node = rclpy.create_node("starve_probe", context=ctx)
    pub = node.create_publisher(VoltageCommand, "/amp/command", topic_qos("/amp/command"))
    got: list[VoltageCommand] = []
    diags: list[str] = []
    node.create_subscription(VoltageCommand, "/amp/applied", got.append, topic_qos("/amp/applied"))
    node.create_subscription(DiagnosticArray, "/diagnostics", lambda m: diags.extend(x.message for x in m.status),
                             topic_qos("/diagnostics"))
    ex_amp, ex_probe = SingleThreadedExecutor(context=ctx), SingleThreadedExecutor(context=ctx)
    ex_amp.add_node(amp)
    ex_probe.add_node(node)

    def spin(until, what: str) -> None:
        for _ in range(500):
            ex_amp.spin_once(timeout_sec=0.0)
            ex_probe.spin_once(timeout_sec=0.002)
            if until():
                return
        raise AssertionError(f"timed out waiting for {what}: got {[(m.applied_kv, m.reason) for m in got]}")

    try:
        spin(lambda: pub.get_subscription_count() and amp.applied_pub.get_subscription_count(), "discovery")
        def send(kv: float) -> None:  # stamped as the measurement it answers, on wall time like the plant's
            msg = VoltageCommand(requested_kv=kv)
            msg.header.stamp = to_stamp(time.time())
            pub.publish(msg)

        send(4.0)
        spin(lambda: any(m.applied_kv == 4.0 for m in got), "the first request")
        n0 = len(got)
        for kv in (5.0, 6.0):  # sent, then the amplifier gets no CPU for 40 ms (timeout 15 ms)
            send(kv)
        time.sleep(0.04)
        spin(lambda: sum(m.requested_kv in (5.0, 6.0) for m in got[n0:]) == 2, "the queued requests")
        after = [(m.applied_kv, m.reason) for m in got[n0:]]
        assert after[0] == (0.0, VoltageCommand.REASON_WATCHDOG)  # the trip first (timers before subscriptions)
        assert all(kv == 0.0 and r == VoltageCommand.REASON_WATCHDOG for kv, r in after), after
        assert amp.tripped and amp.output_kv == 0.0
        spin(lambda: any("measured before the watchdog tripped" in d for d in diags), "the dropped request's notice")
        send(7.0)  # measured after the trip: control resumes
        spin(lambda: any(m.applied_kv == 7.0 for m in got), "the fresh request")
        assert next(m.reason for m in got if m.applied_kv == 7.0) == VoltageCommand.REASON_NONE
    finally:
        ex_amp.shutdown()
        ex_probe.shutdown()
        amp.destroy_node()
        node.destroy_node()
        rclpy.try_shutdown(context=ctx)
