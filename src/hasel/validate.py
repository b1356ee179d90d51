"""Shared argument checks whose messages name the argument, the expected and the actual."""
from __future__ import annotations

import math
from typing import Any

from hasel.errors import BadInputError

__all__ = ["finite", "positive", "in_range"]


def finite(name: str, value: Any) -> float:
    """Return ``value`` as a float, or raise :class:`BadInputError` if it is not finite."""
    try:
        x = float(value)
    except (TypeError, ValueError) as err:
        raise BadInputError(f"{name} must be a number, got {value!r}") from err
    if not math.isfinite(x):
        raise BadInputError(f"{name} must be finite, got {x}")
    return x


def positive(name: str, value: Any) -> float:
    """Return ``value`` as a float, or raise if it is not finite and > 0."""
    x = finite(name, value)
    if x <= 0.0:
        raise BadInputError(f"{name} must be > 0, got {x}")
    return x


def in_range(name: str, value: Any, low: float, high: float) -> float:
    """Return ``value`` as a float, or raise if it is outside ``[low, high]``."""
    x = finite(name, value)
    if not low <= x <= high:
        raise BadInputError(f"{name} must be in [{low}, {high}], got {x}")
    return x
