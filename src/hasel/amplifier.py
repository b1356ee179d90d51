"""Safety logic of the high-voltage amplifier command (no ROS here; the node calls it).

Rules, in order of precedence:

1. 9 kV is a hard ceiling (:data:`HARD_CEILING_KV`): no parameter can raise it;
   ``v_max_kv`` may only lower it. Dielectric breakdown lies above it.
2. A non-finite request gives 0 kV.
3. Finite requests are clamped to ``[v_min_kv, v_max_kv]``.
4. The watchdog: no fresh command for more than ``watchdog_periods`` loop periods
   gives 0 kV until commands return; a command measured before the trip but handled
   after it (queued while the node was starved) keeps 0 kV (:class:`TripMark`).
5. Shutdown and disable give 0 kV.

The paper's charge-reversal pre-conditioning (-1 kV held before each test) is a
separate, deliberate request (:meth:`HvLimits.precondition`), bounded to
``[PRECONDITION_MIN_KV, 0]``; the controller's path can never produce it because
``v_min_kv`` cannot be negative.

:class:`AmplifierCore` is the amplifier node's decisions (limits, watchdog, the
diagnostics they raise); :class:`HeldOutput` is what the actuator gets in a period
without a fresh command (the DAC holds, the MCU's own watchdog zeroes). The nodes and
the offline loop (:mod:`hasel.loop`) use the same objects.
"""
from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass

import numpy as np

from hasel import paper
from hasel.errors import BadInputError, UnsafeParameterError
from hasel.faults import ERROR, WARN, Notice
from hasel.validate import finite, positive

__all__ = ["HARD_CEILING_KV", "PRECONDITION_MIN_KV", "Reason", "HvLimits", "Applied", "Watchdog",
           "AmplifierCore", "TripMark", "HeldOutput"]

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

    def apply_many(self, requested_kv) -> tuple[np.ndarray, np.ndarray]:
        """Limit a waveform (kV) sample by sample with :meth:`apply`: (applied kV, reasons)."""
        out = [self.apply(x) for x in np.asarray(requested_kv, dtype=float).tolist()]
        return (np.array([a.applied_kv for a in out], dtype=float),
                np.array([a.reason for a in out], dtype=np.int64))

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


class AmplifierCore:
    """The amplifier node's decisions: limits, watchdog and the diagnostics they raise.

    Every method takes the time ``now_s`` (s, the node's clock) and returns what to
    publish: the :class:`Applied` command and a :class:`~hasel.faults.Notice` when the
    reason changed to a limiting one (WARN for a clamp, ERROR for a non-finite request
    or the watchdog), else None.
    """

    def __init__(self, limits: HvLimits | None = None, watchdog: Watchdog | None = None) -> None:
        self.limits = limits or HvLimits()
        self.watchdog = watchdog or Watchdog()
        self.output_kv = 0.0
        self.last_reason = Reason.NONE
        self.tripped = False
        self._tripped_at_s: float | None = None
        self._drop_noticed = False  # a queued request dropped (and said) since the last feed (see queued_request)

    def _feed(self, now_s: float) -> None:
        self.watchdog.feed(now_s)
        self.tripped = False
        self._drop_noticed = False

    def _out(self, applied: Applied, now_s: float, **extra: float) -> tuple[Applied, Notice | None]:
        self.output_kv = applied.applied_kv
        reason, notice = applied.reason, None
        if reason != self.last_reason and reason not in (Reason.NONE, Reason.PRECONDITION):
            level = ERROR if reason in (Reason.WATCHDOG, Reason.NONFINITE) else WARN
            notice = Notice(level, f"output limited: {Reason.NAMES[reason]}", now_s,
                            {"requested_kv": applied.requested_kv, "applied_kv": applied.applied_kv, **extra})
        self.last_reason = reason
        return applied, notice

    def command(self, now_s: float, requested_kv: float) -> tuple[tuple[Applied, Notice | None], ...]:
        """A request from the controller (kV): limited, and the watchdog fed.

        Returns the outputs to publish in order: the request's, preceded by the
        watchdog's 0 kV when that fell due at ``now_s`` and the node's watchdog timer has
        not yet sent it (so the first output of an instant never depends on whether the
        timer or the request is handled first).
        """
        due = self.poll(now_s)
        self._feed(now_s)
        out = self._out(self.limits.apply(requested_kv), now_s)
        return (out,) if due is None else (due, out)

    def precondition(self, now_s: float, requested_kv: float) -> tuple[Applied, Notice | None]:
        """The deliberate charge reversal (kV), bounded to [-2, 0] kV; feeds the watchdog."""
        self._feed(now_s)
        return self._out(HvLimits.precondition(requested_kv), now_s)

    def batch(self, now_s: float, requested_kv) -> tuple[np.ndarray, Notice | None]:
        """An open-loop waveform (kV): every sample limited; a WARN notice when any was."""
        self._feed(now_s)
        req = np.asarray(requested_kv, dtype=float)
        applied, reasons = self.limits.apply_many(req)
        n_limited = int(np.count_nonzero(reasons != Reason.NONE))
        self.output_kv = float(applied[-1]) if applied.size else 0.0
        if not n_limited:
            return applied, None
        return applied, Notice(WARN, "batch samples limited", now_s,
                               {"samples": n_limited,
                                "max_requested_kv": float(np.nanmax(np.where(np.isfinite(req), req, 0)))})

    def poll(self, now_s: float) -> tuple[Applied, Notice | None] | None:
        """The watchdog at ``now_s``: 0 kV (``WATCHDOG``) once commands are stale, else None.

        The notice of a trip carries ``command_age_s``: the time since the last command
        arrived, s, on this clock (how late the watchdog acted, apart from the latency of
        the chain upstream, which the commands' stamps include).
        """
        if self.watchdog.last_s is None or not self.watchdog.expired(now_s) or now_s == self._tripped_at_s:
            return None  # fresh, never fed, or this instant's 0 kV already sent
        self.tripped, self._tripped_at_s = True, now_s
        return self._out(Applied(math.nan, 0.0, Reason.WATCHDOG), now_s, command_age_s=now_s - self.watchdog.last_s)

    def queued_request(self, now_s: float, requested_kv: float) -> tuple[Applied, Notice | None]:
        """A request (kV) measured before the watchdog's trip was sent, handled after it.

        It waited in the node's queue while the node was starved: had it been handled in time, the trip
        would not have happened; handled now it is as stale as the trip said (its sender may be dead). It
        gives 0 kV (``WATCHDOG``) and does not feed the watchdog; a WARN notice says so at the first
        one after each trip (see :class:`TripMark`, which decides what counts as measured before)."""
        first, self._drop_noticed = not self._drop_noticed, True
        req = _finite_or_none(requested_kv)
        out, _ = self._out(Applied(math.nan if req is None else req, 0.0, Reason.WATCHDOG), now_s)
        if not first:
            return out, None
        return out, Notice(WARN, "stale command dropped: measured before the watchdog tripped", now_s,
                           {"requested_kv": out.requested_kv, "applied_kv": 0.0})

    def shutdown(self, now_s: float) -> tuple[Applied, Notice | None]:
        """0 kV on the way out (``SHUTDOWN``)."""
        return self._out(Applied(math.nan, 0.0, Reason.SHUTDOWN), now_s)


class TripMark:
    """Which requests were measured before the watchdog's trip was sent: those are stale.

    A node starved of CPU for longer than the watchdog's timeout handles its timer first (rclpy's
    executors take ready timers before ready subscriptions), sends the trip's 0 kV, and then the
    requests that queued meanwhile, the last of them perhaps sent by a controller that has since
    died: applied, they would put a stale voltage back on the actuator for another timeout.

    Decided on the requests' stamps (the time of the measurement they answer), with no
    assumption that the stamps' clock is this node's: a request measured at ``s`` (stamps'
    clock) arrived at ``t`` (node clock), latency ``t - s`` = clock offset + transport delay.
    The smallest latency of the last ``history`` requests bounds the offset from above, so the
    trip, sent at ``T``, lies at or after ``T - min(t - s)`` on the stamps' clock, and a request
    stamped before that was measured before the trip. The smallest, not the last: on a loaded
    machine one late request (a CI run saw 39 ms through the chain) put the mark so early that
    requests measured 23-39 ms before the trip passed as fresh. A request measured after the
    trip always has a stamp above the mark, so none is ever dropped for being early. Only the
    two clocks' rates need to agree (one machine, or simulated time everywhere), not their
    offsets. Every executor gives the stamp (rclpy's EventsExecutor has no reception time).
    Two guards keep it from holding 0 kV on a fresh request: an unset stamp (0) counts as
    fresh, and so does any request handled more than ``window_s`` (s, monotonic clock) after
    the trip.
    """

    def __init__(self, window_s: float = 1.0, history: int = 400) -> None:
        self.window_ns = int(positive("window_s", window_s) * 1e9)
        # latencies (node clock - stamps' clock, s) of the last requests fed; 400 = 2 s at 200 Hz, short
        # enough that a slow drift between two clocks of nearly one rate does not matter
        self._latency: deque[float] = deque(maxlen=int(positive("history", history)))
        self.trip_stamp_s: float | None = None  # the trip on the stamps' clock, s
        self._trip_mono_ns = 0

    def fed(self, now_s: float, stamp_s: float) -> None:
        """A request stamped ``stamp_s`` was applied at ``now_s`` (s): a latency sample; no trip pending."""
        self.clear()
        if stamp_s > 0.0:
            self._latency.append(float(now_s) - float(stamp_s))

    def clear(self) -> None:
        """A request was applied (a waveform, a pre-conditioning): no trip pending."""
        self.trip_stamp_s = None

    def trip(self, now_s: float, mono_ns: int) -> None:
        """The watchdog's trip was sent at ``now_s`` (node clock, s) / ``mono_ns`` (monotonic, ns). Repeats
        of the 0 kV while still tripped keep the first mark."""
        if self.trip_stamp_s is None and self._latency:
            self.trip_stamp_s, self._trip_mono_ns = now_s - min(self._latency), int(mono_ns)

    def queued(self, stamp_s: float, mono_ns: int) -> bool:
        """True when a request stamped ``stamp_s`` (s), handled at ``mono_ns`` (monotonic, ns), was measured
        before the trip was sent."""
        return (self.trip_stamp_s is not None and 0.0 < stamp_s < self.trip_stamp_s
                and int(mono_ns) - self._trip_mono_ns <= self.window_ns)


class HeldOutput:
    """What the actuator gets in a loop period (kV) with or without a fresh amplifier command.

    The DAC holds the last value; after more than ``periods`` periods without a fresh
    one the MCU's own watchdog applies 0 kV. A non-finite command applies 0 kV.
    """

    def __init__(self, periods: int = 3) -> None:
        self.periods = int(periods)
        self.value: float | np.ndarray = 0.0
        self.missed = 0

    def fresh(self, command_kv: float | np.ndarray) -> float | np.ndarray:
        """A command for this period (one value, or a waveform): what is applied, kV."""
        if np.ndim(command_kv):
            self.value = np.where(np.isfinite(command_kv), command_kv, 0.0)
        else:
            self.value = command_kv if math.isfinite(command_kv) else 0.0
        self.missed = 0
        return self.value

    def missing(self) -> float | np.ndarray:
        """No command arrived for this period: what is applied, kV."""
        self.missed += 1
        if self.missed > self.periods:
            self.value = 0.0
        return self.value
