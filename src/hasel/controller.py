"""The controller's decisions for one feedback sample, without ROS: the core of the controller node.

:class:`ControllerCore` wraps the dual-mode PID (:class:`hasel.pid.DualModePid`: C+
for e >= 0, C- for e < 0, bumpless switching) with everything the loop decides
around it (see FAULTS.md):

- **reference schedule**: references take effect at their time stamps
  (:class:`ReferenceSchedule`); before the first one the command is 0 kV;
- **reject and hold**: a sample that fails the plausibility gate (non-finite, out of
  range, a single-sample spike: :class:`hasel.faults.PlausibilityGate`) is counted and
  skipped; the last command is sent again, the integrator does not move;
- **stale feedback**: no accepted sample for more than ``stale_periods`` periods
  (:meth:`ControllerCore.poll`) holds the integrator, forgets the last error (no
  derivative kick on resume) and stops commanding, so the amplifier's watchdog drives
  0 kV; rejected samples do not count as fresh and send nothing while stale;
- **stuck sensor**: feedback frozen while the command moves
  (:class:`hasel.faults.StuckDetector`) latches the same stale state until the value
  changes.

Times are integer nanoseconds, as ROS stamps carry them, so the node graph and the
offline loop (:mod:`hasel.loop`) compare the same integers and decide alike.
"""
from __future__ import annotations

import bisect
import math
from dataclasses import dataclass

from hasel.faults import ERROR, OK, Notice, PlausibilityGate, StuckDetector
from hasel.pid import DualModePid, PidOutput
from hasel.timeconv import ns_to_s, s_to_ns
from hasel.validate import positive

__all__ = ["ReferenceSchedule", "ControlStep", "ControllerCore"]


class ReferenceSchedule:
    """Stroke references (mm), each in effect from its time (ns) until the next one."""

    def __init__(self) -> None:
        self._t_ns: list[int] = []
        self._mm: list[float] = []

    def __len__(self) -> int:
        return len(self._t_ns)

    def set(self, t_ns: int, stroke_mm: float) -> None:
        """Schedule ``stroke_mm`` from ``t_ns`` on; a second value for the same time replaces the first."""
        i = bisect.bisect_left(self._t_ns, t_ns)
        if i < len(self._t_ns) and self._t_ns[i] == t_ns:
            self._mm[i] = float(stroke_mm)
        else:
            self._t_ns.insert(i, int(t_ns))
            self._mm.insert(i, float(stroke_mm))

    def at(self, t_ns: int) -> float:
        """The reference (mm) in effect at ``t_ns``; NaN before the first one."""
        i = bisect.bisect_right(self._t_ns, t_ns) - 1
        return self._mm[i] if i >= 0 else math.nan

    def __call__(self, t_s: float) -> float:
        """The reference (mm) in effect at ``t_s`` seconds (rounded to the nearest ns)."""
        return self.at(s_to_ns(t_s))


@dataclass(slots=True)  # not frozen: built once per 200 Hz sample, where a frozen init costs more
class ControlStep:
    """What one feedback sample decided (read it, do not change it).

    ``command_kv`` is the request for the amplifier, kV (None: send nothing); ``pid``
    the controller update behind it (None when the sample updated no controller:
    rejected, stuck, stale, or no reference yet); ``fresh`` whether the sample was
    accepted (it restarts the stale deadline); ``notices`` the stale/ok transitions
    to report.
    """

    command_kv: float | None
    reference_mm: float
    pid: PidOutput | None
    fresh: bool
    notices: tuple[Notice, ...] = ()


class ControllerCore:
    """The controller's decisions; the node feeds it messages and publishes what it returns.

    Parameters
    ----------
    pid : DualModePid
        The dual-mode PID (its config holds the period Ts, s).
    gate : PlausibilityGate, optional
        The spike/range gate (1.5 mm per period by default).
    stuck : StuckDetector, optional
        The frozen-sensor detector.
    stale_periods : float
        Feedback older than this many periods is stale.
    """

    def __init__(self, pid: DualModePid | None = None, gate: PlausibilityGate | None = None,
                 stuck: StuckDetector | None = None, stale_periods: float = 3.0) -> None:
        self.pid = pid or DualModePid()
        self.gate = gate or PlausibilityGate()
        self.stuck = stuck or StuckDetector()
        self.stale_periods = positive("stale_periods", stale_periods)
        self.references = ReferenceSchedule()
        self.stale = False
        self.stuck_value: float | None = None
        self.last_output_kv = 0.0
        self.last_fresh_ns: int | None = None

    @property
    def rejected(self) -> int:
        """Samples rejected by the plausibility gate so far."""
        return self.gate.rejected

    @property
    def stale_after_ns(self) -> int:
        """Age (ns) beyond which the feedback is stale."""
        return s_to_ns(self.stale_periods * self.pid.config.period_s)

    def on_sample(self, t_ns: int, z_mm: float) -> ControlStep:
        """One feedback sample ``z_mm`` (mm) measured at ``t_ns`` (ns) -> what to command.

        The stale check runs first at ``t_ns``, so the outcome does not depend on whether
        the node's deadline timer or the sample of the same instant is handled first.
        """
        r = self.references.at(t_ns)
        late = self.poll(t_ns)
        notices = () if late is None else (late,)
        if self.stuck_value is not None:
            if z_mm == self.stuck_value:
                return ControlStep(None, r, None, False, notices)  # still frozen: stay in the fault
            self.stuck_value = None
            self.stuck.reset()
        if not self.gate.accept(z_mm):
            # hold the last command for this tick (nothing while stale); the integrator does not move
            return ControlStep(None if self.stale else self.last_output_kv, r, None, False, notices)
        self.last_fresh_ns = t_ns
        if self.stale:
            notices += (self._set_stale(False, t_ns, "feedback back"),)
        if self.stuck.update(z_mm, self.last_output_kv):
            self.stuck_value = z_mm
            notices += (self._set_stale(True, t_ns, "sensor stuck: no change while the command moved"),)
            return ControlStep(None, r, None, True, notices)
        if not math.isfinite(r):
            # nothing to track yet: 0 kV (alive, so the amplifier's watchdog stays calm)
            self.last_output_kv = 0.0
            return ControlStep(0.0, r, None, True, notices)
        out = self.pid.update(r, z_mm)
        self.last_output_kv = out.output_kv
        return ControlStep(out.output_kv, r, out, True, notices)

    def poll(self, now_ns: int) -> Notice | None:
        """The stale check at ``now_ns``: a notice when the feedback has just become stale."""
        if self.last_fresh_ns is None or self.stale:
            return None
        if now_ns - self.last_fresh_ns > self.stale_after_ns:
            return self._set_stale(True, now_ns, "no valid feedback")
        return None

    def _set_stale(self, stale: bool, t_ns: int, why: str) -> Notice:
        self.stale = stale
        if stale:
            self.pid.hold()
        return Notice(ERROR if stale else OK, f"feedback {'stale' if stale else 'ok'}: {why}", ns_to_s(t_ns),
                      {"integrator_kv": self.pid.i_kv})
