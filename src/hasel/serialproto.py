"""The line protocol between the host and the MCU that times the 555 and drives the DAC.

A real rig (paper Fig. 1c: a Teensy 3.6 times the LMC555 edges with interrupts and
outputs the amplifier command on its DAC) talks to the host over a serial line
(USB CDC or UART, 115200 baud 8N1 or faster). Frames are ASCII lines in the NMEA
style, so a terminal can read them and a corrupted line is detected::

    <TYPE>,<field>,<field>...*<XX>\\n

where XX is the two-hex-digit XOR of every byte between the start of the line and
``*``. Frames (all times in microseconds of the sender's clock, voltages in kV):

========  =========  ========================================================
type      direction  fields
========  =========  ========================================================
``T``     MCU->host  seq, t_us, elapsed_us: one strain-sensor timing sample
``L``     MCU->host  seq, t_us, laser_mm: one laser reading (optional)
``A``     MCU->host  seq, applied_kv: the voltage now on the DAC (after its clamp)
``H``     both       seq, t_us: heartbeat (sent at least every loop period)
``V``     host->MCU  seq, kv: set the amplifier command
``Z``     host->MCU  seq: 0 kV now
========  =========  ========================================================

Firmware rules (the host relies on them; :class:`McuModel` implements them):
the MCU clamps every ``V`` to [0, 9] kV itself, treats a malformed value as 0 kV, and
drives 0 kV when it has heard nothing from the host (no ``V`` or ``H``) for three loop
periods. The host drives 0 kV (``Z``) and reports an error when it hears nothing from
the MCU for three periods.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

from hasel.amplifier import HARD_CEILING_KV

__all__ = ["Frame", "encode", "decode", "LineBuffer", "McuModel", "ProtocolError"]


class ProtocolError(ValueError):
    """A line that is not a valid frame (bad checksum, type or fields)."""


_FIELDS = {"T": 3, "L": 3, "A": 2, "H": 2, "V": 2, "Z": 1}


@dataclass(frozen=True)
class Frame:
    """A decoded frame: its type letter and its numeric fields."""

    kind: str
    fields: tuple[float, ...]

    @property
    def seq(self) -> int:
        """The frame's sequence number."""
        return int(self.fields[0])


def _checksum(body: bytes) -> int:
    c = 0
    for b in body:
        c ^= b
    return c


def encode(kind: str, *fields: float) -> bytes:
    """One frame as bytes, checksum and newline included."""
    if kind not in _FIELDS or len(fields) != _FIELDS[kind]:
        raise ProtocolError(f"frame {kind!r} takes {_FIELDS.get(kind, '?')} fields, got {len(fields)}")
    parts = [kind] + [str(int(f)) if float(f).is_integer() and abs(f) < 2**53 else repr(float(f)) for f in fields]
    body = ",".join(parts).encode("ascii")
    return body + b"*%02X\n" % _checksum(body)


def decode(line: bytes) -> Frame:
    """Parse one line (with or without its newline); raises :class:`ProtocolError`."""
    line = line.strip()
    star = line.rfind(b"*")
    if star < 1 or len(line) - star != 3:
        raise ProtocolError(f"no checksum in {line[:40]!r}")
    body = line[:star]
    try:
        given = int(line[star + 1:], 16)
        parts = body.decode("ascii").split(",")
    except (ValueError, UnicodeDecodeError) as err:
        raise ProtocolError(f"unreadable frame {line[:40]!r}") from err
    if given != _checksum(body):
        raise ProtocolError(f"checksum mismatch in {line[:40]!r}")
    kind = parts[0]
    if kind not in _FIELDS or len(parts) - 1 != _FIELDS[kind]:
        raise ProtocolError(f"unknown frame or wrong field count: {line[:40]!r}")
    try:
        fields = tuple(float(p) for p in parts[1:])
    except ValueError as err:
        raise ProtocolError(f"non-numeric field in {line[:40]!r}") from err
    return Frame(kind, fields)


class LineBuffer:
    """Splits a byte stream into frames; counts and skips bad lines; bounds a runaway line."""

    def __init__(self, max_line: int = 256) -> None:
        self.buf = b""
        self.max_line = max_line
        self.bad = 0

    def feed(self, data: bytes) -> list[Frame]:
        """Add received bytes; return the complete, valid frames."""
        self.buf += data
        out = []
        while True:
            nl = self.buf.find(b"\n")
            if nl < 0:
                if len(self.buf) > self.max_line:  # garbage without newline: drop it
                    self.buf = b""
                    self.bad += 1
                return out
            line, self.buf = self.buf[:nl], self.buf[nl + 1:]
            if not line.strip():
                continue
            try:
                out.append(decode(line))
            except ProtocolError:
                self.bad += 1


class McuModel:
    """What the firmware does with host frames: its own clamp and its own watchdog.

    Times are the MCU's clock in seconds.
    """

    def __init__(self, period_s: float = 0.005, watchdog_periods: float = 3.0) -> None:
        self.period_s = period_s
        self.timeout_s = period_s * watchdog_periods
        self.output_kv = 0.0
        self.last_host_s: float | None = None

    def handle(self, frame: Frame, now_s: float) -> None:
        """Apply one host frame."""
        if frame.kind in ("V", "H", "Z"):
            self.last_host_s = now_s
        if frame.kind == "V":
            kv = frame.fields[1]
            self.output_kv = min(max(kv, 0.0), HARD_CEILING_KV) if math.isfinite(kv) else 0.0
        elif frame.kind == "Z":
            self.output_kv = 0.0

    def tick(self, now_s: float) -> float:
        """Run the watchdog; returns the DAC command in kV."""
        if self.last_host_s is None or now_s - self.last_host_s > self.timeout_s + 1e-9:
            self.output_kv = 0.0
        return self.output_kv
