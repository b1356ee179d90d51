"""Sensor-fault detectors used by the controller: a plausibility gate and a stuck-sensor check.

Plausibility gate: a sample outside the physical range, or one that jumps further
from the last accepted sample than the actuator can move in one period, is rejected
(and counted); the controller then skips that update (integrator held). Several
consecutive rejections in a row mean the sensor really moved (or was recalibrated):
the gate re-anchors on the new level rather than locking the loop out forever.
The default step (1.5 mm per 5 ms, i.e. 300 mm/s) is about three times the fastest
stroke rate of the paper's closed loop.

Stuck sensor: if the command moved by at least ``min_command_change_kv`` over a window
while the feedback did not change at all, the sensor is not seeing the actuator
(a frozen driver, a shorted 555, a laser out of range).

A :class:`Notice` is what a core object asks its node to report on ``/diagnostics``
(the node only translates it into a ``diagnostic_msgs/DiagnosticStatus``).
"""
from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass, field

from hasel.validate import positive

__all__ = ["PlausibilityGate", "StuckDetector", "Notice", "OK", "WARN", "ERROR"]

# levels of a Notice: the values of diagnostic_msgs/DiagnosticStatus.level
OK, WARN, ERROR = 0, 1, 2


@dataclass(frozen=True)
class Notice:
    """A diagnostic to report: ``level`` (:data:`OK`, :data:`WARN`, :data:`ERROR`), a message,
    key values (floats in the units their names say), at ``t_s`` seconds."""

    level: int
    message: str
    t_s: float
    values: dict = field(default_factory=dict)


class PlausibilityGate:
    """Rejects single-sample spikes and out-of-range values (mm)."""

    def __init__(self, max_step_mm: float = 1.5, lo_mm: float = -2.0, hi_mm: float = 25.0,
                 reanchor_after: int = 3) -> None:
        self.max_step_mm = positive("max_step_mm", max_step_mm)
        self.lo_mm, self.hi_mm = float(lo_mm), float(hi_mm)
        self.reanchor_after = int(reanchor_after)
        self.last: float | None = None
        self.rejected = 0
        self._run = 0

    def accept(self, z_mm: float) -> bool:
        """True if ``z_mm`` is plausible (and becomes the reference for the next one)."""
        if not math.isfinite(z_mm) or not self.lo_mm <= z_mm <= self.hi_mm:
            self.rejected += 1
            return False
        if self.last is not None and abs(z_mm - self.last) > self.max_step_mm:
            self._run += 1
            if self._run <= self.reanchor_after:
                self.rejected += 1
                return False
        self._run = 0
        self.last = z_mm
        return True


class StuckDetector:
    """Flags a feedback that stays constant while the command moves."""

    def __init__(self, window: int = 40, min_command_change_kv: float = 0.5, tol_mm: float = 0.0) -> None:
        self.window = int(window)
        self.min_change = positive("min_command_change_kv", min_command_change_kv)
        self.tol_mm = float(tol_mm)
        self._z: deque[float] = deque(maxlen=self.window)
        self._u: deque[float] = deque(maxlen=self.window)
        self.stuck = False

    def update(self, z_mm: float, command_kv: float) -> bool:
        """Add one (feedback, command) pair; return True while the sensor looks stuck."""
        self._z.append(z_mm)
        self._u.append(command_kv)
        if len(self._z) < self.window:
            self.stuck = False
        else:
            self.stuck = (max(self._z) - min(self._z) <= self.tol_mm
                          and max(self._u) - min(self._u) >= self.min_change)
        return self.stuck

    def reset(self) -> None:
        """Forget the window (after a fault has been handled)."""
        self._z.clear()
        self._u.clear()
        self.stuck = False
