"""``hasel info``: what an MCAP log holds, like ``ros2 bag info``, and what a damaged one still holds.

The whole file is read (chunk CRCs checked), so the counts, times and rates are those of
the messages actually present, and damage anywhere is found; topics whose schema this
toolkit cannot decode are reported, not fatal.
"""
from __future__ import annotations

import math
import os
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

from hasel.errors import DataFileError
from hasel.io.mcapfile import ChannelRecord, Damage, McapStream, SchemaRecord, read_summary
from hasel.io.msgdefs import MessageDefinitionError, parse_schema
from hasel.timeconv import ns_to_s, ns_to_stamp

__all__ = ["TopicStats", "InfoReport", "info", "format_info", "format_size"]


@dataclass
class TopicStats:
    """One topic (channel) of a log.

    Attributes
    ----------
    topic, type_name, serialization_format : str
    count : int
        Messages read.
    first_ns, last_ns : int
        First and last log time, ns (0 if no message).
    schema_error : str
        Why the schema cannot be decoded ("" if it can).
    """

    topic: str
    type_name: str
    serialization_format: str
    count: int = 0
    first_ns: int = 0
    last_ns: int = 0
    schema_error: str = ""

    @property
    def rate_hz(self) -> float:
        """Mean message rate, Hz (NaN with fewer than two messages)."""
        if self.count < 2 or self.last_ns <= self.first_ns:
            return math.nan
        return (self.count - 1) / ns_to_s(self.last_ns - self.first_ns)


@dataclass
class InfoReport:
    """Summary of one MCAP file (see :func:`info`)."""

    path: Path
    size_bytes: int
    profile: str
    library: str
    ros_distro: str
    topics: list[TopicStats]
    message_count: int
    start_ns: int
    end_ns: int
    chunks: int
    chunks_lost: int
    compression: tuple[str, ...]
    damages: tuple[Damage, ...] = ()
    complete: bool = True
    storage_id: str = "mcap"
    notes: list[str] = field(default_factory=list)

    @property
    def duration_s(self) -> float:
        """Log time from the first to the last message, s."""
        return ns_to_s(self.end_ns - self.start_ns)


def _schema_error(schema: SchemaRecord | None) -> str:
    if schema is None:
        return "no schema"
    if schema.encoding != "ros2msg":
        return f"schema encoding {schema.encoding!r} is not ros2msg"
    try:
        parse_schema(schema.name, schema.data.decode("utf-8", "replace"))
    except MessageDefinitionError as err:
        return str(err)
    return ""


def _ros_distro(metadata: list[tuple[str, dict[str, str]]]) -> str:
    for name, meta in reversed(metadata):
        if name == "rosbag2" and "serialized_metadata" in meta:
            try:
                import yaml

                doc = yaml.safe_load(meta["serialized_metadata"])
            except Exception:  # noqa: BLE001 - a malformed record only loses the distro name
                continue
            if isinstance(doc, dict) and doc.get("ros_distro"):
                return str(doc["ros_distro"])
    return ""


def info(path: str | os.PathLike[str], *, progress: Callable[[float], None] | None = None) -> InfoReport:
    """Read ``path`` completely and summarise it (tolerant of damage).

    Returns
    -------
    InfoReport
        ``complete`` is False when anything is damaged or missing (``damages`` says
        what and where); counts then cover what can be read (what salvage would keep).

    Raises
    ------
    DataFileError
        If the file cannot be opened or is not MCAP at all.
    """
    p = Path(path)
    if not p.is_file():
        raise DataFileError(f"no such file: {p}")
    stream = McapStream(p, tolerant=True)
    stats: dict[int, TopicStats] = {}
    total = 0
    for block in stream:
        for cid, items in block.messages.items():
            st = stats.get(cid)
            if st is None:
                ch = stream.channels.get(cid)
                st = stats[cid] = TopicStats(ch.topic if ch else f"(unknown channel {cid})",
                                             "", ch.message_encoding if ch else "")
            lo = min(it[0] for it in items)
            hi = max(it[0] for it in items)
            st.first_ns = lo if st.count == 0 else min(st.first_ns, lo)
            st.last_ns = max(st.last_ns, hi)
            st.count += len(items)
            total += len(items)
        if progress is not None and stream.size:
            progress(block.offset / stream.size)
    summ = read_summary(p) if stream.footer else None
    schemas: dict[int, SchemaRecord] = dict(summ.schemas) if summ else {}
    schemas.update(stream.schemas)
    channels: dict[int, ChannelRecord] = dict(summ.channels) if summ else {}
    channels.update(stream.channels)
    topics: list[TopicStats] = []
    errors: dict[int, str] = {}
    for cid, ch in channels.items():
        st = stats.pop(cid, None) or TopicStats(ch.topic, "", ch.message_encoding)
        schema = schemas.get(ch.schema_id)
        st.topic, st.serialization_format = ch.topic, ch.message_encoding
        st.type_name = schema.name if schema else ""
        if ch.schema_id not in errors:
            errors[ch.schema_id] = _schema_error(schema)
        st.schema_error = errors[ch.schema_id]
        topics.append(st)
    topics += stats.values()  # messages of channels whose definition was lost
    counted = [t for t in topics if t.count]
    report = InfoReport(
        path=p, size_bytes=stream.size, profile=stream.header[0] if stream.header else "",
        library=stream.header[1] if stream.header else "", ros_distro=_ros_distro(stream.metadata),
        topics=topics, message_count=total,
        start_ns=min((t.first_ns for t in counted), default=0), end_ns=max((t.last_ns for t in counted), default=0),
        chunks=stream.chunks, chunks_lost=stream.chunks_skipped, compression=tuple(sorted(stream.compressions)),
        damages=tuple(stream.damages), complete=stream.footer and not stream.damages)
    if summ is not None and summ.has_statistics and summ.message_count != total and report.complete:
        report.notes.append(f"the summary counts {summ.message_count} messages, the data holds {total}")
    if progress is not None:
        progress(1.0)
    return report


def format_size(n: int) -> str:
    """Bytes as ``ros2 bag info`` prints them (B, KiB, MiB, GiB, TiB)."""
    size = float(n)
    units = ("B", "KiB", "MiB", "GiB", "TiB")
    i = 0
    while size >= 1024 and i < 4:
        size /= 1024
        i += 1
    return f"{size:.0f} {units[i]}" if i == 0 else f"{size:.1f} {units[i]}"


def _format_time(ns: int) -> str:
    sec, rem = ns_to_stamp(ns)
    ms = rem // 1_000_000
    tm = time.localtime(sec)
    return f"{time.strftime('%b %e %Y %H:%M:%S', tm)}.{ms:03d} ({sec}.{ms:03d})"


def format_info(report: InfoReport) -> str:
    """The report as text: ``ros2 bag info``'s layout, then rates and any damage."""
    ind = " " * 19
    lines = [
        "",
        f"Files:             {report.path.name}",
        f"Bag size:          {format_size(report.size_bytes)}",
        f"Storage id:        {report.storage_id}",
        f"ROS Distro:        {report.ros_distro or 'unknown'}",
        f"Duration:          {report.duration_s:.3f}s",
        f"Start:             {_format_time(report.start_ns)}",
        f"End:               {_format_time(report.end_ns)}",
        f"Messages:          {report.message_count}",
    ]
    topic_lines = [f"Topic: {t.topic} | Type: {t.type_name or '(none)'} | Count: {t.count} | "
                   f"Serialization Format: {t.serialization_format}" for t in report.topics]
    lines.append("Topic information: " + (("\n" + ind).join(topic_lines) if topic_lines else ""))
    rate_lines = []
    for t in report.topics:
        r = t.rate_hz
        rate = f"{r:.4g} Hz" if math.isfinite(r) else "-"
        rate_lines.append(f"{t.topic}: {rate} ({t.count} messages over {ns_to_s(t.last_ns - t.first_ns):.3f} s)")
    lines.append("Topic rates:       " + ("\n" + ind).join(rate_lines))
    bad = [t for t in report.topics if t.schema_error]
    if bad:
        lines.append("Undecodable:       " + ("\n" + ind).join(f"{t.topic} ({t.type_name or 'no type'}): "
                                                             f"{t.schema_error}" for t in bad))
    lines.append(f"Chunks:            {report.chunks} ({', '.join(report.compression) or 'none'}); "
                 f"writer: {report.library or 'unknown'}; profile: {report.profile or '(none)'}")
    if report.complete:
        lines.append("Status:            intact")
    else:
        first = str(report.damages[0]) if report.damages else "incomplete"
        more = f" (+{len(report.damages) - 1} more)" if len(report.damages) > 1 else ""
        lines.append(f"Status:            damaged: {first}{more}")
        lost = f", {report.chunks_lost} damaged chunks lost" if report.chunks_lost else ""
        lines.append(f"Recoverable:       {report.message_count} messages in {report.chunks} intact chunks{lost}; "
                     f"`hasel salvage {report.path.name} OUT.mcap` writes them to a valid file")
    for note in report.notes:
        lines.append(f"Note:              {note}")
    return "\n".join(lines) + "\n"
