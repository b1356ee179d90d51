"""The plant node with the real-time bench's loop statistics, measured around its stepping.

The product's plant node (:class:`sim_plant.plant_node.PlantNode`) keeps no statistics;
this subclass, used only by :mod:`hasel_bench.realtime`, watches the same points from
outside: each wall-clock tick's stamp as it is published, the amplifier output that
answers it, and the timer's wake-ups.
"""
from __future__ import annotations

import time

from hasel.timeconv import stamp_to_ns
from sim_plant.plant_node import PlantNode

__all__ = ["MeasuredPlant"]


class MeasuredPlant(PlantNode):
    """:class:`PlantNode` measuring its real-time loop (``clock_mode=wall``).

    Kept per tick (reset by :meth:`reset_wall_stats`): ``latencies_ns`` (a tick's sensor
    stamp to the arrival of the amplifier output carrying it, ns), ``missed_periods`` and
    ``missed_at_ns`` (ticks whose output had not arrived by the next tick, and the
    steady-clock ns of that next wake-up), ``skipped_periods`` and ``skipped_at_ns``
    (periods the timer skipped because it woke a period or more late), ``ticks``.
    """

    def __init__(self, *args, **kwargs) -> None:
        self.reset_wall_stats()
        self._wall_tick_ns: int | None = None
        self._answered = True
        super().__init__(*args, **kwargs)

    def reset_wall_stats(self) -> None:
        """Forget the loop's statistics (and the phase of the timer's schedule)."""
        self.latencies_ns: list[int] = []
        self.missed_periods = 0
        self.missed_at_ns: list[int] = []
        self.skipped_periods = 0
        self.skipped_at_ns: list[int] = []
        self.ticks = 0
        self._first_wake_ns: int | None = None
        self._tick_index = 0

    def on_applied(self, msg) -> None:
        """The amplifier's output; the answer to the latest tick gives its latency."""
        super().on_applied(msg)
        self._answer(msg.header.stamp)

    def on_applied_batch(self, msg) -> None:
        """The amplifier's 10 kHz output; the answer to the latest tick gives its latency."""
        super().on_applied_batch(msg)
        self._answer(msg.header.stamp)

    def _answer(self, stamp) -> None:
        ns = stamp_to_ns(stamp.sec, stamp.nanosec)
        if self.clock_mode == "wall" and ns == self._wall_tick_ns:
            self.latencies_ns.append(self.get_clock().now().nanoseconds - ns)
            self._answered = True

    def on_wall_tick(self) -> None:
        """Count a missed or skipped period from this wake-up, then step as the product does."""
        wake = time.monotonic_ns()
        if self._wall_tick_ns is not None and not self._answered:
            self.missed_periods += 1
            self.missed_at_ns.append(wake)
        # which period of the timer's schedule this wake-up serves: a wake-up less than a
        # period late still serves its own (the timer keeps its schedule), one that
        # jumps periods means the timer skipped them
        if self._first_wake_ns is None:
            self._first_wake_ns, self._tick_index = wake, 0
        else:
            index = (wake - self._first_wake_ns + self.period_ns // 10) // self.period_ns
            if index > self._tick_index + 1:
                self.skipped_periods += index - self._tick_index - 1
                self.skipped_at_ns.append(wake)
            self._tick_index = max(index, self._tick_index + 1)
        super().on_wall_tick()
        self.ticks += 1

    def _publish_tick(self, ns: int | None = None) -> None:
        if self.clock_mode == "wall" and ns is not None:  # the stamp an answer will carry
            self._wall_tick_ns, self._answered = ns, False
        super()._publish_tick(ns)
