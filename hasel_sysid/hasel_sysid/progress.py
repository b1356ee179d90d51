"""A small progress line on stderr for long runs (no dependency, quiet when not a TTY)."""
from __future__ import annotations

import sys
import time

__all__ = ["Progress"]


class Progress:
    """``Progress(total, label, unit)``; call with the current amount; ``done()`` at the end."""

    def __init__(self, total: float, label: str, unit: str = "s") -> None:
        self.total, self.label, self.unit = total, label, unit
        self.t0 = time.monotonic()
        self.tty = sys.stderr.isatty()
        self._last_pct = -10

    def __call__(self, value: float) -> None:
        pct = int(100 * min(value / self.total, 1.0)) if self.total > 0 else 100
        if self.tty:
            bar = "#" * (pct // 4) + "." * (25 - pct // 4)
            sys.stderr.write(f"\r{self.label} [{bar}] {value:.2f}/{self.total:g} {self.unit}")
        elif pct >= self._last_pct + 25:  # logs get a line per quarter
            self._last_pct = pct
            sys.stderr.write(f"{self.label}: {pct}% ({value:.2f}/{self.total:g} {self.unit})\n")
        sys.stderr.flush()

    def done(self) -> float:
        """Finish the line; returns the elapsed wall time, s."""
        dt = time.monotonic() - self.t0
        if self.tty:
            sys.stderr.write("\n")
        sys.stderr.write(f"{self.label}: done in {dt:.2f} s wall\n")
        return dt
