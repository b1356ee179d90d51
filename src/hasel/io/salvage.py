"""Rewrite what is readable in a damaged MCAP file as a valid one.

A recording killed with SIGKILL (or a power cut) leaves a file without summary and
footer, possibly ending inside a chunk; a corrupted byte makes one chunk's CRC fail.
:func:`salvage` reads the file in tolerant mode (:class:`~hasel.io.mcapfile.McapStream`),
keeps every intact chunk and loose message, and writes them, in their original order
and with their original times, schemas and channels, to a new file with a summary.
"""
from __future__ import annotations

import os
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

from hasel.errors import BadInputError, DataFileError
from hasel.io.mcapfile import ChannelRecord, Damage, McapStream, SchemaRecord, read_summary
from hasel.io.writer import Ros2McapWriter

__all__ = ["SalvageReport", "salvage"]


@dataclass(frozen=True)
class SalvageReport:
    """What :func:`salvage` recovered.

    Attributes
    ----------
    source, destination : Path
        The damaged file and the new one.
    messages : int
        Messages written to ``destination``.
    chunks : int
        Intact chunks read.
    chunks_lost : int
        Chunks skipped as damaged (a chunk cut by truncation is not counted here).
    dropped : int
        Messages whose channel definition was lost (not written).
    topics : dict
        Messages recovered per topic.
    damages : tuple of Damage
        Every problem found, with its byte offset.
    intact : bool
        True if the source had no damage at all (the copy is then complete).
    start_ns, end_ns : int
        Log times of the first and last recovered message (0 if none), ns.
    """

    source: Path
    destination: Path
    messages: int
    chunks: int
    chunks_lost: int
    dropped: int
    topics: dict[str, int] = field(default_factory=dict)
    damages: tuple[Damage, ...] = ()
    intact: bool = False
    start_ns: int = 0
    end_ns: int = 0

    def summary(self) -> str:
        """A few human lines about the result."""
        k = len(self.topics)
        lines = [f"{self.destination}: {self.messages} messages on {k} topic{'' if k == 1 else 's'} "
                 f"from {self.chunks} intact chunks of {self.source}"]
        if self.intact:
            lines.append("the source was not damaged: the copy is complete")
        else:
            c = self.chunks_lost
            lost = (f"{c} damaged chunk{'' if c == 1 else 's'} lost, with the messages in {'it' if c == 1 else 'them'}"
                    if c else "the damage lay outside the chunks: no chunk was lost")
            n = len(self.damages)
            lines.append(f"{n} problem{'' if n == 1 else 's'} found ({lost}); first: {self.damages[0]}"
                         if self.damages else lost)
        if self.messages == 0 and not self.intact:
            lines.append("no message could be recovered")
        if self.dropped:
            lines.append(f"{self.dropped} messages dropped: their channel definition was in a damaged part")
        for topic, n in sorted(self.topics.items()):
            lines.append(f"  {topic}: {n}")
        return "\n".join(lines)


def salvage(src: str | os.PathLike[str], dst: str | os.PathLike[str], *, overwrite: bool = False,
            progress: Callable[[float], None] | None = None) -> SalvageReport:
    """Copy every intact chunk and message of ``src`` into a new valid MCAP file ``dst``.

    Parameters
    ----------
    src : path-like
        A (possibly damaged) MCAP file.
    dst : path-like
        The file to write (must differ from ``src``).
    overwrite : bool
        Replace ``dst`` if it exists.
    progress : callable, optional
        Called with the fraction of ``src`` read (0..1).

    Returns
    -------
    SalvageReport

    Raises
    ------
    BadInputError
        If ``dst`` is ``src`` or exists (without ``overwrite``).
    DataFileError
        If ``src`` cannot be read or is not an MCAP file at all.
    """
    s, d = Path(src), Path(dst)
    if not s.is_file():
        raise DataFileError(f"no such file: {s}")
    if d.exists() and (d.resolve() == s.resolve()):
        raise BadInputError(f"the output {d} is the damaged file itself; choose another name")
    if d.exists() and not overwrite:
        raise BadInputError(f"{d} exists; choose another name (or --overwrite to replace it)")
    stream = McapStream(s, tolerant=True)
    summ = read_summary(s)  # a damaged data section may still have an intact summary
    schema_map: dict[int, int] = {}
    channel_map: dict[int, int] = {}
    topics: dict[str, int] = {}
    messages = dropped = 0
    t_lo: int | None = None
    t_hi = 0
    tmp = d.with_name(d.name + ".partial")
    writer = Ros2McapWriter(tmp, fsync_interval_s=None)

    def schema_id(old: int, schemas: dict[int, SchemaRecord]) -> int | None:
        if old == 0:
            return 0
        if old not in schema_map:
            rec = schemas.get(old) or (summ.schemas.get(old) if summ else None)
            if rec is None:
                return None
            schema_map[old] = writer.add_schema(rec.name, rec.encoding, rec.data)
        return schema_map[old]

    def channel_id(old: int) -> int | None:
        if old in channel_map:
            return channel_map[old]
        ch: ChannelRecord | None = stream.channels.get(old) or (summ.channels.get(old) if summ else None)
        if ch is None:
            return None
        sid = schema_id(ch.schema_id, stream.schemas)
        if sid is None:
            return None
        channel_map[old] = writer.add_channel(ch.topic, sid, message_encoding=ch.message_encoding,
                                              metadata=ch.metadata)
        topics.setdefault(ch.topic, 0)
        return channel_map[old]

    try:
        for block in stream:
            items = [(it, cid) for cid, lst in block.messages.items() for it in lst]
            if len(block.messages) > 1:
                items.sort(key=lambda x: x[0][3])  # original order within the chunk
            buf = memoryview(block.buf)
            for (lt, pt, seq, start, end), cid in items:
                new = channel_id(cid)
                if new is None:
                    dropped += 1
                    continue
                writer.write(new, buf[start:end], lt, pt, seq)
                topic = stream.channels[cid].topic if cid in stream.channels else summ.channels[cid].topic  # type: ignore[union-attr]
                topics[topic] = topics.get(topic, 0) + 1
                messages += 1
                t_lo = lt if t_lo is None else min(t_lo, lt)
                t_hi = max(t_hi, lt)
            if progress is not None and stream.size:
                progress(block.offset / stream.size)
        # channels that never carried a message still belong to the file
        for old in list(stream.channels) + (list(summ.channels) if summ else []):
            channel_id(old)
        for name, meta in stream.metadata:
            writer.add_metadata(name, meta)
        writer.close()
        os.replace(tmp, d)
    except BaseException:
        writer.close()
        tmp.unlink(missing_ok=True)
        raise
    if progress is not None:
        progress(1.0)
    intact = not stream.damages and stream.footer
    # a chunk cut by truncation is damaged too, though the reader had nothing left to skip
    cut = {dm.offset for dm in stream.damages if dm.record == "chunk"}
    return SalvageReport(s, d, messages, stream.chunks, max(stream.chunks_skipped, len(cut)), dropped, topics,
                         tuple(stream.damages), intact, t_lo or 0, t_hi)
