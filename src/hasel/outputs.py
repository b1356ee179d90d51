"""Output files of every command: refused if they exist (unless ``--overwrite``), checked
writable before any work, written atomically with the permissions the umask gives.

A command declares its output options once (:class:`Output` rows in
:data:`hasel.cli.COMMANDS`); the command line adds ``--overwrite`` and calls
:func:`check_outputs` before the command runs, so a run of minutes cannot end in
"cannot write" or silently replace yesterday's log. Writers use :func:`write_text` /
:func:`write_bytes` (a temporary file in the same directory, then ``os.replace``): an
interrupted write never leaves half a file under the final name.
"""
from __future__ import annotations

import argparse
import contextlib
import math
import os
import tempfile
from collections.abc import Iterable, Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from hasel.errors import BadInputError

__all__ = ["Output", "add_overwrite_option", "check_output", "check_outputs", "write_text", "write_bytes",
           "file_mode", "replacing", "json_safe"]


@dataclass(frozen=True)
class Output:
    """An output option: ``dest`` of the parsed argument, ``inside`` a file name if it is a directory."""

    dest: str
    inside: str = ""


def add_overwrite_option(p: argparse.ArgumentParser) -> None:
    """Add ``--overwrite`` to a parser (once)."""
    if not any("--overwrite" in a.option_strings for a in p._actions):
        p.add_argument("--overwrite", action="store_true", help="replace output files that exist")


def file_mode() -> int:
    """Permission bits a new regular file gets under the current umask (0o666 & ~umask)."""
    old = os.umask(0o022)
    os.umask(old)
    return 0o666 & ~old


def check_output(path: str | os.PathLike, overwrite: bool, what: str = "") -> Path:
    """Refuse ``path`` if it exists (unless ``overwrite``) or its directory cannot take a new file.

    Creates the missing parent directories. Raises :class:`BadInputError` naming the path.
    """
    p = Path(path)
    label = f"{what} {p}".strip()
    if p.is_dir():
        raise BadInputError(f"{label} is a directory, not a file")
    if p.exists() and not overwrite:
        raise BadInputError(f"{label} exists; use --overwrite to replace it")
    try:
        p.parent.mkdir(parents=True, exist_ok=True)
        fd, tmp = tempfile.mkstemp(prefix=".hasel-check-", dir=p.parent)
        os.close(fd)
        os.unlink(tmp)
    except OSError as err:
        raise BadInputError(f"cannot write {label}: {err.strerror or err}") from err
    return p


def check_outputs(args: argparse.Namespace, outputs: Iterable[Output]) -> None:
    """:func:`check_output` for every declared output option that was given."""
    outputs = list(outputs)
    dests = {o.dest for o in outputs}
    inputs = {Path(v).resolve() for k, v in vars(args).items()
              if k not in dests and isinstance(v, str) and v and not k.startswith("_") and Path(v).is_file()}
    seen: dict[Path, str] = {}
    for o in outputs:
        value = getattr(args, o.dest, None)
        if not value:
            continue
        opt = "--" + o.dest.replace("_", "-")
        path = Path(value) / o.inside if o.inside else Path(value)
        key = path.resolve()
        if key in seen:
            raise BadInputError(f"{opt} and {seen[key]} name the same file {path}")
        seen[key] = opt
        if key in inputs:
            raise BadInputError(f"{opt} {path} is also an input of this command; choose another name")
        check_output(path, bool(getattr(args, "overwrite", False)), opt)


def write_bytes(path: str | os.PathLike, data: bytes) -> Path:
    """Write ``data`` to ``path`` atomically (temporary file + rename), mode 0o666 & ~umask."""
    p = Path(path)
    try:
        p.parent.mkdir(parents=True, exist_ok=True)
        fd, tmp = tempfile.mkstemp(prefix=f".{p.name}.", suffix=".part", dir=p.parent)
    except OSError as err:
        raise BadInputError(f"cannot write {p}: {err.strerror or err}") from err
    try:
        with os.fdopen(fd, "wb") as fh:
            fh.write(data)
            fh.flush()
            os.fchmod(fh.fileno(), file_mode())  # mkstemp makes 0600; outputs follow the umask
        os.replace(tmp, p)
    except BaseException as err:  # also a signal: never leave the temporary file behind
        with contextlib.suppress(OSError):
            os.unlink(tmp)
        if isinstance(err, OSError):
            raise BadInputError(f"cannot write {p}: {err.strerror or err}") from err
        raise
    return p


def write_text(path: str | os.PathLike, text: str) -> Path:
    """Write ``text`` (UTF-8) to ``path`` atomically, mode 0o666 & ~umask."""
    return write_bytes(path, text.encode("utf-8"))



@contextlib.contextmanager
def replacing(path: str | os.PathLike) -> Iterator[Path]:
    """Yield a temporary path beside ``path`` (same suffix) for a writer that wants a file name;
    on success it replaces ``path``, on any failure or signal it is removed."""
    p = Path(path)
    p.parent.mkdir(parents=True, exist_ok=True)
    tmp = p.with_name(f".{p.stem}.{os.getpid()}.part{p.suffix}")
    try:
        yield tmp
        os.chmod(tmp, file_mode())
        os.replace(tmp, p)
    except BaseException as err:
        with contextlib.suppress(OSError):
            os.unlink(tmp)
        if isinstance(err, OSError):
            raise BadInputError(f"cannot write {p}: {err.strerror or err}") from err
        raise


def json_safe(obj: Any) -> Any:
    """``obj`` ready for strict JSON: numpy arrays and scalars made plain, NaN and inf as ``None``.

    Mappings get string keys; tuples become lists; anything else with an ``item()``
    (a numpy scalar) is unwrapped; other objects are returned as they are.
    """
    import numpy as np  # here: the command line imports this module at start, before it needs numpy

    if isinstance(obj, dict):
        return {str(k): json_safe(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [json_safe(v) for v in obj]
    if isinstance(obj, np.ndarray):
        return json_safe(obj.tolist())
    if isinstance(obj, (bool, np.bool_)):
        return bool(obj)
    if isinstance(obj, (int, np.integer)):
        return int(obj)
    if isinstance(obj, (float, np.floating)):
        x = float(obj)
        return x if math.isfinite(x) else None
    if hasattr(obj, "item") and callable(obj.item):
        return json_safe(obj.item())
    return obj
