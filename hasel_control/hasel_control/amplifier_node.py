"""High-voltage amplifier command node: the last software stage before the actuator.

It turns requests into the command the 5 kV/V amplifier receives, under the rules of
:mod:`hasel.amplifier`: a hard 9 kV ceiling no parameter can raise (parameters above
it are rejected with the reason), non-finite requests give 0 kV, requests are clamped
to [v_min_kv, v_max_kv], no fresh request for more than ``watchdog_periods`` loop
periods gives 0 kV, requests measured before that 0 kV was sent but handled after it
(queued while the node was starved of CPU, their sender perhaps dead) keep 0 kV, and
shutdown commands 0 kV. It publishes every applied command on ``/amp/applied`` (or
``/amp/applied_batch`` for open-loop 10 kHz waveforms) and a ``diagnostic_msgs`` status
whenever the clamp or the watchdog acts.

The paper's -1 kV charge reversal is a separate, deliberate request on
``/amp/precondition`` (bounded to [-2, 0] kV); the controller's path cannot produce a
negative voltage because v_min_kv cannot be negative.

Every decision is :class:`hasel.amplifier.AmplifierCore`'s; this node only translates
messages into core calls and the results into messages.
"""
from __future__ import annotations

import time
from collections.abc import Sequence

from diagnostic_msgs.msg import DiagnosticArray
from rclpy.node import Node

from hasel import paper
from hasel.amplifier import HARD_CEILING_KV, AmplifierCore, Applied, HvLimits, TripMark, Watchdog
from hasel.faults import Notice
from hasel_ros.rosutil import (Deadline, declare, diagnostic, float64_array, from_stamp, now_s, run_node, to_stamp,
                               topic_qos, validate_with)
from hasel_msgs.msg import SampleBatch, VoltageCommand

__all__ = ["HvAmplifierNode", "main"]


class HvAmplifierNode(Node):
    """The amplifier command node. Parameters: v_min_kv, v_max_kv (<= 9), watchdog_periods, period_s."""

    def __init__(self, **kwargs) -> None:
        super().__init__("hv_amplifier", **kwargs)
        v_min = declare(self, "v_min_kv", 0.0, "lowest command, kV (>= 0)", lo=0.0, hi=HARD_CEILING_KV)
        v_max = declare(self, "v_max_kv", HARD_CEILING_KV, "highest command, kV (hard ceiling 9 kV)",
                        lo=0.0, hi=HARD_CEILING_KV)
        self.period_s = declare(self, "period_s", paper.LOOP_PERIOD_S, "loop period, s", lo=1e-4, hi=1.0,
                                read_only=True)
        periods = declare(self, "watchdog_periods", 3.0, "periods without a command before 0 kV",
                          lo=1.0, hi=10.0)
        self.core = AmplifierCore(HvLimits(v_min, v_max), Watchdog(self.period_s, periods))
        self.trip_mark = TripMark()  # requests queued behind a trip are stale (see TripMark)
        self.add_on_set_parameters_callback(validate_with(self._on_params))
        self.applied_pub = self.create_publisher(VoltageCommand, "amp/applied", topic_qos("/amp/applied"))
        self._applied = VoltageCommand()
        self.batch_pub = self.create_publisher(SampleBatch, "amp/applied_batch", topic_qos("/amp/applied_batch"))
        self.diag_pub = self.create_publisher(DiagnosticArray, "/diagnostics", topic_qos("/diagnostics"))
        self.create_subscription(VoltageCommand, "amp/command", self.on_command, topic_qos("/amp/command"))
        self.create_subscription(SampleBatch, "amp/command_batch", self.on_batch, topic_qos("/amp/command_batch"))
        self.create_subscription(VoltageCommand, "amp/precondition", self.on_precondition,
                                 topic_qos("/amp/precondition"))
        # runs only when commands are late (not every period): see Deadline
        self.deadline = Deadline(self, self.watchdog.timeout_s, self.period_s, self.on_watchdog)

    def _on_params(self, new: dict) -> None:
        """Reject unsafe limits with the reason (HvLimits raises); apply safe ones."""
        limits = HvLimits(new.get("v_min_kv", self.limits.v_min_kv), new.get("v_max_kv", self.limits.v_max_kv))
        periods = new.get("watchdog_periods", self.watchdog.periods)
        self.limits = limits
        self.watchdog.periods = float(periods)
        self.deadline.timeout_s = self.watchdog.timeout_s

    @property
    def limits(self) -> HvLimits:
        """The voltage limits in force."""
        return self.core.limits

    @limits.setter
    def limits(self, limits: HvLimits) -> None:
        self.core.limits = limits

    @property
    def watchdog(self) -> Watchdog:
        """The command watchdog."""
        return self.core.watchdog

    @property
    def output_kv(self) -> float:
        """The last applied command, kV."""
        return self.core.output_kv

    @property
    def tripped(self) -> bool:
        """True while the watchdog holds 0 kV."""
        return self.core.tripped

    def _now(self) -> float:
        return now_s(self)

    def _publish(self, stamp, result: tuple[Applied, Notice | None]) -> None:
        out, notice = result
        msg = self._applied  # one message object, refilled: publish() copies it at once
        msg.requested_kv, msg.applied_kv, msg.clamped, msg.reason = (out.requested_kv, out.applied_kv, out.clamped,
                                                                     out.reason)
        msg.header.stamp = stamp
        self.applied_pub.publish(msg)
        self._report(notice, stamp)

    def _report(self, notice: Notice | None, stamp) -> None:
        """A diagnostic stamped like the message it is about."""
        if notice is not None:
            self.diag_pub.publish(diagnostic(self, bytes([notice.level]), notice.message, from_stamp(stamp),
                                             **notice.values))

    def _fed(self, now: float | None = None, stamp=None) -> None:
        """A request was taken: the deadline pushed back; a request's own time (``now``, s) and ``stamp``
        become the reference of the next trip's mark."""
        self.deadline.feed()
        if now is not None:
            self.trip_mark.fed(now, from_stamp(stamp))
        else:
            self.trip_mark.clear()

    def on_command(self, msg: VoltageCommand) -> None:
        """A 200 Hz request from the controller: limit it and pass it on with its stamp.

        After a watchdog trip this node sent, a request measured before the trip (see :class:`TripMark`)
        is dropped: 0 kV, the watchdog not fed. It queued while the node was starved."""
        now = self._now()
        if self.core.tripped and self.trip_mark.queued(from_stamp(msg.header.stamp), time.monotonic_ns()):
            self._publish(msg.header.stamp, self.core.queued_request(now, msg.requested_kv))
            return
        results = self.core.command(now, msg.requested_kv)
        self._fed(now, msg.header.stamp)
        if len(results) > 1:  # the watchdog's 0 kV fell due at this instant: it goes first
            self._publish(to_stamp(now), results[0])
        self._publish(msg.header.stamp, results[-1])

    def on_batch(self, msg: SampleBatch) -> None:
        """An open-loop 10 kHz request: every sample limited (NaN/inf -> 0 kV)."""
        self._fed()
        applied, notice = self.core.batch(self._now(), msg.voltage_kv)
        self.batch_pub.publish(SampleBatch(header=msg.header, sample_period_s=msg.sample_period_s,
                                           voltage_kv=float64_array(applied)))
        self._report(notice, msg.header.stamp)

    def on_precondition(self, msg: VoltageCommand) -> None:
        """The deliberate charge reversal (bounded to [-2, 0] kV)."""
        self._fed()
        self._publish(msg.header.stamp, self.core.precondition(self._now(), msg.requested_kv))

    def on_watchdog(self) -> None:
        """Once commands have stopped for too long: command 0 kV, then again every period."""
        now = self._now()
        result = self.core.poll(now)
        if result is not None:
            self.trip_mark.trip(now, time.monotonic_ns())
            self._publish(to_stamp(now), result)

    def on_shutdown(self) -> None:
        """Leave the actuator at 0 kV."""
        try:
            now = self._now()
            self._publish(to_stamp(now), self.core.shutdown(now))
        except Exception:  # noqa: BLE001 - the context may already be gone at exit
            pass


def main(args: Sequence[str] | None = None) -> int:
    """Entry point of ``ros2 run hasel_control hv_amplifier``."""
    return run_node(HvAmplifierNode, args)
