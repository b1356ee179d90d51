"""Dual-mode PID controller node at 200 Hz (paper section IV.B).

Each feedback sample (one per 200 Hz tick, stamped with its measurement time) runs
one update of :class:`hasel.pid.DualModePid`: e = r - z_hat, C+ for e >= 0, C- for
e < 0, trapezoidal integral, backward-rectangular derivative, Ts = 0.005 s. The
request goes to the amplifier node on ``/amp/command`` with the feedback's stamp,
the state on ``/controller/state``.

Feedback: ``feedback`` = "laser" (``/laser/stroke``) or "strain"
(``/strain/stroke_filtered``, i.e. through the driver and the 40 Hz filter).
References arrive on ``/reference`` stamped with the time they take effect, so a
sequence can be published ahead of time and still be applied at exactly the right
tick (deterministic in simulated time).

Faults (see FAULTS.md), all decided by :class:`hasel.controller.ControllerCore`: a
sample that fails the plausibility gate is counted and skipped, the last command held
for that tick; no valid sample for ``stale_periods`` periods, or a stuck sensor,
holds the integrator, sends no command (the amplifier's watchdog then drives 0 kV
within three periods) and reports a diagnostic ERROR, said again each second while it
lasts; when valid, moving samples return, control resumes from the held integrator
without a derivative kick. This node only translates: message -> one core call -> publish.
"""
from __future__ import annotations

import dataclasses
import math
from collections.abc import Sequence

from diagnostic_msgs.msg import DiagnosticArray
from rclpy.node import Node

from hasel import paper
from hasel.controller import ControllerCore, ControlStep
from hasel.faults import OK, Notice, PlausibilityGate, StuckDetector
from hasel.pid import ANTI_WINDUP, DualModeConfig, DualModePid, PidGains
from hasel.timeconv import ns_to_s, s_to_ns
from hasel_ros.rosutil import (Deadline, declare, diagnostic, run_node, stamp_ns, to_stamp, topic_qos,
                               validate_with)
from hasel_msgs.msg import ControllerState, Reference, Stroke, VoltageCommand

__all__ = ["PidControllerNode", "main", "FEEDBACK_TOPICS"]

FEEDBACK_TOPICS = {"laser": "laser/stroke", "strain": "strain/stroke_filtered"}
#: While the feedback stays stale its ERROR diagnostic is said again this often (s), as
#: diagnostic_updater does: a monitor that joins, or is matched by discovery, after the
#: transition still sees the fault.
RESTATE_S = 1.0
_GAIN_PARAMS = ("kp_plus", "ki_plus", "kd_plus", "kp_minus", "ki_minus", "kd_minus")


class PidControllerNode(Node):
    """The controller. Parameters: feedback, gains (kV/mm, kV/(mm s), kV s/mm), limits, anti_windup."""

    def __init__(self, **kwargs) -> None:
        super().__init__("pid_controller", **kwargs)
        self.feedback = declare(self, "feedback", "laser", "feedback source: laser | strain", read_only=True)
        if self.feedback not in FEEDBACK_TOPICS:
            from hasel.errors import BadInputError

            raise BadInputError(f"feedback must be one of {sorted(FEEDBACK_TOPICS)}, got {self.feedback!r}")
        g = {}
        for sign, gains in (("plus", paper.C_PLUS), ("minus", paper.C_MINUS)):
            for name, default, unit in zip(("kp", "ki", "kd"), gains, ("kV/mm", "kV/(mm s)", "kV s/mm")):
                g[f"{name}_{sign}"] = declare(self, f"{name}_{sign}", float(default),
                                              f"C{'+' if sign == 'plus' else '-'} {name}, {unit}", lo=0.0, hi=1000.0)
        period = declare(self, "period_s", paper.LOOP_PERIOD_S, "loop period Ts, s", lo=1e-4, hi=1.0, read_only=True)
        v_min = declare(self, "v_min_kv", 0.0, "lowest command, kV", lo=0.0, hi=9.0)
        v_max = declare(self, "v_max_kv", paper.V_MAX_KV, "highest command, kV (never above 9)", lo=0.0, hi=9.0)
        aw = declare(self, "anti_windup", "conditional_integration", f"one of {', '.join(ANTI_WINDUP)}")
        self.stale_periods = declare(self, "stale_periods", 3.0, "feedback age that counts as stale, periods",
                                     lo=1.0, hi=100.0)
        max_step = declare(self, "gate_max_step_mm", 1.5, "largest plausible change per period, mm", lo=0.01, hi=100.0)
        self.gate = PlausibilityGate(max_step_mm=max_step)
        self.stuck = StuckDetector()
        self.pid = DualModePid(self._config(g, period, v_min, v_max, aw))
        self.add_on_set_parameters_callback(validate_with(self._on_params))

        self.core = ControllerCore(self.pid, self.gate, self.stuck, self.stale_periods)
        self.cmd_pub = self.create_publisher(VoltageCommand, "amp/command", topic_qos("/amp/command"))
        self._cmd = VoltageCommand(applied_kv=math.nan, clamped=False)
        self.state_pub = self.create_publisher(ControllerState, "controller/state", topic_qos("/controller/state"))
        self._state = ControllerState(input_stale=False)
        self.diag_pub = self.create_publisher(DiagnosticArray, "/diagnostics", topic_qos("/diagnostics"))
        fb_topic = declare(self, "feedback_topic", "", "override of the feedback topic ('' = from feedback)",
                           read_only=True) or FEEDBACK_TOPICS[self.feedback]
        self.create_subscription(Stroke, fb_topic, self.on_feedback, topic_qos("/" + FEEDBACK_TOPICS[self.feedback]))
        self.create_subscription(Reference, "reference", self.on_reference, topic_qos("/reference"))
        # staleness check on the ROS (maybe simulated) clock; runs only when feedback is late
        self.deadline = Deadline(self, self.stale_periods * period, period, self.on_watch)
        self._fault: Notice | None = None  # the stale notice in force, restated every RESTATE_S
        self._fault_said_ns = 0

    def _config(self, g: dict, period: float, v_min: float, v_max: float, aw: str) -> DualModeConfig:
        return DualModeConfig(plus=PidGains(g["kp_plus"], g["ki_plus"], g["kd_plus"]),
                              minus=PidGains(g["kp_minus"], g["ki_minus"], g["kd_minus"]),
                              period_s=period, v_min_kv=v_min, v_max_kv=v_max, anti_windup=aw)

    def _on_params(self, new: dict) -> None:
        """Validate and apply gain/limit changes at run time (raises with the reason)."""
        cfg = self.pid.config
        g = {"kp_plus": cfg.plus.kp, "ki_plus": cfg.plus.ki, "kd_plus": cfg.plus.kd,
             "kp_minus": cfg.minus.kp, "ki_minus": cfg.minus.ki, "kd_minus": cfg.minus.kd}
        g.update({k: v for k, v in new.items() if k in _GAIN_PARAMS})
        candidate = self._config(g, cfg.period_s, new.get("v_min_kv", cfg.v_min_kv),
                                 new.get("v_max_kv", cfg.v_max_kv), new.get("anti_windup", cfg.anti_windup))
        self.pid.config = candidate

    @property
    def references(self):
        """The reference schedule (its length is the number of references received)."""
        return self.core.references

    @property
    def stale(self) -> bool:
        """True while the feedback is stale or the sensor stuck (no commands sent)."""
        return self.core.stale

    def reference_at(self, t_s: float) -> float:
        """The reference (mm) in effect at ``t_s`` seconds; NaN before the first one."""
        return self.core.references(t_s)

    def on_reference(self, msg: Reference) -> None:
        """Schedule a reference at its stamp (a later message for the same time replaces it)."""
        self.core.references.set(stamp_ns(msg.header.stamp), msg.stroke_mm)

    def on_feedback(self, msg: Stroke) -> None:
        """One control update for one feedback sample."""
        step = self.core.on_sample(stamp_ns(msg.header.stamp), msg.stroke_mm)
        if step.fresh:
            self.deadline.feed()
        for notice in step.notices:
            self._report(notice)
        if step.command_kv is None:
            if self._fault is not None:  # a stuck sensor: samples come, the fault stays
                self._restate(stamp_ns(msg.header.stamp))
            return
        cmd = self._cmd  # one message object, refilled: publish() copies it at once
        cmd.requested_kv = step.command_kv
        cmd.header.stamp = msg.header.stamp
        self.cmd_pub.publish(cmd)
        # the state only when someone records it: a publish costs about 9 us even to nobody
        if step.pid is not None and self.state_pub.get_subscription_count():
            self._publish_state(step, msg)

    def _publish_state(self, step: ControlStep, msg: Stroke) -> None:
        out = step.pid
        st = self._state  # one message object, refilled: publish() copies it at once
        st.reference_mm, st.measured_mm, st.error_mm, st.mode = step.reference_mm, msg.stroke_mm, out.error_mm, out.mode
        st.p_term_kv, st.i_term_kv, st.d_term_kv, st.output_kv = out.p_kv, out.i_kv, out.d_kv, out.output_kv
        st.saturated, st.rejected_samples = out.saturated, self.core.rejected
        st.header.stamp = msg.header.stamp
        self.state_pub.publish(st)

    def on_watch(self) -> None:
        """Declare the feedback stale when it is older than ``stale_periods`` periods."""
        now_ns = self.get_clock().now().nanoseconds
        notice = self.core.poll(now_ns)
        if notice is not None:
            self._report(notice)
        elif self._fault is not None:
            self._restate(now_ns)

    def _restate(self, now_ns: int) -> None:
        """Say the stale diagnostic again (no ControllerState: those mark transitions) if
        ``RESTATE_S`` has passed since it was last said; ``now_ns`` on the node's clock."""
        if now_ns - self._fault_said_ns >= s_to_ns(RESTATE_S):
            self._say(dataclasses.replace(self._fault, t_s=ns_to_s(now_ns)))

    def _say(self, notice: Notice) -> None:
        """Publish one diagnostic for ``notice`` (its time ``t_s`` in s on the node's clock)."""
        self.diag_pub.publish(diagnostic(self, bytes([notice.level]), notice.message, notice.t_s,
                                         **notice.values, feedback=self.feedback))
        self._fault_said_ns = s_to_ns(notice.t_s)

    def _report(self, notice: Notice) -> None:
        """A stale/ok transition: diagnostic and a ControllerState saying so."""
        self._fault = None if notice.level == OK else notice
        self._say(notice)
        core = self.core
        st = ControllerState(reference_mm=self.reference_at(notice.t_s), measured_mm=math.nan, error_mm=math.nan,
                             mode=core.pid.mode, i_term_kv=core.pid.i_kv, output_kv=0.0, input_stale=notice.level != OK,
                             rejected_samples=core.rejected)
        st.header.stamp = to_stamp(notice.t_s)
        self.state_pub.publish(st)


def main(args: Sequence[str] | None = None) -> int:
    """Entry point of ``ros2 run hasel_control pid_controller``."""
    return run_node(PidControllerNode, args)
