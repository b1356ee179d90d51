"""The MCAP file format, read defensively: a streaming record reader that survives damage.

:class:`McapStream` walks a file from its first byte, chunk by chunk, and hands the
messages of each chunk to the caller as one :class:`MessageBlock` (the decompressed
chunk and, per channel, the positions of its messages), so that a reader keeps only one
chunk in memory. Every length read from the file is checked against what remains
before anything is allocated; chunk CRCs, the data-section CRC and the summary CRC are
checked when present. Damage is reported as a :class:`Damage` (byte offset, record,
reason): in strict mode it raises :class:`~hasel.errors.DataFileError`, in tolerant
mode (salvage, ``hasel info``) the stream skips the damaged record, looks for the next
intact chunk and carries on.

:func:`iter_messages` builds on the stream: the raw messages of a file in log-time
order (what ``hasel replay`` publishes), with :func:`read_summary`'s chunk index
bounding how many are held back.

Format: https://mcap.dev/spec (records are opcode u8, length u64, body; little endian).
"""
from __future__ import annotations

import bisect
import heapq
import os
import struct
import zlib
from collections.abc import Iterator, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, BinaryIO

from hasel.errors import DataFileError

__all__ = [
    "MAGIC", "Op", "OP_NAMES", "SchemaRecord", "ChannelRecord", "Damage", "MessageBlock", "McapStream",
    "Summary", "read_summary", "RawMessage", "iter_messages", "MAX_RECORD_BYTES", "MAX_CHUNK_BYTES",
]

MAGIC = b"\x89MCAP0\r\n"
MAX_RECORD_BYTES = 1 << 28  # 256 MiB: no sane record is larger; guards memory against bad lengths
MAX_CHUNK_BYTES = 1 << 30  # decompressed size of one chunk


class Op:
    """Record opcodes of MCAP."""

    HEADER = 0x01
    FOOTER = 0x02
    SCHEMA = 0x03
    CHANNEL = 0x04
    MESSAGE = 0x05
    CHUNK = 0x06
    MESSAGE_INDEX = 0x07
    CHUNK_INDEX = 0x08
    ATTACHMENT = 0x09
    ATTACHMENT_INDEX = 0x0A
    STATISTICS = 0x0B
    METADATA = 0x0C
    METADATA_INDEX = 0x0D
    SUMMARY_OFFSET = 0x0E
    DATA_END = 0x0F


OP_NAMES = {v: k.lower().replace("_", " ") for k, v in vars(Op).items() if k.isupper()}

_OPLEN = struct.Struct("<BQ").unpack_from
_MSGHDR = struct.Struct("<HIQQ").unpack_from
_CHUNKHDR = struct.Struct("<QQQI").unpack_from
_U16 = struct.Struct("<H").unpack_from
_U32 = struct.Struct("<I").unpack_from
_U64 = struct.Struct("<Q").unpack_from
_FOOTER = struct.Struct("<QQI").unpack_from


class _Bad(Exception):
    """A record body does not parse (internal; becomes a Damage)."""


class _Body:
    """Bounded cursor over one record body."""

    __slots__ = ("buf", "pos", "end")

    def __init__(self, buf: Any, start: int, end: int) -> None:
        self.buf, self.pos, self.end = buf, start, end

    def take(self, n: int) -> int:
        p = self.pos
        if n < 0 or p + n > self.end:
            raise _Bad(f"field of {n} bytes runs past the record's end")
        self.pos = p + n
        return p

    def u16(self) -> int:
        return int(_U16(self.buf, self.take(2))[0])

    def u32(self) -> int:
        return int(_U32(self.buf, self.take(4))[0])

    def u64(self) -> int:
        return int(_U64(self.buf, self.take(8))[0])

    def raw(self, n: int) -> bytes:
        p = self.take(n)
        return bytes(self.buf[p:p + n])

    def string(self) -> str:
        try:
            return self.raw(self.u32()).decode("utf-8")
        except UnicodeDecodeError as err:
            raise _Bad("string is not UTF-8") from err

    def string_map(self) -> dict[str, str]:
        n = self.u32()
        sub = _Body(self.buf, self.take(n), self.pos)
        out = {}
        while sub.pos < sub.end:
            k = sub.string()
            out[k] = sub.string()
        return out


@dataclass(frozen=True)
class SchemaRecord:
    """A Schema record: ``id``, ``name`` (``pkg/msg/Type``), ``encoding`` (``ros2msg``), ``data``."""

    id: int
    name: str
    encoding: str
    data: bytes


@dataclass(frozen=True)
class ChannelRecord:
    """A Channel record: ``id``, ``schema_id``, ``topic``, ``message_encoding`` (``cdr``), ``metadata``."""

    id: int
    schema_id: int
    topic: str
    message_encoding: str
    metadata: dict[str, str]


def _parse_schema(buf: Any, start: int, end: int) -> SchemaRecord:
    b = _Body(buf, start, end)
    sid = b.u16()
    name = b.string()
    enc = b.string()
    data = b.raw(b.u32())
    return SchemaRecord(sid, name, enc, data)


def _parse_channel(buf: Any, start: int, end: int) -> ChannelRecord:
    b = _Body(buf, start, end)
    cid = b.u16()
    sid = b.u16()
    topic = b.string()
    enc = b.string()
    meta = b.string_map()
    return ChannelRecord(cid, sid, topic, enc, meta)


@dataclass(frozen=True)
class Damage:
    """Where and how a file is damaged: byte ``offset``, the ``record`` there, the ``reason``."""

    offset: int
    record: str
    reason: str

    def __str__(self) -> str:
        return f"{self.record} at byte {self.offset}: {self.reason}"


@dataclass
class MessageBlock:
    """The messages of one chunk (or one loose message record).

    Attributes
    ----------
    buf : bytes
        The decompressed chunk records.
    messages : dict
        Channel id -> list of ``(log_time_ns, publish_time_ns, sequence, start, end)``:
        the message data is ``buf[start:end]`` (CDR, with its encapsulation header).
    offset : int
        Byte offset of the chunk record in the file.
    count : int
        Number of messages in the block.
    """

    buf: bytes
    messages: dict[int, list[tuple[int, int, int, int, int]]]
    offset: int
    count: int


class McapStream:
    """Walk an MCAP file record by record, one chunk in memory at a time.

    Parameters
    ----------
    path : path-like
        The file.
    tolerant : bool
        False (default): the first damage raises :class:`DataFileError`. True: damage
        is recorded in :attr:`damages`, the damaged record skipped, and the stream
        resynchronises on the next intact chunk.
    validate_crcs : bool
        Check chunk, data-section and summary CRCs (where the writer stored them).

    Attributes
    ----------
    header : tuple of (str, str) or None
        ``(profile, library)`` of the Header record.
    schemas, channels : dict
        Records seen so far, by id (filled while iterating).
    metadata : list of (str, dict)
        Metadata records (e.g. rosbag2's ``"rosbag2"`` record).
    damages : list of Damage
        What was wrong (tolerant mode).
    chunks, chunks_skipped : int
        Chunks read, chunks skipped as damaged.
    data_end, footer : bool
        Whether the DataEnd record and the Footer (plus closing magic) were reached.
    size : int
        File size, bytes.
    """

    def __init__(self, path: str | os.PathLike[str], *, tolerant: bool = False, validate_crcs: bool = True,
                 max_record_bytes: int = MAX_RECORD_BYTES, max_chunk_bytes: int = MAX_CHUNK_BYTES) -> None:
        self.path = Path(path)
        self.tolerant = tolerant
        self.validate_crcs = validate_crcs
        self.max_record_bytes = max_record_bytes
        self.max_chunk_bytes = max_chunk_bytes
        self.header: tuple[str, str] | None = None
        self.schemas: dict[int, SchemaRecord] = {}
        self.channels: dict[int, ChannelRecord] = {}
        self.metadata: list[tuple[str, dict[str, str]]] = []
        self.damages: list[Damage] = []
        self.chunks = 0
        self.chunks_skipped = 0
        self.compressions: set[str] = set()
        self.data_end = False
        self.footer = False
        self.summary_start = 0
        self.size = 0
        self._crc = 0
        self._data_crc_ok = True
        self._resync_pos = 0
        self._f: BinaryIO | None = None

    # -- damage
    def _damage(self, offset: int, op: int | None, reason: str) -> None:
        d = Damage(offset, OP_NAMES.get(op, f"record 0x{op:02x}") if op is not None else "file", reason)
        if not self.tolerant:
            hint = "" if self.footer or op is None else "; `hasel salvage` can recover the intact chunks"
            raise DataFileError(f"{self.path}: damaged MCAP: {d}{hint}")
        self.damages.append(d)

    # -- reading
    def _read(self, n: int) -> bytes:
        assert self._f is not None
        data = self._f.read(n)
        if self.validate_crcs and not self.data_end:
            self._crc = zlib.crc32(data, self._crc)
        return data

    def __iter__(self) -> Iterator[MessageBlock]:
        return self.blocks()

    def blocks(self) -> Iterator[MessageBlock]:
        """Yield the :class:`MessageBlock` of each chunk (and of each loose message), in file order.

        Raises
        ------
        DataFileError
            Strict mode: on the first damage (with its byte offset and record), if the
            file is not MCAP, or if it cannot be opened.
        """
        try:
            f = open(self.path, "rb")  # noqa: SIM115 - closed in finally
        except OSError as err:
            raise DataFileError(f"cannot open {self.path}: {err.strerror or err}") from err
        self._f = f
        try:
            self.size = os.fstat(f.fileno()).st_size
            yield from self._blocks()
        finally:
            f.close()
            self._f = None

    def _blocks(self) -> Iterator[MessageBlock]:
        size = self.size
        magic = self._read(8)
        if magic != MAGIC:
            what = "empty file" if not magic else f"starts with {magic[:8]!r}, not the MCAP magic"
            raise DataFileError(f"{self.path}: not an MCAP file ({what})")
        pos = 8
        first = True
        while True:
            if pos >= size:
                self._damage(pos, None, f"file ends at byte {size} before the DataEnd and Footer records "
                             "(truncated, or the recording was not closed)")
                return
            crc_before = self._crc
            head = self._read(9)
            if len(head) < 9:
                self._damage(pos, None, f"file ends inside a record header ({len(head)} of 9 bytes)")
                return
            op, ln = _OPLEN(head, 0)
            body_pos = pos + 9
            remaining = size - body_pos
            if first and op != Op.HEADER:
                self._damage(pos, op, "the first record is not a Header")
                if not self._resync(pos + 1):
                    return
                pos = self._resync_pos
                first = False
                continue
            first = False
            if ln > remaining or ln > self.max_record_bytes:
                why = (f"claims {ln} bytes but only {remaining} remain (truncated file or corrupt length)"
                       if ln > remaining else f"claims {ln} bytes, more than the {self.max_record_bytes} allowed")
                self._damage(pos, op, why)
                if not self._resync(pos + 1):
                    return
                pos = self._resync_pos
                continue
            if op == Op.CHUNK:
                body = self._read(ln)
                block = self._chunk(body, pos)
                if block is not None:
                    yield block
            elif op == Op.MESSAGE:
                body = self._read(ln)
                if ln < 22:
                    self._damage(pos, op, f"message record of {ln} bytes is shorter than its 22-byte header")
                else:
                    cid, seq, lt, pt = _MSGHDR(body, 0)
                    yield MessageBlock(body, {cid: [(lt, pt, seq, 22, ln)]}, pos, 1)
            elif op in (Op.SCHEMA, Op.CHANNEL, Op.HEADER, Op.METADATA):
                body = self._read(ln)
                try:
                    self._simple(op, body, 0, ln)
                except (_Bad, struct.error) as err:
                    self._damage(pos, op, str(err) or "does not parse")
            elif op == Op.DATA_END:
                crc_at_end = crc_before
                body = self._read(ln)
                self.data_end = True
                if ln >= 4 and self.validate_crcs:
                    stored = _U32(body, 0)[0]
                    if stored and self._data_crc_ok and stored != crc_at_end:
                        self._damage(pos, op, f"data section CRC mismatch (stored 0x{stored:08x}, "
                                     f"computed 0x{crc_at_end:08x})")
                self.summary_start = body_pos + ln
                self._tail(body_pos + ln)
                return
            elif op == Op.FOOTER:
                self._footer(pos, op, ln)
                return
            else:
                self._skip(ln)
            pos = body_pos + ln

    def _skip(self, n: int) -> None:
        assert self._f is not None
        if self.validate_crcs and not self.data_end:
            self._read(n)
        else:
            self._f.seek(n, 1)

    def _simple(self, op: int, buf: Any, start: int, end: int) -> None:
        if op == Op.SCHEMA:
            s = _parse_schema(buf, start, end)
            self.schemas.setdefault(s.id, s)
        elif op == Op.CHANNEL:
            c = _parse_channel(buf, start, end)
            self.channels.setdefault(c.id, c)
        elif op == Op.HEADER:
            b = _Body(buf, start, end)
            profile = b.string()
            self.header = (profile, b.string())
        elif op == Op.METADATA:
            b = _Body(buf, start, end)
            name = b.string()
            self.metadata.append((name, b.string_map()))

    def _chunk(self, body: bytes, pos: int) -> MessageBlock | None:
        ln = len(body)
        try:
            if ln < 40:
                raise _Bad(f"chunk body of {ln} bytes is too short")
            start_t, end_t, usize, crc = _CHUNKHDR(body, 0)
            b = _Body(body, 28, ln)
            compression = b.string()
            rlen = b.u64()
            if rlen != ln - b.pos:
                raise _Bad(f"records length {rlen} does not match the chunk length ({ln - b.pos})")
            if usize > self.max_chunk_bytes:
                raise _Bad(f"uncompressed size {usize} exceeds the {self.max_chunk_bytes} allowed")
            data = _decompress(compression, body[b.pos:], usize)
            if len(data) != usize:
                raise _Bad(f"decompressed to {len(data)} bytes, expected {usize}")
            if crc and self.validate_crcs and zlib.crc32(data) != crc:
                raise _Bad("CRC mismatch of the uncompressed records")
            self.compressions.add(compression or "none")
            block = self._records(data, pos)
        except (_Bad, struct.error) as err:
            self.chunks_skipped += 1
            self._damage(pos, Op.CHUNK, str(err) or "does not parse")
            return None
        self.chunks += 1
        return block

    def _records(self, buf: bytes, pos: int) -> MessageBlock:
        groups: dict[int, list[tuple[int, int, int, int, int]]] = {}
        n = len(buf)
        p = 0
        count = 0
        msghdr = _MSGHDR
        oplen = _OPLEN
        while p < n:
            if n - p < 9:
                raise _Bad(f"record header cut at offset {p} of the chunk")
            op, ln = oplen(buf, p)
            body = p + 9
            end = body + ln
            if end > n:
                raise _Bad(f"record at offset {p} of the chunk claims {ln} bytes, past the chunk's end")
            if op == 5:
                if ln < 22:
                    raise _Bad(f"message at offset {p} of the chunk is shorter than its header")
                cid, seq, lt, pt = msghdr(buf, body)
                g = groups.get(cid)
                if g is None:
                    g = groups[cid] = []
                g.append((lt, pt, seq, body + 22, end))
                count += 1
            elif op == 3 or op == 4:
                self._simple(op, buf, body, end)
            p = end
        return MessageBlock(buf, groups, pos, count)

    def _tail(self, pos: int) -> None:
        """After DataEnd: walk the summary section to the Footer and the closing magic."""
        size = self.size
        while True:
            if pos + 9 > size:
                self._damage(pos, None, "file ends in the summary section, before the Footer (truncated)")
                return
            head = self._read(9)
            op, ln = _OPLEN(head, 0)
            if op == Op.FOOTER:
                self._footer(pos, op, ln)
                return
            if ln > size - pos - 9:
                self._damage(pos, op, f"summary record claims {ln} bytes but only {size - pos - 9} remain (truncated)")
                return
            assert self._f is not None
            self._f.seek(ln, 1)
            pos += 9 + ln

    def _footer(self, pos: int, op: int, ln: int) -> None:
        if ln != 20 or pos + 9 + 20 + 8 != self.size:
            if pos + 9 + 20 + 8 > self.size:
                self._damage(pos, op, "file ends inside the Footer or before the closing magic (truncated)")
            else:
                self._damage(pos, op, f"footer of {ln} bytes, or {self.size - pos - 37} stray bytes after it")
            return
        body = self._read(20)
        magic = self._read(8)
        if magic != MAGIC:
            self._damage(pos + 29, None, "closing magic is missing or corrupt")
            return
        summary_start, _, summary_crc = _FOOTER(body, 0)
        if self.validate_crcs and summary_crc and 0 < summary_start <= pos \
                and pos - summary_start <= self.max_record_bytes:
            assert self._f is not None
            self._f.seek(summary_start)
            section = self._f.read(pos - summary_start)
            crc = zlib.crc32(section)
            crc = zlib.crc32(head_bytes(op, ln) + body[:16], crc)
            if crc != summary_crc:
                self._damage(summary_start, None, "summary section CRC mismatch")
                return
        self.footer = True

    # -- resynchronisation (tolerant mode)
    def _resync(self, start: int) -> bool:
        """Find the next plausible chunk record at or after ``start`` and seek there."""
        assert self._f is not None
        f = self._f
        size = self.size
        window = 1 << 20
        pos = start
        self._data_crc_ok = False  # bytes are skipped: the data-section CRC cannot match any more
        while pos < size - 9:
            f.seek(pos)
            buf = f.read(min(window + 64, size - pos))
            i = buf.find(b"\x06")
            while i != -1 and i < window:
                if _plausible_chunk(buf, i, size - (pos + i)):
                    self._resync_pos = pos + i
                    f.seek(self._resync_pos)
                    return True
                i = buf.find(b"\x06", i + 1)
            pos += window
        return False

def head_bytes(op: int, ln: int) -> bytes:
    """Opcode and length prefix of a record."""
    return struct.pack("<BQ", op, ln)


def _plausible_chunk(buf: bytes, i: int, remaining: int) -> bool:
    if i + 9 + 32 > len(buf):
        return False
    op, ln = _OPLEN(buf, i)
    if op != Op.CHUNK or ln < 40 or ln > remaining - 9 or ln > MAX_RECORD_BYTES:
        return False
    clen = _U32(buf, i + 9 + 28)[0]
    if clen > 8 or i + 9 + 32 + clen + 8 > len(buf):
        return False
    comp = buf[i + 9 + 32:i + 9 + 32 + clen]
    if comp not in (b"", b"zstd", b"lz4"):
        return False
    rlen = _U64(buf, i + 9 + 32 + clen)[0]
    return bool(ln == 40 + clen + rlen)


def _decompress(compression: str, data: bytes, usize: int) -> bytes:
    if compression == "":
        return data
    if compression == "zstd":
        import zstandard

        try:
            return bytes(zstandard.ZstdDecompressor().decompress(data, max_output_size=usize))
        except zstandard.ZstdError as err:
            raise _Bad(f"zstd decompression failed: {err}") from err
    if compression == "lz4":
        try:
            import lz4.frame
        except ImportError as err:
            raise _Bad("lz4-compressed chunk, but the lz4 package is not installed") from err
        try:
            out = lz4.frame.decompress(data)
        except RuntimeError as err:
            raise _Bad(f"lz4 decompression failed: {err}") from err
        return bytes(out)
    raise _Bad(f"unknown compression {compression!r}")


# --------------------------------------------------------------------------- summary


@dataclass
class Summary:
    """What the summary section of an intact file says (no message data read)."""

    header: tuple[str, str]
    schemas: dict[int, SchemaRecord]
    channels: dict[int, ChannelRecord]
    message_count: int = 0
    channel_message_counts: dict[int, int] = field(default_factory=dict)
    message_start_time: int = 0
    message_end_time: int = 0
    chunk_count: int = 0
    has_statistics: bool = False
    chunk_times: list[tuple[int, int, int]] = field(default_factory=list)
    """``(chunk record's byte offset, first, last message log time in ns)`` per Chunk Index record."""


def read_summary(path: str | os.PathLike[str]) -> Summary | None:
    """The summary of an intact MCAP file via its Footer, or None if it has none or it is damaged.

    Cheap: reads the header, the footer and the summary section only.
    """
    try:
        with open(path, "rb") as f:
            size = os.fstat(f.fileno()).st_size
            if size < 8 + 9 + 29 + 8:
                return None
            if f.read(8) != MAGIC:
                return None
            op, ln = _OPLEN(f.read(9), 0)
            if op != Op.HEADER or ln > min(size, 1 << 20):
                return None
            hb = _Body(f.read(ln), 0, ln)
            header = (hb.string(), hb.string())
            f.seek(size - 8 - 29)
            tail = f.read(37)
            if tail[-8:] != MAGIC:
                return None
            op, ln = _OPLEN(tail, 0)
            if op != Op.FOOTER or ln != 20:
                return None
            summary_start, _, summary_crc = _FOOTER(tail, 9)
            end = size - 37
            if not summary_start or summary_start > end or end - summary_start > MAX_RECORD_BYTES:
                return None
            f.seek(summary_start)
            buf = f.read(end - summary_start)
            if summary_crc and zlib.crc32(tail[:25], zlib.crc32(buf)) != summary_crc:
                return None
    except (OSError, _Bad, struct.error):
        return None
    out = Summary(header, {}, {})
    p = 0
    try:
        while p < len(buf):
            op, ln = _OPLEN(buf, p)
            body, rend = p + 9, p + 9 + ln
            if rend > len(buf):
                return None
            if op == Op.SCHEMA:
                s = _parse_schema(buf, body, rend)
                out.schemas[s.id] = s
            elif op == Op.CHANNEL:
                c = _parse_channel(buf, body, rend)
                out.channels[c.id] = c
            elif op == Op.STATISTICS:
                b = _Body(buf, body, rend)
                out.message_count = b.u64()
                b.u16()  # schema count
                b.u32()  # channel count
                b.u32()  # attachment count
                b.u32()  # metadata count
                out.chunk_count = b.u32()
                out.message_start_time = b.u64()
                out.message_end_time = b.u64()
                n = b.u32()
                sub = _Body(buf, b.take(n), b.pos)
                while sub.pos < sub.end:
                    cid = sub.u16()
                    out.channel_message_counts[cid] = sub.u64()
                out.has_statistics = True
            elif op == Op.CHUNK_INDEX:
                b = _Body(buf, body, rend)
                first, last, offset = b.u64(), b.u64(), b.u64()
                out.chunk_times.append((offset, first, last))
            p = rend
    except (_Bad, struct.error):
        return None
    return out


# --------------------------------------------------------------------------- messages


@dataclass(frozen=True)
class RawMessage:
    """One recorded message: ``topic``, ``type_name`` (``pkg/msg/Type``), CDR ``data``, log and publish time (ns)."""

    topic: str
    type_name: str
    data: bytes
    log_time_ns: int
    publish_time_ns: int


def _type_name(schema: SchemaRecord | None) -> str:
    name = schema.name if schema is not None else ""
    return name.replace("/", "/msg/") if name.count("/") == 1 else name  # older rosbag2 naming pkg/Type


def iter_messages(path: str | os.PathLike[str], topics: Sequence[str] | None = None) -> Iterator[RawMessage]:
    """The messages of an MCAP file in log-time order (ties in file order), streamed.

    The file is read once, chunk by chunk, in strict mode (damage raises). A message
    is held back only while a chunk further on may still hold an earlier one: the
    chunk index of the summary says when each chunk starts, so for files written in
    time order (rosbag2, :class:`~hasel.io.writer.Ros2McapWriter`) at most one chunk
    is held. Without a chunk index (no summary) every message is held and sorted at
    the end.

    Parameters
    ----------
    path : path-like
        The MCAP file.
    topics : sequence of str, optional
        Only these topics (default: all).

    Raises
    ------
    DataFileError
        A missing, damaged or non-MCAP file (the message says where and suggests
        ``hasel salvage``).
    """
    wanted = set(topics) if topics else None
    summ = read_summary(path)
    index = sorted(summ.chunk_times) if summ is not None else []
    offsets = [o for o, _, _ in index]
    # earliest start of the chunks from i on: nothing later in the file is older than this
    later_start = [0] * (len(index) + 1)
    later_start[-1] = 2**64
    for i in range(len(index) - 1, -1, -1):
        later_start[i] = min(index[i][1], later_start[i + 1])
    stream = McapStream(path)
    heap: list[tuple[int, int, int, RawMessage]] = []  # (log time, block offset, position): ties in file order
    for block in stream:
        for cid, items in block.messages.items():
            ch = stream.channels.get(cid)
            if ch is None:
                raise DataFileError(f"{path}: message of unknown channel {cid} in the record at byte {block.offset}")
            if wanted is not None and ch.topic not in wanted:
                continue
            name = _type_name(stream.schemas.get(ch.schema_id))
            buf = block.buf
            for lt, pt, _seq, start, end in items:
                heapq.heappush(heap, (lt, block.offset, start, RawMessage(ch.topic, name, bytes(buf[start:end]), lt, pt)))
        bound = later_start[bisect.bisect_right(offsets, block.offset)] if index else -1
        while heap and heap[0][0] < bound:
            yield heapq.heappop(heap)[3]
    while heap:
        yield heapq.heappop(heap)[3]
