"""Safety logic of the high-voltage amplifier command (no ROS here; the node calls it).

Rules, in order of precedence:

1. 9 kV is a hard ceiling (:data:`HARD_CEILING_KV`): no parameter can raise it;
   ``v_max_kv`` may only lower it. Dielectric breakdown lies above it.
2. A non-finite request gives 0 kV.
3. Finite requests are clamped to ``[v_min_kv, v_max_kv]``.
4. The watchdog: no fresh command for more than ``watchdog_periods`` loop periods
   gives 0 kV until commands return.
5. Shutdown and disable give 0 kV.

The paper's charge-reversal pre-conditioning (-1 kV held before each test) is a
separate, deliberate request (:meth:`HvLimits.precondition`), bounded to
``[PRECONDITION_MIN_KV, 0]``; the controller's path can never produce it because
``v_min_kv`` cannot be negative.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

from hasel import paper
from hasel.errors import BadInputError, UnsafeParameterError
from hasel.validate import finite, positive

__all__ = ["HARD_CEILING_KV", "PRECONDITION_MIN_KV", "Reason", "HvLimits", "Applied", "Watchdog"]

HARD_CEILING_KV = paper.V_MAX_KV
PRECONDITION_MIN_KV = -2.0


class Reason:
    """Why the applied voltage differs from the request (values of VoltageCommand.reason)."""

    NONE = 0
    CLAMP_HIGH = 1
    CLAMP_LOW = 2
    NONFINITE = 3
    WATCHDOG = 4
    SHUTDOWN = 5
    PRECONDITION = 6
    DISABLED = 7

    NAMES = {0: "none", 1: "clamp_high", 2: "clamp_low", 3: "nonfinite", 4: "watchdog",
             5: "shutdown", 6: "precondition", 7: "disabled"}


@dataclass(frozen=True)
class Applied:
    """Result of the limits: what goes to the actuator (kV) and why."""

    requested_kv: float
    applied_kv: float
    reason: int

    @property
    def clamped(self) -> bool:
        """True when the applied voltage is not the request."""
        return self.reason != Reason.NONE


def _finite_or_none(value: object) -> float | None:
    """``value`` as a finite float, or None (NaN, infinite, not a number at all)."""
    try:
        x = float(value)  # type: ignore[arg-type]
    except (TypeError, ValueError):
        return None
    return x if math.isfinite(x) else None


def _nonfinite(value: object) -> Applied:
    """0 kV for a request that is not a finite number."""
    try:
        req = float(value)  # type: ignore[arg-type]
    except (TypeError, ValueError):
        req = math.nan
    return Applied(req, 0.0, Reason.NONFINITE)


@dataclass(frozen=True)
class HvLimits:
    """Voltage limits of the amplifier command, kV.

    Raises :class:`UnsafeParameterError` with the reason for any unsafe setting.
    """

    v_min_kv: float = 0.0
    v_max_kv: float = HARD_CEILING_KV

    def __post_init__(self) -> None:
        lo, hi = finite("v_min_kv", self.v_min_kv), finite("v_max_kv", self.v_max_kv)
        if hi > HARD_CEILING_KV:
            raise UnsafeParameterError(
                f"v_max_kv={hi} kV is above the hard {HARD_CEILING_KV} kV ceiling (dielectric breakdown)")
        if lo < 0.0:
            raise UnsafeParameterError(
                f"v_min_kv={lo} kV is negative: reverse voltage is only for the deliberate pre-conditioning")
        if not lo < hi:
            raise BadInputError(f"v_min_kv ({lo}) must be below v_max_kv ({hi})")

    def apply(self, requested_kv: float) -> Applied:
        """Limit one request (kV)."""
        req = _finite_or_none(requested_kv)
        if req is None:
            return _nonfinite(requested_kv)
        if req > self.v_max_kv:
            return Applied(req, self.v_max_kv, Reason.CLAMP_HIGH)
        if req < self.v_min_kv:
            return Applied(req, self.v_min_kv, Reason.CLAMP_LOW)
        return Applied(req, req, Reason.NONE)

    @staticmethod
    def precondition(requested_kv: float) -> Applied:
        """The deliberate charge-reversal command (paper: -1 kV), kept in [-2, 0] kV."""
        req = _finite_or_none(requested_kv)
        if req is None:
            return _nonfinite(requested_kv)
        return Applied(req, min(max(req, PRECONDITION_MIN_KV), 0.0), Reason.PRECONDITION)


class Watchdog:
    """Declares commands stale after ``periods`` loop periods without a fresh one.

    Times are the caller's clock in seconds (ROS or simulated time).
    """

    def __init__(self, period_s: float = paper.LOOP_PERIOD_S, periods: float = 3.0) -> None:
        self.period_s = positive("period_s", period_s)
        self.periods = positive("periods", periods)
        self.last_s: float | None = None

    @property
    def timeout_s(self) -> float:
        """Age after which a command is stale, seconds."""
        return self.period_s * self.periods

    def feed(self, now_s: float) -> None:
        """A fresh command arrived at ``now_s``."""
        self.last_s = now_s

    def expired(self, now_s: float) -> bool:
        """True when no command is fresh at ``now_s`` (also before the first one)."""
        if self.last_s is None:
            return True
        age = now_s - self.last_s
        # a clock that jumps backwards makes the command's age meaningless: stale
        return age > self.timeout_s + 1e-9 or age < -self.period_s
