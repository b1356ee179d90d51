"""``hasel info FILE`` and ``hasel salvage FILE OUT``: the CLI side of :mod:`hasel.io`.

Each command is a pair ``add_*_arguments(parser)`` / ``run_*(args) -> int`` registered in
:data:`hasel.cli.COMMANDS`. Bad input raises :class:`~hasel.errors.BadInputError` (one
line on stderr, exit code 2).
"""
from __future__ import annotations

import argparse
import json
import math
import os
import sys
import time
from collections.abc import Callable

from hasel.errors import DataFileError
from hasel.io.info import format_info, info
from hasel.io.salvage import salvage
from hasel.outputs import write_text

__all__ = ["add_info_arguments", "run_info", "add_salvage_arguments", "run_salvage"]

_PROGRESS_MIN_BYTES = 64 << 20


def _progress(label: str, size: int) -> Callable[[float], None] | None:
    """A progress printer on stderr (at most twice a second), for files big enough to need one."""
    if size < _PROGRESS_MIN_BYTES or not sys.stderr.isatty():
        return None
    last = [0.0]

    def show(frac: float) -> None:
        now = time.monotonic()
        if frac < 1.0 and now - last[0] < 0.5:
            return
        last[0] = now
        end = "\n" if frac >= 1.0 else "\r"
        sys.stderr.write(f"{label}: {100 * frac:5.1f} % of {size / 2**20:.0f} MiB{end}")
        sys.stderr.flush()

    return show


def _size(path: str) -> int:
    try:
        return os.path.getsize(path)
    except OSError:
        return 0


def add_info_arguments(p: argparse.ArgumentParser) -> None:
    """Options of ``hasel info``."""
    p.add_argument("file", metavar="FILE", help="an MCAP file (ROS 2 profile)")
    p.add_argument("--json", metavar="OUT.json", help="also write the report as JSON")


def run_info(args: argparse.Namespace) -> int:
    """Print the summary of an MCAP file; a damaged file exits with code 2 after the report."""
    report = info(args.file, progress=_progress("reading", _size(args.file)))
    sys.stdout.write(format_info(report))
    sys.stdout.flush()
    if args.json:
        doc = {
            "file": str(report.path), "size_bytes": report.size_bytes, "storage_id": report.storage_id,
            "profile": report.profile, "library": report.library, "ros_distro": report.ros_distro,
            "duration_s": report.duration_s, "start_ns": report.start_ns, "end_ns": report.end_ns,
            "message_count": report.message_count, "chunks": report.chunks, "chunks_lost": report.chunks_lost,
            "complete": report.complete, "damages": [str(d) for d in report.damages],
            "topics": [{"topic": t.topic, "type": t.type_name, "count": t.count,
                        "serialization_format": t.serialization_format,
                        "rate_hz": None if math.isnan(t.rate_hz) else t.rate_hz,
                        "schema_error": t.schema_error} for t in report.topics],
        }
        write_text(args.json, json.dumps(doc, indent=2))
    if not report.complete:
        first = report.damages[0] if report.damages else "incomplete file"
        raise DataFileError(f"{args.file} is damaged ({first}); {report.message_count} messages are recoverable "
                            f"with `hasel salvage {args.file} OUT.mcap`")
    return 0


def add_salvage_arguments(p: argparse.ArgumentParser) -> None:
    """Options of ``hasel salvage``."""
    p.add_argument("file", metavar="FILE", help="a damaged MCAP file (e.g. a recording killed before it closed)")
    p.add_argument("out", metavar="OUT", help="the valid MCAP file to write")
    p.add_argument("--overwrite", "--force", dest="overwrite", action="store_true", help="replace OUT if it exists")


def run_salvage(args: argparse.Namespace) -> int:
    """Write the intact chunks of FILE to OUT as a valid MCAP file; print what was recovered."""
    report = salvage(args.file, args.out, overwrite=args.overwrite, progress=_progress("salvaging", _size(args.file)))
    sys.stdout.write(report.summary() + "\n")
    if report.messages == 0 and not report.intact:
        raise DataFileError(f"no message of {args.file} could be recovered; {args.out} holds only its "
                            "topics and types")
    return 0
