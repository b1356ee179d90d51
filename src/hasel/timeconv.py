"""Time conversions between float seconds and integer nanoseconds, in one place.

The core works in float seconds; ROS clocks, ``builtin_interfaces/Time`` stamps
(``sec`` int32 + ``nanosec`` uint32) and MCAP records carry integer nanoseconds. Every
conversion between the two, in the core, the I/O layer and the nodes, goes through
these functions, so that one instant gives the same float everywhere: nanoseconds
become seconds by one multiplication by ``1e-9`` (the graph and the offline loop then
agree to the bit), seconds become nanoseconds by rounding to the nearest one.
"""
from __future__ import annotations

import numpy as np

from hasel.errors import BadInputError

__all__ = ["NS_PER_S", "S_PER_NS", "MAX_TIME_NS", "s_to_ns", "ns_to_s", "ns_to_s_array", "stamp_to_ns",
           "ns_to_stamp", "stamp_to_s", "s_to_stamp"]

NS_PER_S = 1_000_000_000
S_PER_NS = 1e-9  # == 1 / NS_PER_S, the nearest double to 10**-9
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
    """Integer nanoseconds -> float seconds (``t_ns * 1e-9``, like :func:`ns_to_s_array`)."""
    return t_ns * S_PER_NS


def ns_to_s_array(t_ns: np.ndarray) -> np.ndarray:
    """Integer nanoseconds (array) -> float64 seconds (array), element by element as :func:`ns_to_s`."""
    return np.asarray(t_ns, dtype=np.int64) * S_PER_NS


def stamp_to_ns(sec: int, nanosec: int) -> int:
    """A ROS stamp (``sec`` s, ``nanosec`` ns) -> integer nanoseconds (exact)."""
    return int(sec) * NS_PER_S + int(nanosec)


def ns_to_stamp(t_ns: int) -> tuple[int, int]:
    """Integer nanoseconds -> ROS stamp ``(sec, nanosec)`` with ``0 <= nanosec < 1e9``.

    Negative times follow the ROS convention: -1.7 s is ``(-2, 300000000)``.
    """
    sec, nanosec = divmod(int(t_ns), NS_PER_S)
    return sec, nanosec


def stamp_to_s(sec: int, nanosec: int) -> float:
    """A ROS stamp -> float seconds (through its integer nanoseconds, so the same float as :func:`ns_to_s`)."""
    return ns_to_s(stamp_to_ns(sec, nanosec))


def s_to_stamp(t_s: float) -> tuple[int, int]:
    """Float seconds -> ROS stamp ``(sec, nanosec)``, rounded to the nearest nanosecond."""
    return ns_to_stamp(s_to_ns(t_s))
