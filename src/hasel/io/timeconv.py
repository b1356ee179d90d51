"""Time conversions at the MCAP and ROS boundary, in one place.

The core works in float seconds; MCAP records and ROS ``builtin_interfaces/Time``
stamps carry integer nanoseconds (``sec`` int32 + ``nanosec`` uint32). Everything
that crosses that boundary goes through these functions.
"""
from __future__ import annotations

import numpy as np

from hasel.errors import BadInputError

__all__ = ["NS_PER_S", "s_to_ns", "ns_to_s", "ns_to_s_array", "stamp_to_ns", "ns_to_stamp", "MAX_TIME_NS"]

NS_PER_S = 1_000_000_000
MAX_TIME_NS = 2**64 - 1  # MCAP timestamps are uint64 nanoseconds


def s_to_ns(t_s: float) -> int:
    """Float seconds -> integer nanoseconds (rounded to the nearest ns).

    Raises
    ------
    BadInputError
        If ``t_s`` is not finite.
    """
    x = float(t_s)
    if not np.isfinite(x):
        raise BadInputError(f"time must be finite, got {t_s!r} s")
    return int(round(x * NS_PER_S))


def ns_to_s(t_ns: int) -> float:
    """Integer nanoseconds -> float seconds."""
    return int(t_ns) / NS_PER_S


def ns_to_s_array(t_ns: np.ndarray) -> np.ndarray:
    """Integer nanoseconds (array) -> float64 seconds (array)."""
    return np.asarray(t_ns, dtype=np.int64) * (1.0 / NS_PER_S)


def stamp_to_ns(sec: int, nanosec: int) -> int:
    """A ROS stamp (``sec`` s, ``nanosec`` ns) -> integer nanoseconds."""
    return int(sec) * NS_PER_S + int(nanosec)


def ns_to_stamp(t_ns: int) -> tuple[int, int]:
    """Integer nanoseconds -> ROS stamp ``(sec, nanosec)`` with ``0 <= nanosec < 1e9``.

    Negative times follow the ROS convention: -1.7 s is ``(-2, 300000000)``.
    """
    sec, nanosec = divmod(int(t_ns), NS_PER_S)
    return sec, nanosec
