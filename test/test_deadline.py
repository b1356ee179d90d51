"""The watchdogs' Deadline timer on the simulated clock: when it fires, and that it stays quiet while fed."""
from __future__ import annotations

import rclpy
from rclpy.context import Context
from rclpy.experimental import EventsExecutor
from rclpy.parameter import Parameter
from rosgraph_msgs.msg import Clock as ClockMsg

from hasel_ros.rosutil import Deadline

PERIOD_NS = 5_000_000  # one 200 Hz tick


def _run(feeds: set[int], ticks: int, timeout_periods: float = 3.0) -> list[float]:
    """Step /clock one tick at a time for ``ticks`` ticks; feed the deadline at the ticks in
    ``feeds`` (after the clock has moved, as a message of that tick would); return the
    simulated times (ms) at which it fired."""
    ctx = Context()
    rclpy.init(context=ctx)
    try:
        src = rclpy.create_node("clock_src", context=ctx)
        pub = src.create_publisher(ClockMsg, "/clock", 10)
        node = rclpy.create_node("deadline_probe", context=ctx,
                                 parameter_overrides=[Parameter("use_sim_time", value=True)])
        fired: list[float] = []
        dl = Deadline(node, timeout_periods * PERIOD_NS * 1e-9, PERIOD_NS * 1e-9,
                      lambda: fired.append(node.get_clock().now().nanoseconds / 1e6))
        ex = EventsExecutor(context=ctx)
        ex.add_node(src)
        ex.add_node(node)
        for _ in range(500):
            if pub.get_subscription_count():
                break
            ex.spin_once(timeout_sec=0.01)
        msg = ClockMsg()
        for k in range(1, ticks + 1):
            msg.clock.sec, msg.clock.nanosec = divmod(k * PERIOD_NS, 1_000_000_000)
            pub.publish(msg)
            for _ in range(20):  # until the clock has arrived (and any timer due at it has run)
                ex.spin_once(timeout_sec=0.005)
                if node.get_clock().now().nanoseconds == k * PERIOD_NS:
                    break
            for _ in range(3):
                ex.spin_once(timeout_sec=0.001)
            if k in feeds:
                dl.feed()
        ex.shutdown()
        src.destroy_node()
        node.destroy_node()
        return fired
    finally:
        rclpy.try_shutdown(context=ctx)


def test_deadline_fires_only_after_the_timeout_then_every_period_until_fed():
    # fed at ticks 1..9 (last at 45 ms): older than 3 periods from 60 ms on, so the first
    # call is at the 65 ms tick (as a poll of age > 15 ms at each tick would find), then
    # every 5 ms; fed again at 100..120 ms: quiet, then 120 + 20 = 140 ms
    fired = _run(set(range(1, 10)) | set(range(20, 25)), 32)
    assert fired[:8] == [65.0, 70.0, 75.0, 80.0, 85.0, 90.0, 95.0, 100.0]
    assert fired[8:] == [140.0, 145.0, 150.0, 155.0, 160.0]


def test_deadline_is_silent_while_fed_every_period_and_disarmed_before_the_first_feed():
    assert _run(set(range(1, 41)), 40) == []  # fed each tick: never a callback
    assert _run(set(), 20) == []  # never fed: never armed
