"""CDR bytes for test fixtures, serialised by ``mcap_ros2`` (an independent codec; the toolkit only decodes).

``encode(type_name, msg)`` takes a mapping (nested mappings for nested messages; lists or
numpy arrays for arrays; missing fields are zero or empty) and returns the message's CDR
bytes with their encapsulation header, as rclpy would hand them to the recorder.
"""
from __future__ import annotations

from typing import Any

import numpy as np
from mcap_ros2._dynamic import serialize_dynamic

from hasel.io.msgdefs import message_definition

_ENCODERS: dict[tuple[str, str | None], Any] = {}


def _plain(value: Any) -> Any:
    """numpy arrays and scalars -> Python lists and numbers, which mcap_ros2 packs."""
    if isinstance(value, dict):
        return {k: _plain(v) for k, v in value.items()}
    if isinstance(value, np.ndarray):
        return value.tolist()
    if isinstance(value, (list, tuple)):
        return [_plain(v) for v in value]
    if isinstance(value, np.generic):
        return value.item()
    return value


def encode(type_name: str, msg: dict, definition: str | None = None) -> bytes:
    """CDR bytes of ``msg`` of ``type_name`` (its definition from :mod:`hasel.io.msgdefs` unless given)."""
    key = (type_name, definition)
    enc = _ENCODERS.get(key)
    if enc is None:
        text = message_definition(type_name) if definition is None else definition
        enc = _ENCODERS[key] = serialize_dynamic(type_name, text)[type_name]
    return bytes(enc(_plain(msg)))
