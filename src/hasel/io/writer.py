"""Write ROS 2 MCAP logs the way rosbag2's MCAP storage plugin does, without ROS.

Layout (as rosbag2 Jazzy / libmcap): profile ``ros2``; one Schema per message type
(encoding ``ros2msg``, the complete definition text of :func:`message_definition`); one
Channel per topic (message encoding ``cdr``, metadata ``offered_qos_profiles`` in
rosbag2 Jazzy's YAML and ``topic_type_hash``); messages in zstd-compressed chunks of
768 KiB with a message index after each chunk; at close a summary (schemas, channels,
statistics, chunk indexes, summary offsets) and the footer.

Crash safety: Schema and Channel records go to the file as soon as a topic is added,
and every chunk is written and flushed to the operating system the moment it is
closed (size reached, or ``max_chunk_span_s`` of log time), so a process killed with
SIGKILL loses at most the chunk being filled; a background thread fsyncs the file at
most every ``fsync_interval_s`` so that a power cut loses little more. A file that was
not closed has no summary or footer; :func:`hasel.io.salvage.salvage` rewrites it.

The writer takes messages already serialised (CDR bytes, as rclpy hands them to a
recorder): no decode/encode round trip.
"""
from __future__ import annotations

import os
import struct
import threading
import time
import zlib
from array import array
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from types import TracebackType
from typing import Any

from mcap.data_stream import RecordBuilder
from mcap.records import (
    Channel, ChunkIndex, DataEnd, Header, Metadata, MetadataIndex, Schema, Statistics, SummaryOffset,
)

from hasel import __version__ as _hasel_version
from hasel.errors import BadInputError
from hasel.io.mcapfile import MAGIC, Op
from hasel.io.msgdefs import full_name, message_definition, type_hash
from hasel.timeconv import ns_to_stamp, s_to_ns

__all__ = ["Ros2McapWriter", "QosProfile", "offered_qos_yaml", "DEFAULT_CHUNK_SIZE", "LIBRARY", "INFINITE_NS"]

DEFAULT_CHUNK_SIZE = 768 * 1024  # libmcap's default, what rosbag2 uses
LIBRARY = f"hasel-io/{_hasel_version}"
INFINITE_NS = 2**63 - 1  # RMW_DURATION_INFINITE: {sec: 9223372036, nsec: 854775807}

_MSG_HEAD = struct.Struct("<BQHIQQ").pack
_HEAD = struct.Struct("<BQ").pack
_CHUNK_HEAD = struct.Struct("<QQQI").pack
_U32 = struct.Struct("<I").pack
_U64 = struct.Struct("<Q").pack
_MI_HEAD = struct.Struct("<BQHI").pack
_OPLEN = struct.Struct("<BQ").unpack_from
_CID = struct.Struct("<H").unpack_from
_LT = struct.Struct("<Q").unpack_from

# rmw enum values -> the names rosbag2 Jazzy writes (rmw_qos_*_policy_to_str; UNKNOWN -> "unknown")
_HISTORY = {0: "system_default", 1: "keep_last", 2: "keep_all", 3: "unknown"}
_RELIABILITY = {0: "system_default", 1: "reliable", 2: "best_effort", 3: "unknown", 4: "best_available"}
_DURABILITY = {0: "system_default", 1: "transient_local", 2: "volatile", 3: "unknown", 4: "best_available"}
_LIVELINESS = {0: "system_default", 1: "automatic", 3: "manual_by_topic", 4: "unknown", 5: "best_available"}


def _policy(name: str, value: str | int, table: Mapping[int, str]) -> str:
    if isinstance(value, bool):
        raise BadInputError(f"QoS {name} must be a policy name or rmw enum value, got {value!r}")
    if isinstance(value, int) or (hasattr(value, "value") and isinstance(getattr(value, "value"), int)):
        v = int(getattr(value, "value", value))
        if v not in table:
            raise BadInputError(f"QoS {name}: unknown rmw value {v}; known: {dict(table)}")
        return table[v]
    text = str(value).lower()
    if text not in table.values():
        raise BadInputError(f"QoS {name}: unknown policy {value!r}; known: {', '.join(table.values())}")
    return text


def _duration(name: str, value: int | tuple[int, int] | None) -> tuple[int, int]:
    if value is None:
        return 0, 0
    if isinstance(value, tuple):
        sec, nsec = value
        return int(sec), int(nsec)
    ns = int(getattr(value, "nanoseconds", value))
    if ns < 0:
        raise BadInputError(f"QoS {name} must be >= 0 ns, got {ns}")
    return ns_to_stamp(ns)


@dataclass(frozen=True)
class QosProfile:
    """A QoS profile as rosbag2 records it (``offered_qos_profiles``).

    Policies are names (``"reliable"``) or rmw enum values (``1``); durations are
    integer nanoseconds (``INFINITE_NS`` for infinite, 0 for unspecified) or
    ``(sec, nsec)``. The defaults are rclpy's default publisher profile (depth 10).
    """

    history: str | int = "keep_last"
    depth: int = 10
    reliability: str | int = "reliable"
    durability: str | int = "volatile"
    deadline: int | tuple[int, int] | None = 0
    lifespan: int | tuple[int, int] | None = 0
    liveliness: str | int = "system_default"
    liveliness_lease_duration: int | tuple[int, int] | None = 0
    avoid_ros_namespace_conventions: bool = False

    def to_yaml(self) -> str:
        """This profile as one item of rosbag2 Jazzy's YAML sequence (no trailing newline)."""
        lines = [
            f"- history: {_policy('history', self.history, _HISTORY)}",
            f"  depth: {int(self.depth)}",
            f"  reliability: {_policy('reliability', self.reliability, _RELIABILITY)}",
            f"  durability: {_policy('durability', self.durability, _DURABILITY)}",
        ]
        for key, value in (("deadline", self.deadline), ("lifespan", self.lifespan)):
            sec, nsec = _duration(key, value)
            lines += [f"  {key}:", f"    sec: {sec}", f"    nsec: {nsec}"]
        lines.append(f"  liveliness: {_policy('liveliness', self.liveliness, _LIVELINESS)}")
        sec, nsec = _duration("liveliness_lease_duration", self.liveliness_lease_duration)
        lines += ["  liveliness_lease_duration:", f"    sec: {sec}", f"    nsec: {nsec}"]
        lines.append(f"  avoid_ros_namespace_conventions: {'true' if self.avoid_ros_namespace_conventions else 'false'}")
        return "\n".join(lines)


def offered_qos_yaml(profiles: QosProfile | Mapping[str, Any] | Sequence[QosProfile | Mapping[str, Any]]) -> str:
    """The ``offered_qos_profiles`` YAML of rosbag2 Jazzy for one or more profiles.

    Parameters
    ----------
    profiles : QosProfile, mapping or sequence of them
        Mappings take the :class:`QosProfile` field names.

    Returns
    -------
    str
        A YAML sequence, one item per profile, as yaml-cpp dumps it (``[]`` if empty).
    """
    if isinstance(profiles, (QosProfile, Mapping)):
        profiles = [profiles]
    items = []
    for p in profiles:
        if isinstance(p, Mapping):
            try:
                p = QosProfile(**p)
            except TypeError as err:
                raise BadInputError(f"bad QoS profile {dict(p)!r}: {err}") from err
        items.append(p.to_yaml())
    return "\n".join(items) if items else "[]"


def _record(rec: Any) -> bytes:
    rb = RecordBuilder()
    rec.write(rb)
    return bytes(rb.end())


class _Syncer(threading.Thread):
    """fsyncs a file descriptor when asked, off the writing thread."""

    def __init__(self, fd: int) -> None:
        super().__init__(name="mcap-fsync", daemon=True)
        self.fd = fd
        self.wake = threading.Event()
        self.stopping = False

    def run(self) -> None:
        while True:
            self.wake.wait()
            self.wake.clear()
            if self.stopping:
                return
            try:
                os.fsync(self.fd)
            except OSError:
                return

    def stop(self) -> None:
        self.stopping = True
        self.wake.set()
        self.join()


@dataclass
class _ChunkInfo:
    start: int
    end: int
    offset: int
    length: int
    mi_offsets: dict[int, int]
    mi_length: int
    compression: str
    compressed_size: int
    uncompressed_size: int


class Ros2McapWriter:
    """A ROS 2 MCAP log writer (rosbag2's MCAP layout), a context manager.

    Parameters
    ----------
    path : path-like
        The ``.mcap`` file (created or truncated).
    chunk_size : int
        Close a chunk once its uncompressed records reach this many bytes (768 KiB).
    compression : {"zstd", "lz4", "none"}
        Chunk compression.
    compression_level : int
        zstd level (1: libmcap's "Default", what rosbag2 uses).
    max_chunk_span_s : float or None
        Also close a chunk once its messages span this much log time, s, bounding what a
        crash loses (None: size only).
    fsync_interval_s : float or None
        fsync after a chunk at most this often, s, in a background thread (0: inline
        after every chunk; None: only at close).
    search_prefixes : sequence of path, optional
        Where :func:`message_definition` looks for ``.msg`` files.
    library : str
        The Header's library string.

    Notes
    -----
    Not thread-safe: call from one thread (or hold a lock). ``close()`` is idempotent;
    call it from the shutdown path after SIGINT/SIGTERM (not inside the signal handler: a
    handler can interrupt write() between records) to write the summary.
    """

    def __init__(self, path: str | os.PathLike[str], *, chunk_size: int = DEFAULT_CHUNK_SIZE,
                 compression: str = "zstd", compression_level: int = 1, max_chunk_span_s: float | None = 1.0,
                 fsync_interval_s: float | None = 1.0,
                 search_prefixes: Sequence[str | os.PathLike[str]] | None = None, library: str = LIBRARY) -> None:
        if int(chunk_size) < 1:
            raise BadInputError(f"chunk_size must be >= 1 byte, got {chunk_size}")
        comp = "" if compression in ("none", "", None) else str(compression)
        if comp == "zstd":
            import zstandard

            self._compress = zstandard.ZstdCompressor(level=int(compression_level)).compress
        elif comp == "lz4":
            try:
                import lz4.frame
            except ImportError as err:
                raise BadInputError("lz4 compression needs the lz4 package") from err
            self._compress = lz4.frame.compress
        elif comp == "":
            self._compress = bytes
        else:
            raise BadInputError(f"compression must be zstd, lz4 or none, got {compression!r}")
        self.path = Path(path)
        self.compression = comp
        self._chunk_size = int(chunk_size)
        self._span_ns = 2**66 if max_chunk_span_s is None else max(1, s_to_ns(max_chunk_span_s))
        self._fsync_interval = fsync_interval_s
        self._prefixes = search_prefixes
        try:
            self._f = open(self.path, "wb", buffering=1 << 20)  # noqa: SIM115 - closed in close()
        except OSError as err:
            raise BadInputError(f"cannot write {self.path}: {err.strerror or err}") from err
        self._pos = 0
        self._crc = 0
        self._chunk = bytearray()
        self._index: dict[int, array[int]] = {}
        self._deadline = 0
        self._schemas: dict[int, Schema] = {}
        self._schema_by_name: dict[tuple[str, str, bytes], int] = {}
        self._channels: dict[int, Channel] = {}
        self._topics: dict[str, tuple[int, str]] = {}
        self._counts: dict[int, int] = {}
        self._chunks: list[_ChunkInfo] = []
        self._metadata_index: list[MetadataIndex] = []
        self._t_min: int | None = None
        self._t_max = 0
        self._closed = False
        self._last_sync = time.monotonic()
        self._syncer: _Syncer | None = None
        if fsync_interval_s is not None and fsync_interval_s > 0:
            self._syncer = _Syncer(self._f.fileno())
            self._syncer.start()
        self._emit(MAGIC)
        self._emit(_record(Header(profile="ros2", library=library)))
        self._f.flush()

    # ------------------------------------------------------------------ set-up

    def add_schema(self, name: str, encoding: str, data: bytes) -> int:
        """Write a Schema record (once per distinct schema); returns its id (1, 2, ...)."""
        key = (name, encoding, bytes(data))
        sid = self._schema_by_name.get(key)
        if sid is not None:
            return sid
        self._check_open()
        sid = len(self._schemas) + 1
        schema = Schema(id=sid, name=name, encoding=encoding, data=bytes(data))
        self._schemas[sid] = schema
        self._schema_by_name[key] = sid
        self._emit(_record(schema))
        self._f.flush()
        return sid

    def add_channel(self, topic: str, schema_id: int, *, message_encoding: str = "cdr",
                    metadata: Mapping[str, str] | None = None) -> int:
        """Write a Channel record; returns its id (1, 2, ...)."""
        self._check_open()
        if schema_id and schema_id not in self._schemas:
            raise BadInputError(f"unknown schema id {schema_id}")
        cid = len(self._channels) + 1
        if cid > 0xFFFF:
            raise BadInputError("too many channels (MCAP allows 65535)")
        channel = Channel(id=cid, topic=topic, message_encoding=message_encoding, schema_id=schema_id,
                          metadata=dict(metadata or {}))
        self._channels[cid] = channel
        self._counts[cid] = 0
        self._emit(_record(channel))
        self._f.flush()
        return cid

    def add_topic(self, topic: str, type_name: str, definition: str | None = None,
                  qos: QosProfile | Mapping[str, Any] | Sequence[QosProfile | Mapping[str, Any]] | str | None = None,
                  *, topic_type_hash: str | None = None) -> int:
        """Register a topic; returns the channel id to :meth:`write` with.

        Parameters
        ----------
        topic : str
            Topic name, e.g. ``"/plant/batch"``.
        type_name : str
            ``pkg/msg/Type``.
        definition : str, optional
            Complete ``ros2msg`` schema text; default :func:`message_definition`.
        qos : QosProfile, mapping, sequence of them, or str, optional
            The publishers' offered QoS (a str is stored as the YAML as is); default one
            :class:`QosProfile` with rclpy's defaults.
        topic_type_hash : str, optional
            ``RIHS01_...``; default read from the installed ``.json`` (``""`` if none).

        Raises
        ------
        BadInputError
            If the topic was added with another type, or the definition is not found.
        """
        old = self._topics.get(topic)
        if old is not None:
            if old[1] != full_name(type_name):
                raise BadInputError(f"topic {topic} already added with type {old[1]}, not {type_name}")
            return old[0]
        name = full_name(type_name)
        text = message_definition(name, self._prefixes) if definition is None else definition
        sid = self.add_schema(name, "ros2msg", text.encode("utf-8"))
        qos_text = qos if isinstance(qos, str) else offered_qos_yaml(QosProfile() if qos is None else qos)
        thash = type_hash(name, self._prefixes) if topic_type_hash is None else topic_type_hash
        cid = self.add_channel(topic, sid, message_encoding="cdr",
                               metadata={"offered_qos_profiles": qos_text, "topic_type_hash": thash})
        self._topics[topic] = (cid, name)
        return cid

    def add_metadata(self, name: str, data: Mapping[str, str]) -> None:
        """Write a Metadata record (key-value strings), indexed in the summary."""
        self._check_open()
        rec = _record(Metadata(name=name, metadata={str(k): str(v) for k, v in data.items()}))
        self._metadata_index.append(MetadataIndex(offset=self._pos, length=len(rec), name=name))
        self._emit(rec)
        self._f.flush()

    # ------------------------------------------------------------------ hot path

    def write(self, channel_id: int, data: bytes, log_time_ns: int, publish_time_ns: int, sequence: int = 0) -> None:
        """Append one serialised message to the current chunk.

        Parameters
        ----------
        channel_id : int
            From :meth:`add_topic` / :meth:`add_channel`.
        data : bytes-like
            The CDR bytes (with their encapsulation header).
        log_time_ns, publish_time_ns : int
            Receive and publish times, integer nanoseconds (uint64).
        sequence : int
            Publisher sequence number (uint32), 0 if unknown.
        """
        idx = self._index.get(channel_id)
        if idx is None:
            idx = self._new_index(channel_id)
        buf = self._chunk
        off = len(buf)
        if not off:
            self._deadline = log_time_ns + self._span_ns
        try:  # one += per record
            buf += _MSG_HEAD(5, 22 + len(data), channel_id, sequence, log_time_ns, publish_time_ns) + data
        except struct.error as err:
            raise BadInputError(f"bad message fields (times must be uint64 ns, sequence uint32): {err}") from err
        idx.append(log_time_ns)
        idx.append(off)
        if len(buf) >= self._chunk_size or log_time_ns >= self._deadline:
            self._close_chunk()

    def _new_index(self, channel_id: int) -> array[int]:
        self._check_open()
        if channel_id not in self._channels:
            raise BadInputError(f"unknown channel id {channel_id}: call add_topic() first")
        idx = self._index[channel_id] = array("Q")
        return idx

    # ------------------------------------------------------------------ chunks

    def _emit(self, data: bytes) -> None:
        self._f.write(data)
        self._crc = zlib.crc32(data, self._crc)
        self._pos += len(data)

    def _close_chunk(self) -> None:
        if not self._chunk:
            self._index = {}
            return
        data = bytes(self._chunk)
        comp = self._compress(data)
        t_lo: int | None = None
        t_hi = 0
        indexes = []
        for cid, idx in self._index.items():
            if len(idx) % 2:  # interrupted between the two appends of write()
                idx.pop()
            times = idx[0::2]
            if not times:
                continue
            lo, hi = min(times), max(times)
            t_lo = lo if t_lo is None else min(t_lo, lo)
            t_hi = max(t_hi, hi)
            self._counts[cid] += len(times)
            indexes.append((cid, idx))
        if t_lo is None:
            t_lo = 0
        comp_name = self.compression.encode()
        body_len = 28 + 4 + len(comp_name) + 8 + len(comp)
        chunk_offset = self._pos
        head = (_HEAD(Op.CHUNK, body_len) + _CHUNK_HEAD(t_lo, t_hi, len(data), zlib.crc32(data))
                + _U32(len(comp_name)) + comp_name + _U64(len(comp)))
        self._emit(head)
        self._emit(comp)
        chunk_length = self._pos - chunk_offset
        mi_offsets = {}
        mi_start = self._pos
        parts = []
        for cid, idx in indexes:
            raw = idx.tobytes()
            mi_offsets[cid] = mi_start + sum(len(x) for x in parts)
            parts.append(_MI_HEAD(Op.MESSAGE_INDEX, 6 + len(raw), cid, len(raw)) + raw)
        mi = b"".join(parts)
        self._emit(mi)
        self._f.flush()  # the chunk now survives the death of this process
        self._chunks.append(_ChunkInfo(t_lo, t_hi, chunk_offset, chunk_length, mi_offsets, len(mi),
                                       self.compression, len(comp), len(data)))
        self._t_min = t_lo if self._t_min is None else min(self._t_min, t_lo)
        self._t_max = max(self._t_max, t_hi)
        self._chunk = bytearray()
        self._index = {}
        self._sync()

    def _reindex(self) -> None:
        """Rebuild the message index of the open chunk from its records."""
        index: dict[int, array[int]] = {}
        buf = self._chunk
        pos, n = 0, len(buf)
        while pos + 31 <= n:
            op, ln = _OPLEN(buf, pos)
            if op == Op.MESSAGE:
                cid, lt = _CID(buf, pos + 9)[0], _LT(buf, pos + 15)[0]
                index.setdefault(cid, array("Q")).extend((lt, pos))
            pos += 9 + ln
        self._index = index

    def _sync(self) -> None:
        if self._fsync_interval is None:
            return
        now = time.monotonic()
        if self._fsync_interval <= 0:
            os.fsync(self._f.fileno())
        elif self._syncer is not None and now - self._last_sync >= self._fsync_interval:
            self._last_sync = now
            self._syncer.wake.set()

    def flush(self) -> None:
        """Close the current chunk (if any) and push it to the operating system."""
        self._check_open()
        self._close_chunk()
        self._f.flush()

    # ------------------------------------------------------------------ close

    @property
    def closed(self) -> bool:
        """True once :meth:`close` ran."""
        return self._closed

    @property
    def message_count(self) -> int:
        """Messages in closed chunks plus the current one."""
        return sum(self._counts.values()) + sum(len(i) // 2 for i in self._index.values())

    @property
    def chunk_count(self) -> int:
        """Chunks written so far."""
        return len(self._chunks)

    def _check_open(self) -> None:
        if self._closed:
            raise BadInputError(f"{self.path}: the writer is closed")

    def close(self) -> None:
        """Write the last chunk, the summary and the footer; fsync; close. Idempotent."""
        if self._closed:
            return
        try:
            self._reindex()  # rebuild the indexes from the records themselves
            self._close_chunk()
            self._emit(_record(DataEnd(data_section_crc=self._crc)))
            summary_start = self._pos
            groups: list[tuple[int, bytes]] = [
                (Op.SCHEMA, b"".join(_record(s) for s in self._schemas.values())),
                (Op.CHANNEL, b"".join(_record(c) for c in self._channels.values())),
                (Op.STATISTICS, _record(Statistics(
                    message_count=sum(self._counts.values()), schema_count=len(self._schemas),
                    channel_count=len(self._channels), attachment_count=0,
                    metadata_count=len(self._metadata_index), chunk_count=len(self._chunks),
                    message_start_time=self._t_min or 0, message_end_time=self._t_max,
                    channel_message_counts={c: n for c, n in self._counts.items() if n}))),
                (Op.CHUNK_INDEX, b"".join(_record(ChunkIndex(
                    message_start_time=c.start, message_end_time=c.end, chunk_start_offset=c.offset,
                    chunk_length=c.length, message_index_offsets=c.mi_offsets, message_index_length=c.mi_length,
                    compression=c.compression, compressed_size=c.compressed_size,
                    uncompressed_size=c.uncompressed_size)) for c in self._chunks)),
                (Op.METADATA_INDEX, b"".join(_record(m) for m in self._metadata_index)),
            ]
            summary = bytearray()
            offsets = bytearray()
            for opcode, blob in groups:
                if blob:
                    offsets += _record(SummaryOffset(group_opcode=opcode, group_start=summary_start + len(summary),
                                                     group_length=len(blob)))
                    summary += blob
            offset_start = summary_start + len(summary)
            summary += offsets
            footer_fields = _U64(summary_start) + _U64(offset_start)
            crc = zlib.crc32(bytes(summary) + _HEAD(Op.FOOTER, 20) + footer_fields)
            self._f.write(summary)
            self._f.write(_HEAD(Op.FOOTER, 20) + footer_fields + _U32(crc) + MAGIC)
            self._f.flush()
            if self._fsync_interval is not None:
                os.fsync(self._f.fileno())
        finally:
            self._closed = True
            self._index = {}
            if self._syncer is not None:
                self._syncer.stop()
            self._f.close()

    def __enter__(self) -> Ros2McapWriter:
        return self

    def __exit__(self, exc_type: type[BaseException] | None, exc: BaseException | None,
                 tb: TracebackType | None) -> None:
        self.close()
