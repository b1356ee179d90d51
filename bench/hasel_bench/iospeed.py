"""Measurements of the I/O layer for ``hasel bench``: writer overhead and loading speed.

- :func:`writer_overhead`: CPU time per message of :class:`Ros2McapWriter` against a bare
  ``mcap.writer.Writer`` writing the same pre-serialised bytes with the same chunk size
  and zstd level (the target is a ratio below 1.3).
- :func:`load_speed`: a log of the paper's identification campaign size (18 segments x
  60 s x 10 kHz, 50 samples per ``SampleBatch`` at 200 Hz, 10.8 M samples) is written,
  then :func:`load_signals` reads ``voltage_kv`` and ``stroke_mm``; samples per second.
"""
from __future__ import annotations

import struct
import tempfile
import time
from pathlib import Path
from typing import Any

import numpy as np

from hasel.io.loader import load_signals
from hasel.io.msgdefs import message_definition
from hasel.io.writer import DEFAULT_CHUNK_SIZE, Ros2McapWriter
from hasel.timeconv import s_to_ns

__all__ = ["writer_overhead", "load_speed", "encode", "encode_sample_batch"]

_BATCH = "hasel_msgs/msg/SampleBatch"
_STROKE = "hasel_msgs/msg/Stroke"
_ENCODERS: dict[str, Any] = {}


def encode(type_name: str, msg: dict[str, Any]) -> bytes:
    """CDR bytes of one message given as a mapping, serialised by ``mcap_ros2`` (benchmark inputs only).

    The toolkit itself never encodes CDR (the recorder writes what rclpy received).
    """
    from mcap_ros2._dynamic import serialize_dynamic

    enc = _ENCODERS.get(type_name)
    if enc is None:
        enc = _ENCODERS[type_name] = serialize_dynamic(type_name, message_definition(type_name))[type_name]
    return bytes(enc(msg))


_HEAD = struct.Struct("<iII").pack  # header.stamp (sec, nanosec), frame_id length
_U32 = struct.Struct("<I").pack
_F64 = struct.Struct("<d").pack


def encode_sample_batch(stamp_ns: int, sample_period_s: float, voltage_kv: Any = (), stroke_mm: Any = (),
                        true_stroke_mm: Any = (), elapsed_us: Any = (), frame_id: str = "") -> bytes:
    """CDR bytes of a ``hasel_msgs/msg/SampleBatch`` from numpy arrays (kV, mm, mm, us), fast.

    The same bytes as :func:`encode` (offsets relative to the payload after the 4-byte
    encapsulation header, 8-byte values aligned to 8); for writing big benchmark logs.
    """
    from hasel.timeconv import ns_to_stamp

    name = frame_id.encode("utf-8")
    out = bytearray(b"\x00\x01\x00\x00")
    out += _HEAD(*ns_to_stamp(stamp_ns), len(name) + 1) + name + b"\x00"
    out += b"\x00" * ((-(len(out) - 4)) % 8)
    out += _F64(float(sample_period_s))
    for arr in (voltage_kv, stroke_mm, true_stroke_mm, elapsed_us):
        a = np.asarray(arr, dtype="<f8").ravel()
        out += b"\x00" * ((-(len(out) - 4)) % 4)
        out += _U32(a.size)
        if a.size:
            out += b"\x00" * ((-(len(out) - 4)) % 8)
            out += a.tobytes()
    return bytes(out)


def _messages(n: int, rng: np.random.Generator) -> list[tuple[int, bytes, int]]:
    out = []
    for i in range(n):
        t = 10**9 + i * 5_000_000
        if i % 2 == 0:
            out.append((1, encode_sample_batch(t, 1e-4, rng.normal(size=50), rng.normal(size=50),
                                               rng.normal(size=50)), t))
        else:
            out.append((2, encode(_STROKE, {"header": {"stamp": {"sec": t // 10**9, "nanosec": t % 10**9}},
                                            "stroke_mm": float(rng.normal()), "source": 2}), t))
    return out


def _write_ours(path: Path, msgs: list[tuple[int, bytes, int]], compression: str, level: int) -> float:
    """Write ``msgs`` (channel 1: SampleBatch, 2: Stroke) with :class:`Ros2McapWriter`; CPU s of the writes."""
    with Ros2McapWriter(path, compression=compression, compression_level=level,
                        max_chunk_span_s=None, fsync_interval_s=None) as w:
        w.add_topic("/plant/batch", _BATCH)
        w.add_topic("/sensor/stroke", _STROKE)
        t0 = time.process_time()
        for c, d, t in msgs:
            w.write(c, d, t, t)
        w.close()
        return time.process_time() - t0


def _write_bare(path: Path, msgs: list[tuple[int, bytes, int]], compression) -> float:
    """The same messages through a bare ``mcap.writer.Writer`` (same chunk size); CPU s of the writes."""
    from mcap.writer import Writer

    defs = {name: message_definition(name).encode() for name in (_BATCH, _STROKE)}
    w = Writer(str(path), chunk_size=DEFAULT_CHUNK_SIZE, compression=compression)
    w.start("ros2", "bare")
    s1 = w.register_schema(_BATCH, "ros2msg", defs[_BATCH])
    s2 = w.register_schema(_STROKE, "ros2msg", defs[_STROKE])
    w.register_channel("/plant/batch", "cdr", s1)
    w.register_channel("/sensor/stroke", "cdr", s2)
    t0 = time.process_time()
    for c, d, t in msgs:
        w.add_message(c, t, d, t)
    w.finish()
    return time.process_time() - t0


def writer_overhead(n_messages: int = 20000, compression_level: int = 3, repeats: int = 3) -> dict[str, Any]:
    """CPU time per message, ours vs the bare mcap writer (best of ``repeats``).

    Half the messages are 50-sample ``SampleBatch`` (three arrays), half ``Stroke``.

    Returns
    -------
    dict
        ``ours_us``, ``bare_us`` (per message), ``ratio`` and the same without
        compression (``ours_none_us``, ``bare_none_us``, ``ratio_none``).
    """
    from mcap.writer import CompressionType

    msgs = _messages(n_messages, np.random.default_rng(1))

    def ours(path: Path, comp: str) -> float:
        return _write_ours(path, msgs, comp, compression_level)

    def bare(path: Path, comp: CompressionType) -> float:
        return _write_bare(path, msgs, comp)

    with tempfile.TemporaryDirectory() as tmp:
        d = Path(tmp)
        a = min(ours(d / "a.mcap", "zstd") for _ in range(repeats))
        b = min(bare(d / "b.mcap", CompressionType.ZSTD) for _ in range(repeats))
        an = min(ours(d / "c.mcap", "none") for _ in range(repeats))
        bn = min(bare(d / "e.mcap", CompressionType.NONE) for _ in range(repeats))
    n = len(msgs)
    return {"messages": n, "compression_level": compression_level,
            "ours_us": 1e6 * a / n, "bare_us": 1e6 * b / n, "ratio": a / b,
            "ours_none_us": 1e6 * an / n, "bare_none_us": 1e6 * bn / n, "ratio_none": an / bn}


def load_speed(segments: int = 18, segment_s: float = 60.0, rate_hz: float = 10_000.0, batch: int = 50,
               repeats: int = 2) -> dict[str, Any]:
    """Write a batched 10 kHz log and time :func:`load_signals` on two of its fields.

    Returns
    -------
    dict
        ``samples`` (per signal), ``file_mib``, ``write_s``, ``load_wall_s``,
        ``load_cpu_s`` (best of ``repeats``) and ``samples_per_s`` (per signal, CPU time).
    """
    rng = np.random.default_rng(2)
    n_msgs = int(round(segments * segment_s * rate_hz / batch))
    period = 1.0 / rate_hz
    step_ns = s_to_ns(batch * period)
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "campaign.mcap"
        t0 = time.perf_counter()
        with Ros2McapWriter(path, fsync_interval_s=None) as w:
            c = w.add_topic("/plant/batch", _BATCH)
            k = np.arange(batch)
            for i in range(n_msgs):
                v = 4.0 + np.sin(2e-3 * (k + i * batch)) + 0.01 * rng.standard_normal(batch)
                y = 0.4 * v + 0.002 * rng.standard_normal(batch)
                t = i * step_ns
                w.write(c, encode_sample_batch(t, period, v, y, y, 100.0 + y, frame_id="plant"), t, t, i)
        write_s = time.perf_counter() - t0
        best_wall = best_cpu = float("inf")
        n = 0
        for _ in range(repeats):
            w0, c0 = time.perf_counter(), time.process_time()
            sig = load_signals(path, ["/plant/batch.voltage_kv", "/plant/batch.stroke_mm"])
            best_wall = min(best_wall, time.perf_counter() - w0)
            best_cpu = min(best_cpu, time.process_time() - c0)
            n = int(sig["/plant/batch.voltage_kv"].values.size)
            del sig
        size = path.stat().st_size
    return {"samples": n, "file_mib": size / 2**20, "write_s": write_s, "load_wall_s": best_wall,
            "load_cpu_s": best_cpu, "samples_per_s": n / best_cpu}
