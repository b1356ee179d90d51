"""Shared argument checks whose messages name the argument, the expected and the actual."""
from __future__ import annotations

import argparse
import math
from pathlib import Path
from typing import Any

from hasel.errors import BadInputError

__all__ = ["finite", "positive", "in_range", "seed", "text_file", "excited", "SEED_MAX"]

SEED_MAX = 2**31 - 1  # the nodes' seed parameters take a signed 32-bit integer


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


def seed(text: str) -> int:
    """argparse type of a noise seed: an integer in [0, 2^31 - 1] (what the nodes accept)."""
    try:
        x = int(text)
    except ValueError as err:
        raise argparse.ArgumentTypeError(f"must be an integer in [0, {SEED_MAX}], got {text!r}") from err
    if not 0 <= x <= SEED_MAX:
        raise argparse.ArgumentTypeError(f"must be an integer in [0, {SEED_MAX}], got {x}")
    return x


def text_file(name: str, path: str, limit_bytes: int = 64 << 20) -> Path:
    """Check that ``path`` (the option ``name``) is a readable UTF-8 text file; return it.

    Raises :class:`BadInputError` naming the option, the file and what is wrong (missing,
    a directory, too big, or binary: the byte offset of the first undecodable byte).
    """
    p = Path(path)
    if not p.exists():
        raise BadInputError(f"no such {name.lstrip('-')} file: {p} (given as {name})")
    if not p.is_file():
        raise BadInputError(f"{name} {p} is not a regular file")
    try:
        size = p.stat().st_size
        if size > limit_bytes:
            raise BadInputError(f"{name} {p} is {size} bytes; a text file of at most {limit_bytes} was expected")
        data = p.read_bytes()
    except OSError as err:
        raise BadInputError(f"cannot read {name} {p}: {err.strerror or err}") from err
    try:
        data.decode("utf-8")
    except UnicodeDecodeError as err:
        kind = "an MCAP log" if data.startswith(b"\x89MCAP") else "binary"
        raise BadInputError(f"{name} {p} is not a text file ({kind}: byte {err.start} is not UTF-8)") from err
    return p


def excited(name: str, samples: Any, purpose: str) -> None:
    """Raise :class:`BadInputError` if the input ``samples`` (any unit) never change: nothing to ``purpose`` from.

    Constant means a spread within 1e-12 of the larger of 1 and the largest magnitude
    (a wiggle of float rounding excites nothing either).
    """
    import numpy as np  # here, not at the top: the `hasel` command imports this module at start-up

    x = np.asarray(samples, float)
    if np.ptp(x) <= 1e-12 * max(1.0, float(np.max(np.abs(x)))):
        raise BadInputError(f"{name} is constant ({x[0]:.6g}): no excitation to {purpose} from")
