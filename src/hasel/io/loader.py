"""Signals out of ROS 2 MCAP logs: any numeric field of any topic, batched samples unrolled.

A field is named ``"/topic.field"`` with dots into nested messages
(``"/amp/applied.applied_kv"``, ``"/plant/batch.voltage_kv"``, ``"/x.data[2]"``). Times
come from ``header.stamp`` when the message has a ``std_msgs/Header`` named ``header``,
else from the log time. A message with a top-level ``sample_period_s`` carries batched
samples: each of its primitive array fields is unrolled, sample ``i`` at
``stamp + i * sample_period_s``.

The file is streamed chunk by chunk (:class:`~hasel.io.mcapfile.McapStream`); only the
requested fields are kept, in compact arrays, so memory is bounded by the result plus
one chunk. Each message type gets a generated CDR walker (:mod:`hasel.io.cdr`) that reads
the float arrays of a batch straight from the chunk bytes.
"""
from __future__ import annotations

import os
from array import array
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any, NamedTuple

import numpy as np

from hasel.errors import BadInputError, DataFileError
from hasel.io.cdr import CdrError, Extractor, FieldRequest, numeric_fields
from hasel.io.mcapfile import ChannelRecord, McapStream, SchemaRecord, read_summary
from hasel.io.msgdefs import PRIMITIVE_FORMATS, MessageDefinitionError, MsgSpec, parse_schema, resolve_type, short_name
from hasel.timeconv import NS_PER_S, ns_to_s_array, stamp_to_ns

__all__ = [
    "Signal", "TopicInfo", "Marker", "Segment", "MarkerSegment", "list_topics", "split_field_spec",
    "load_signals", "load_markers", "load_signals_and_markers", "marker_segments", "fields_of", "MARKER_TYPE",
]

MARKER_TYPE = "hasel_msgs/ExperimentMarker"
_MARKER_FIELDS = ("label", "signal", "offset_kv", "amplitude_kv", "f0_hz", "f1_hz", "duration_s", "start")
ProgressFn = Callable[[float], None]


@dataclass(frozen=True)
class Signal:
    """A sampled signal.

    Attributes
    ----------
    t_s : ndarray, shape (n,)
        Sample times, float seconds (ROS time of ``header.stamp``, or log time).
    values : ndarray, shape (n,)
        Values as float64, in the field's own unit.
    topic, field, type_name : str
        Where it came from.
    batched : bool
        True if unrolled from batched samples.
    time_source : str
        ``"header"`` (``header.stamp``) or ``"log"`` (the MCAP log time: the message has
        no header, or its stamps are all zero).
    """

    t_s: np.ndarray
    values: np.ndarray
    topic: str = ""
    field: str = ""
    type_name: str = ""
    batched: bool = False
    time_source: str = "header"

    def __len__(self) -> int:
        return int(self.values.size)


@dataclass(frozen=True)
class TopicInfo:
    """A topic of a log: name, type, message count, encodings."""

    topic: str
    type_name: str
    message_count: int
    message_encoding: str
    schema_encoding: str


@dataclass(frozen=True)
class Marker:
    """One ``hasel_msgs/msg/ExperimentMarker`` (time ``t_s`` from its header, s)."""

    t_s: float
    label: str
    signal: str
    offset_kv: float
    amplitude_kv: float
    f0_hz: float
    f1_hz: float
    duration_s: float
    start: bool


class Segment(NamedTuple):
    """A segment of an experiment: start and end time (s) and its DC offset (kV)."""

    t_start_s: float
    t_end_s: float
    offset_kv: float


@dataclass(frozen=True)
class MarkerSegment:
    """A segment between a start marker and its end marker, with everything the marker said."""

    t_start_s: float
    t_end_s: float
    offset_kv: float
    label: str
    signal: str
    amplitude_kv: float
    f0_hz: float
    f1_hz: float
    duration_s: float

    def as_segment(self) -> Segment:
        """``(t_start_s, t_end_s, offset_kv)``."""
        return Segment(self.t_start_s, self.t_end_s, self.offset_kv)


def split_field_spec(spec: str) -> tuple[str, str]:
    """``"/topic.a.b"`` -> ``("/topic", "a.b")`` (ROS topic names hold no dots).

    Raises
    ------
    BadInputError
        If there is no ``.field`` part.
    """
    topic, dot, fld = str(spec).partition(".")
    if not dot or not topic or not fld:
        raise BadInputError(f"bad signal {spec!r}: expected /topic.field (e.g. /plant/batch.voltage_kv)")
    return topic, fld


# --------------------------------------------------------------------------- topics


def _type_of(ch: ChannelRecord, schemas: Mapping[int, SchemaRecord]) -> str:
    s = schemas.get(ch.schema_id)
    return s.name if s is not None else ""


def list_topics(path: str | os.PathLike[str]) -> list[TopicInfo]:
    """The topics of an MCAP log, from its summary (or a full scan if it has none).

    Raises
    ------
    DataFileError
        If the file is damaged (and has no summary) or is not MCAP.
    """
    summ = read_summary(path)
    if summ is not None and summ.has_statistics:
        counts = summ.channel_message_counts
        return [TopicInfo(c.topic, _type_of(c, summ.schemas), counts.get(c.id, 0), c.message_encoding,
                          summ.schemas[c.schema_id].encoding if c.schema_id in summ.schemas else "")
                for c in summ.channels.values()]
    stream = McapStream(path)
    counts2: dict[int, int] = {}
    for block in stream:
        for cid, items in block.messages.items():
            counts2[cid] = counts2.get(cid, 0) + len(items)
    return [TopicInfo(c.topic, _type_of(c, stream.schemas), counts2.get(c.id, 0), c.message_encoding,
                      stream.schemas[c.schema_id].encoding if c.schema_id in stream.schemas else "")
            for c in stream.channels.values()]


# --------------------------------------------------------------------------- collectors


def _has_header(spec: MsgSpec, specs: Mapping[str, MsgSpec]) -> bool:
    for f in spec.fields:
        if f.name == "header" and f.type.is_message and not f.type.is_array:
            h = resolve_type(specs, f.type.base)
            return h.name == "std_msgs/Header"
    return False


def _is_batched(spec: MsgSpec) -> bool:
    return any(f.name == "sample_period_s" and f.type.base in ("float32", "float64") and not f.type.is_array
               for f in spec.fields)


class _Collector:
    """Accumulates the requested fields of one topic (one message type) over the stream."""

    def __init__(self, topic: str, type_name: str, specs: Mapping[str, MsgSpec], fields: Sequence[str],
                 *, allow_strings: bool = False) -> None:
        root = resolve_type(specs, short_name(type_name))
        self.topic, self.type_name = topic, type_name
        self.header = _has_header(root, specs)
        self.batched = _is_batched(root)
        pre = (["header.stamp.sec", "header.stamp.nanosec"] if self.header else [])
        if self.batched:
            pre.append("sample_period_s")
        self.fields = list(dict.fromkeys(fields))
        ex = Extractor(specs, type_name, pre + self.fields)
        self.extractor = ex
        self.npre = len(pre)
        reqs = dict(zip(ex.paths, ex.requests))
        self.kinds: dict[str, FieldRequest] = {}
        for fld in self.fields:
            req = reqs[fld]
            if req.kind == "string" and not allow_strings:
                raise BadInputError(f"{topic}.{fld} is a string, not a number")
            if req.kind == "array" and not self.batched:
                raise BadInputError(
                    f"{topic}.{fld} is an array in a message without sample_period_s (not batched samples); "
                    f"ask for one element, e.g. {topic}.{fld}[0]")
            self.kinds[fld] = req
        pos = {p: i for i, p in enumerate(ex.paths)}
        self.scalar_cols = [(pos[f], f) for f in self.fields if self.kinds[f].kind in ("scalar", "element")]
        self.string_cols = [(pos[f], f) for f in self.fields if self.kinds[f].kind == "string"]
        self.array_cols = [(pos[f], f, PRIMITIVE_FORMATS[self.kinds[f].base][1]) for f in self.fields
                           if self.kinds[f].kind == "array"]
        self.times = array("q")
        self.log_times = array("q")
        self.periods = array("d")
        self.scalars = {f: array("d") for _, f in self.scalar_cols}
        self.strings: dict[str, list[str]] = {f: [] for _, f in self.string_cols}
        self.counts = {f: array("q") for _, f, _ in self.array_cols}
        self.slices: dict[str, list[Any]] = {f: [] for _, f, _ in self.array_cols}
        self.parts: dict[str, list[bytes]] = {f: [] for _, f, _ in self.array_cols}
        self.messages = 0
        self._loop, self._sinks = self._make_loop()

    def _make_loop(self) -> tuple[Callable[..., None], tuple[Callable[[Any], Any], ...]]:
        """The generated per-chunk loop and the bound ``append`` methods it feeds."""
        names: list[str] = ["T", "L"]
        sinks: list[Callable[[Any], Any]] = [self.times.append, self.log_times.append]
        lines = [f"T(v0 * {NS_PER_S} + v1)" if self.header else "T(lt)", "L(lt)"]  # stamp_to_ns, inlined
        if self.array_cols:
            names.append("P")
            sinks.append(self.periods.append)
            lines.append(f"P(v{self.npre - 1})")
        for k, (j, f) in enumerate(self.scalar_cols):
            names.append(f"S{k}")
            sinks.append(self.scalars[f].append)
            lines.append(f"S{k}(v{j})")
        for k, (j, f) in enumerate(self.string_cols):
            names.append(f"X{k}")
            sinks.append(self.strings[f].append)
            lines.append(f"X{k}(v{j})")
        for k, (j, f, size) in enumerate(self.array_cols):
            names += [f"A{k}", f"C{k}"]
            sinks += [self.slices[f].append, self.counts[f].append]
            lines += [f"A{k}(mv[v{j}[0]:v{j}[0] + {size} * v{j}[1]])", f"C{k}(v{j}[1])"]
        return self.extractor.make_loop(names, lines), tuple(sinks)

    def _sizes(self) -> list[int]:
        return [len(self.times), len(self.log_times), len(self.periods)] + [
            len(c) for c in self.scalars.values()] + [len(c) for c in self.strings.values()] + [
            len(c) for c in self.counts.values()]

    def _rollback(self, sizes: list[int]) -> None:
        cols: list[Any] = [self.times, self.log_times, self.periods, *self.scalars.values(), *self.strings.values(),
                           *self.counts.values()]
        for col, n in zip(cols, sizes):
            del col[n:]
        for sl in self.slices.values():
            sl.clear()

    def consume(self, buf: bytes, items: Sequence[tuple[int, int, int, int, int]]) -> None:
        """Decode the requested fields of the messages ``items`` of one chunk ``buf``."""
        mv = memoryview(buf)
        sizes = self._sizes()
        try:
            self._loop(buf, mv, items, *self._sinks)
        except Exception:  # noqa: BLE001 - big-endian or damaged: redo this chunk message by message
            self._rollback(sizes)
            self._consume_slow(buf, mv, items)
        self.messages += len(items)
        for f, sl in self.slices.items():  # copy out, so the chunk buffer can be freed
            if sl:
                self.parts[f].append(b"".join(sl))
                sl.clear()

    def _consume_slow(self, buf: bytes, mv: memoryview, items: Sequence[tuple[int, int, int, int, int]]) -> None:
        ex = self.extractor
        pi = self.npre - 1
        for lt, _pt, _seq, s, e in items:
            r = ex(buf, s, e)  # raises CdrError on damage
            self.times.append(stamp_to_ns(r[0], r[1]) if self.header else lt)
            self.log_times.append(lt)
            for j, f in self.scalar_cols:
                self.scalars[f].append(r[j])
            for j, f in self.string_cols:
                self.strings[f].append(r[j])
            if self.array_cols:
                self.periods.append(r[pi])
                for j, f, size in self.array_cols:
                    off, n = r[j]
                    self.slices[f].append(mv[off:off + size * n])
                    self.counts[f].append(n)

    def signals(self) -> dict[str, Signal]:
        out: dict[str, Signal] = {}
        t_ns = np.frombuffer(self.times, dtype=np.int64) if len(self.times) else np.zeros(0, np.int64)
        source = "header" if self.header else "log"
        if self.header and t_ns.size and not t_ns.any():  # stamps never set: use the log times
            t_ns = np.frombuffer(self.log_times, dtype=np.int64)
            source = "log"
        t_s = ns_to_s_array(t_ns)
        for _, f in self.scalar_cols:
            vals = np.array(self.scalars[f], dtype=float)
            out[f] = Signal(t_s.copy(), vals, self.topic, f, self.type_name, False, source)
        period = np.frombuffer(self.periods, dtype=float) if len(self.periods) else np.zeros(0)
        done: list[tuple[np.ndarray, np.ndarray]] = []  # (counts, times): fields sharing a time base
        for _, f, _size in self.array_cols:
            req = self.kinds[f]
            raw = bytearray().join(self.parts[f])
            self.parts[f] = []
            vals = np.frombuffer(raw, dtype=req.dtype)
            if vals.dtype != np.float64 or not vals.dtype.isnative:
                vals = vals.astype(float)
            counts = np.frombuffer(self.counts[f], dtype=np.int64) if len(self.counts[f]) else np.zeros(0, np.int64)
            t = next((tt for cc, tt in done if np.array_equal(cc, counts)), None)
            if t is None:
                t = _unroll_times(t_s, period, counts)
                done.append((counts, t))
            out[f] = Signal(t, vals, self.topic, f, self.type_name, True, source)
        return out


def _unroll_times(stamp_s: np.ndarray, period_s: np.ndarray, counts: np.ndarray) -> np.ndarray:
    """Per-sample times of batches: sample i of batch k at stamp_s[k] + i * period_s[k]."""
    if counts.size and np.all(counts == counts[0]):
        n = int(counts[0])
        return (stamp_s[:, None] + np.arange(n, dtype=float)[None, :] * period_s[:, None]).ravel()
    starts = np.cumsum(counts) - counts
    k = np.arange(int(counts.sum())) - np.repeat(starts, counts)
    return np.repeat(stamp_s, counts) + k * np.repeat(period_s, counts)


def _short_or_none(name: str) -> str | None:
    try:
        return short_name(name)
    except MessageDefinitionError:
        return None


class _Scan:
    """One pass over a log feeding collectors of several topics (and markers)."""

    def __init__(self, path: str | os.PathLike[str], wanted: Mapping[str, Sequence[str]], *,
                 markers: bool = False, progress: ProgressFn | None = None) -> None:
        self.path = Path(path)
        if not self.path.exists():
            raise DataFileError(f"no such file: {self.path}")
        if self.path.is_dir():
            raise DataFileError(f"{self.path} is a directory, not an MCAP file")
        self.wanted = {t: list(f) for t, f in wanted.items()}
        self.markers = markers
        self.progress = progress
        self.by_topic: dict[str, _Collector] = {}
        self.marker_collectors: list[_Collector] = []
        self.handlers: dict[int, _Collector | None] = {}
        self.specs_cache: dict[int, dict[str, MsgSpec] | Exception] = {}
        self.topics_seen: dict[str, str] = {}

    def _specs(self, schema: SchemaRecord | None, topic: str) -> dict[str, MsgSpec]:
        if schema is None:
            raise DataFileError(f"{self.path}: topic {topic} has no schema: its messages cannot be decoded")
        got = self.specs_cache.get(schema.id)
        if got is None:
            try:
                if schema.encoding != "ros2msg":
                    raise MessageDefinitionError(f"schema encoding {schema.encoding!r} (only ros2msg is supported)")
                got = parse_schema(schema.name, schema.data.decode("utf-8", "replace"))
            except MessageDefinitionError as err:
                got = err
            self.specs_cache[schema.id] = got
        if isinstance(got, Exception):
            raise DataFileError(f"{self.path}: cannot decode topic {topic} ({schema.name}): {got}")
        return got

    def _handler(self, ch: ChannelRecord, schemas: Mapping[int, SchemaRecord]) -> _Collector | None:
        schema = schemas.get(ch.schema_id)
        self.topics_seen[ch.topic] = schema.name if schema else ""
        is_marker = self.markers and schema is not None and _short_or_none(schema.name) == MARKER_TYPE
        if ch.topic not in self.wanted and not is_marker:
            return None
        if ch.message_encoding != "cdr":
            raise DataFileError(f"{self.path}: topic {ch.topic} is {ch.message_encoding!r}-encoded, not cdr")
        specs = self._specs(schema, ch.topic)
        assert schema is not None
        if is_marker and ch.topic not in self.wanted:
            col = _Collector(ch.topic, schema.name, specs, list(_MARKER_FIELDS), allow_strings=True)
            self.marker_collectors.append(col)
            return col
        old = self.by_topic.get(ch.topic)
        if old is not None:
            if short_name(old.type_name) != short_name(schema.name):
                raise DataFileError(f"{self.path}: topic {ch.topic} has two types: {old.type_name}, {schema.name}")
            return old
        try:
            col = _Collector(ch.topic, schema.name, specs, self.wanted[ch.topic])
        except MessageDefinitionError as err:
            raise BadInputError(f"{ch.topic}: {err}") from None
        self.by_topic[ch.topic] = col
        return col

    def run(self) -> None:
        summ = read_summary(self.path)
        if summ is not None:  # fail fast on unknown topics / fields, before reading any data
            for ch in summ.channels.values():
                self.handlers[ch.id] = self._handler(ch, summ.schemas)
            self._check_topics()
        stream = McapStream(self.path)
        handlers = self.handlers
        try:
            for block in stream:
                for cid, items in block.messages.items():
                    h = handlers.get(cid, False)
                    if h is False:
                        ch = stream.channels.get(cid)
                        if ch is None:
                            raise DataFileError(f"{self.path}: message of unknown channel {cid} in the chunk "
                                                f"at byte {block.offset}")
                        h = handlers[cid] = self._handler(ch, stream.schemas)
                    if h is not None:
                        h.consume(block.buf, items)
                if self.progress is not None and stream.size:
                    self.progress(block.offset / stream.size)
        except CdrError as err:
            raise DataFileError(f"{self.path}: {err}") from None
        except DataFileError:
            raise
        except BadInputError:
            # a field or topic the data section names differently: damage shows up later
            # (CRCs are checked at the end), so look for it before blaming the request
            self._raise_if_damaged()
            raise
        if self.progress is not None:
            self.progress(1.0)
        self._check_topics()

    def _raise_if_damaged(self) -> None:
        check = McapStream(self.path, tolerant=True)
        for _ in check:
            pass
        if check.damages or not check.footer:
            what = check.damages[0] if check.damages else "no footer"
            raise DataFileError(f"{self.path}: damaged MCAP: {what}") from None

    def _check_topics(self) -> None:
        missing = [t for t in self.wanted if t not in self.by_topic]
        if missing:
            have = ", ".join(f"{t} ({ty})" for t, ty in sorted(self.topics_seen.items())) or "(none)"
            raise BadInputError(f"{self.path}: no topic {', '.join(missing)}; topics: {have}")


def load_signals(path: str | os.PathLike[str], fields: Sequence[str], *,
                 progress: ProgressFn | None = None) -> dict[str, Signal]:
    """Load numeric fields of an MCAP log as signals.

    Parameters
    ----------
    path : path-like
        A ROS 2 MCAP file (CDR messages, ``ros2msg`` schemas).
    fields : sequence of str
        ``"/topic.field"`` names; nested with dots, array elements as ``name[i]``.
    progress : callable, optional
        Called with the fraction of the file read (0..1) after each chunk.

    Returns
    -------
    dict
        ``{field spec: Signal}``, in the order asked.

    Raises
    ------
    BadInputError
        Unknown topic or field (the message lists what exists), a string field, or an
        array field of a non-batched message.
    DataFileError
        A damaged or non-MCAP file (with the byte offset and record), or messages that
        do not decode.
    """
    specs = [(f, *split_field_spec(f)) for f in fields]
    wanted: dict[str, list[str]] = {}
    for _, topic, fld in specs:
        wanted.setdefault(topic, []).append(fld)
    scan = _Scan(path, wanted, progress=progress)
    scan.run()
    out: dict[str, Signal] = {}
    per_topic = {t: c.signals() for t, c in scan.by_topic.items()}
    for spec, topic, fld in specs:
        out[spec] = per_topic[topic][fld]
    return out


def _markers_from(collectors: Sequence[_Collector]) -> list[Marker]:
    out: list[Marker] = []
    for col in collectors:
        t = ns_to_s_array(np.frombuffer(col.times, dtype=np.int64)) if len(col.times) else np.zeros(0)
        num = {f: col.scalars[f] for _, f in col.scalar_cols}
        for i in range(len(col.times)):
            out.append(Marker(float(t[i]), col.strings["label"][i], col.strings["signal"][i],
                              num["offset_kv"][i], num["amplitude_kv"][i], num["f0_hz"][i], num["f1_hz"][i],
                              num["duration_s"][i], bool(num["start"][i])))
    out.sort(key=lambda m: m.t_s)
    return out


def load_markers(path: str | os.PathLike[str]) -> list[Marker]:
    """All ``hasel_msgs/msg/ExperimentMarker`` messages of a log (any topic), by time."""
    scan = _Scan(path, {}, markers=True)
    scan.run()
    return _markers_from(scan.marker_collectors)


def marker_segments(markers: Sequence[Marker], t_end_s: float | None = None) -> list[MarkerSegment]:
    """Pair start and end markers (by label) into segments.

    A start while the same label is open closes the open one at that time; a segment
    still open at the end closes at ``t_end_s`` (the end of the data) or, without it,
    after the marker's ``duration_s`` (dropped if that is not positive). Ends without
    a start are ignored.
    """
    open_: dict[str, Marker] = {}
    out: list[MarkerSegment] = []

    def close(m: Marker, t1: float) -> None:
        if t1 > m.t_s:
            out.append(MarkerSegment(m.t_s, t1, m.offset_kv, m.label, m.signal, m.amplitude_kv, m.f0_hz,
                                     m.f1_hz, m.duration_s))

    for m in sorted(markers, key=lambda x: x.t_s):
        if m.start:
            if m.label in open_:
                close(open_.pop(m.label), m.t_s)
            open_[m.label] = m
        elif m.label in open_:
            close(open_.pop(m.label), m.t_s)
    for m in open_.values():
        if t_end_s is not None:
            close(m, t_end_s)
        elif m.duration_s > 0:
            close(m, m.t_s + m.duration_s)
    out.sort(key=lambda s: s.t_start_s)
    return out


def load_signals_and_markers(path: str | os.PathLike[str], fields: Sequence[str], *,
                             progress: ProgressFn | None = None) -> tuple[dict[str, Signal], list[Marker]]:
    """:func:`load_signals` and :func:`load_markers` in one pass over the file."""
    specs = [(f, *split_field_spec(f)) for f in fields]
    wanted: dict[str, list[str]] = {}
    for _, topic, fld in specs:
        wanted.setdefault(topic, []).append(fld)
    scan = _Scan(path, wanted, markers=True, progress=progress)
    scan.run()
    per_topic = {t: c.signals() for t, c in scan.by_topic.items()}
    markers = _markers_from(scan.marker_collectors)
    return {spec: per_topic[topic][fld] for spec, topic, fld in specs}, markers


def fields_of(path: str | os.PathLike[str], topic: str) -> list[str]:
    """Numeric field paths of ``topic`` in the log (for error messages and discovery)."""
    summ = read_summary(path)
    if summ is None:
        return []
    for ch in summ.channels.values():
        s = summ.schemas.get(ch.schema_id)
        if ch.topic == topic and s is not None:
            try:
                return numeric_fields(parse_schema(s.name, s.data.decode("utf-8", "replace")), s.name)
            except MessageDefinitionError:
                return []
    return []
