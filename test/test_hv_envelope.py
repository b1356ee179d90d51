"""The HV envelope across the node boundary: no sequence of references, gains, run-time
parameter changes, sensor values (NaN, inf, spikes, stuck, silence, out-of-order or
duplicated stamps) or clock jumps puts the applied voltage above 9 kV or below v_min; and
the check is not vacuous: the loop does apply voltage, up to the ceiling and no further."""
from __future__ import annotations

import math

import pytest
import rclpy
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from rclpy.context import Context
from rclpy.experimental import EventsExecutor
from rclpy.parameter import Parameter
from rosgraph_msgs.msg import Clock as ClockMsg

from hasel_control.amplifier_node import HvAmplifierNode
from hasel_control.controller_node import PidControllerNode
from hasel_ros.rosutil import to_stamp, topic_qos
from hasel_msgs.msg import Reference, Stroke, VoltageCommand


class Loop:
    """Controller and amplifier in simulated time, driven by a probe that plays sensor and clock."""

    def __init__(self) -> None:
        self.ctx = Context()
        rclpy.init(context=self.ctx)
        sim = [Parameter("use_sim_time", value=True)]
        self.pid = PidControllerNode(context=self.ctx, parameter_overrides=sim)
        self.amp = HvAmplifierNode(context=self.ctx, parameter_overrides=sim)
        self.probe = rclpy.create_node("envelope_probe", context=self.ctx)
        self.fb = self.probe.create_publisher(Stroke, "/laser/stroke", topic_qos("/laser/stroke"))
        self.ref = self.probe.create_publisher(Reference, "/reference", topic_qos("/reference"))
        self.clock = self.probe.create_publisher(ClockMsg, "/clock", 10)
        self.applied: list[float] = []
        self.checked: list[float] = []  # every applied value checked so far (the run must have applied some)
        self.probe.create_subscription(VoltageCommand, "/amp/applied", lambda m: self.applied.append(m.applied_kv),
                                       topic_qos("/amp/applied"))
        self.ex = EventsExecutor(context=self.ctx)
        for n in (self.pid, self.amp, self.probe):
            self.ex.add_node(n)
        for _ in range(500):
            if self.fb.get_subscription_count() and self.amp.applied_pub.get_subscription_count() \
                    and self.ref.get_subscription_count():
                break
            self.ex.spin_once(timeout_sec=0.01)

    def spin(self, n: int = 6) -> None:
        for _ in range(n):
            self.ex.spin_once(timeout_sec=0.0005)

    def close(self) -> None:
        self.ex.shutdown()
        for n in (self.pid, self.amp, self.probe):
            n.destroy_node()
        rclpy.try_shutdown(context=self.ctx)


@pytest.fixture(scope="module")
def loop():
    lp = Loop()
    yield lp
    lp.close()
    if getattr(lp, "t", 0.0) > 1.0:  # the random run took place: its checks must have seen real voltages
        assert len(lp.checked) >= 100 and max(lp.checked) > 1.0, \
            f"the envelope run applied only {len(lp.checked)} values (max {max(lp.checked, default=0.0)} kV)"


def _drive(lp: Loop, t: float, stroke_mm: float, n: int) -> float:
    """``n`` feedback samples of ``stroke_mm`` (+ a tiny ramp: not a stuck sensor), one per 5 ms tick."""
    for k in range(n):
        t += 0.005
        lp.clock.publish(ClockMsg(clock=to_stamp(t)))
        m = Stroke(stroke_mm=stroke_mm + 1e-4 * k, source=Stroke.SOURCE_LASER)
        m.header.stamp = to_stamp(t)
        lp.fb.publish(m)
        lp.spin()
    lp.spin(20)
    return t


def test_the_loop_applies_voltage_up_to_the_ceiling_and_no_further():
    lp = Loop()
    try:
        r = Reference(stroke_mm=6.0)
        r.header.stamp = to_stamp(0.0)
        lp.ref.publish(r)
        t = _drive(lp, 0.0, 0.5, 80)  # far below the reference: the PID saturates high
        assert len(lp.applied) >= 60 and max(lp.applied) == 9.0 and min(lp.applied) >= 0.0
        assert not lp.amp.set_parameters([Parameter("v_max_kv", value=12.0)])[0].successful
        lp.applied.clear()
        t = _drive(lp, t, 0.5, 40)
        assert len(lp.applied) >= 30 and max(lp.applied) == 9.0  # 12 kV was refused: still the 9 kV ceiling
        assert lp.amp.set_parameters([Parameter("v_max_kv", value=7.5)])[0].successful
        lp.applied.clear()
        t = _drive(lp, t, 0.5, 40)
        assert len(lp.applied) >= 30 and max(lp.applied) == 7.5 and lp.applied[-1] == 7.5
        lp.applied.clear()
        _drive(lp, t, math.nan, 10)  # a non-finite reading: 0 kV (from the controller's hold or the watchdog)
        assert lp.applied and lp.applied[-1] == 0.0
    finally:
        lp.close()


values = st.one_of(st.floats(-50, 50), st.sampled_from([math.nan, math.inf, -math.inf, 1e300, -1e300]))
event = st.one_of(
    st.tuples(st.just("sample"), values, st.integers(-3, 3)),             # stamp jitter: out of order, duplicated
    st.tuples(st.just("reference"), st.floats(-100, 100), st.integers(0, 3)),
    st.tuples(st.just("gain"), st.sampled_from(["kp_plus", "ki_plus", "kd_plus", "kp_minus", "ki_minus",
                                                "kd_minus"]), st.floats(0, 1000)),
    st.tuples(st.just("limit"), st.sampled_from(["v_max_kv", "v_min_kv"]), st.floats(-20, 20)),
    st.tuples(st.just("clock"), st.floats(-10, 100), st.just(0)),          # clock jumps, also backwards
    st.tuples(st.just("silence"), st.integers(1, 8), st.just(0)),
)


@settings(max_examples=500, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(events=st.lists(event, min_size=1, max_size=25))
def test_applied_stays_in_envelope(loop, events):
    t = getattr(loop, "t", 0.0)
    loop.applied.clear()
    for kind, a, b in events:
        if kind == "sample":
            t += 0.005
            c = ClockMsg(clock=to_stamp(t))
            loop.clock.publish(c)
            m = Stroke(stroke_mm=a, source=Stroke.SOURCE_LASER)
            m.header.stamp = to_stamp(max(0.0, t + 0.005 * b))
            loop.fb.publish(m)
        elif kind == "reference":
            m = Reference(stroke_mm=a)
            m.header.stamp = to_stamp(max(0.0, t + 0.005 * b))
            loop.ref.publish(m)
        elif kind == "gain":
            loop.pid.set_parameters([Parameter(a, value=float(b))])
        elif kind == "limit":
            loop.spin(20)  # what was limited under the old limits is checked against them
            check(loop)
            loop.pid.set_parameters([Parameter(a, value=float(b))])
            loop.amp.set_parameters([Parameter(a, value=float(b))])
        elif kind == "clock":
            t = max(0.0, t + a)
            loop.clock.publish(ClockMsg(clock=to_stamp(t)))
        else:  # silence: time passes without samples
            for _ in range(a):
                t += 0.005
                loop.clock.publish(ClockMsg(clock=to_stamp(t)))
                loop.spin(2)
        loop.spin()
    loop.spin(20)
    loop.t = t
    check(loop)


def check(loop) -> None:
    """Every applied value so far is 0 kV (a fault) or within [v_min, 9] kV."""
    v_min = loop.amp.limits.v_min_kv
    for kv in loop.applied:
        assert kv == 0.0 or v_min <= kv <= 9.0, (kv, v_min)
    loop.checked += loop.applied
    loop.applied.clear()
