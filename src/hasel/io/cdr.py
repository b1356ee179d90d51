"""ROS 2 CDR (XCDR1, as rmw_fastrtps writes it) without ROS: a fast field extractor.

Extractor: for a message type and the fields wanted (``"header.stamp.sec"``,
``"voltage_kv"``, ``"data[2]"``) it generates, once, a straight-line Python function that
walks the CDR bytes of one message to the last wanted field only, with the alignment
worked out at generation time wherever it is static and runs of fixed-size fields read
by one :func:`struct.unpack_from`. Primitive arrays come back as ``(byte offset, count)``
so that the caller can read them with :func:`numpy.frombuffer` without a copy per value.
Every length read from the data is bounded by the message's end, so damaged bytes give
:class:`CdrError`, never a hang or a huge allocation.

Alignment is relative to the start of the payload (after the 4-byte encapsulation
header); 8-byte types align to 8 (XCDR1). The toolkit never encodes CDR itself: the
recorder writes the bytes rclpy received.
"""
from __future__ import annotations

import math
import struct
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from typing import Any


from hasel.errors import DataFileError
from hasel.io.msgdefs import (
    PRIMITIVE_FORMATS, FieldType, MessageDefinitionError, MsgSpec, parse_schema, resolve_type, short_name,
)

__all__ = ["CdrError", "FieldRequest", "Extractor", "compile_extractor", "numeric_fields"]


class CdrError(DataFileError):
    """The bytes of a message do not decode with its schema."""


class _Overrun(Exception):
    pass


class ForeignMessage(Exception):
    """A message that the fast loop does not take (not CDR little endian)."""


def _str_at(mv: Any, start: int, n: int) -> str:
    if n <= 1:
        return ""
    return bytes(mv[start:start + n - 1]).decode("utf-8", "replace")


# --------------------------------------------------------------------------- requests


@dataclass(frozen=True)
class FieldRequest:
    """A wanted field, resolved against a message type.

    Attributes
    ----------
    path : str
        As asked, e.g. ``"header.stamp.sec"`` or ``"data[2]"``.
    kind : str
        ``"scalar"`` (a number), ``"string"``, ``"array"`` (a whole primitive array:
        the extractor yields ``offset, count``) or ``"element"`` (one element of a
        primitive array; NaN when the array is shorter).
    base : str
        The primitive type of the value (``"float64"``...), or ``"string"``.
    """

    path: str
    kind: str
    base: str

    @property
    def dtype(self) -> str:
        """numpy dtype (little-endian) of the values of an array request."""
        code, size = PRIMITIVE_FORMATS[self.base]
        return {"?": "?", "B": "u1", "b": "i1"}.get(code, f"<{code}")


def _parse_path(path: str) -> list[tuple[str, int | None]]:
    steps: list[tuple[str, int | None]] = []
    for part in path.split("."):
        idx: int | None = None
        name = part
        if part.endswith("]") and "[" in part:
            name, _, rest = part[:-1].partition("[")
            if not rest.isdigit():
                raise MessageDefinitionError(f"bad index in field {path!r}: use name[N] with N >= 0")
            idx = int(rest)
        if not name:
            raise MessageDefinitionError(f"bad field name {path!r}")
        steps.append((name, idx))
    return steps


def numeric_fields(specs: Mapping[str, MsgSpec], root: str, *, depth: int = 6) -> list[str]:
    """Paths of the numeric fields of ``root``: scalars as ``a.b``, primitive arrays as ``x[]``.

    Fields inside arrays of messages are not listed (the extractor does not reach them).
    """
    out: list[str] = []

    def walk(spec: MsgSpec, prefix: str, d: int) -> None:
        for f in spec.fields:
            t = f.type
            if t.is_primitive:
                out.append(prefix + f.name + ("[]" if t.is_array else ""))
            elif t.is_message and not t.is_array and d > 0:
                walk(resolve_type(specs, t.base), prefix + f.name + ".", d - 1)

    walk(resolve_type(specs, short_name(root)), "", depth)
    return out


# --------------------------------------------------------------------------- code generation


class _Gen:
    """Generates the walker of one message type for one byte order."""

    def __init__(self, specs: Mapping[str, MsgSpec], endian: str) -> None:
        self.specs = specs
        self.endian = endian
        self.lines: list[str] = []
        self.ns: dict[str, Any] = {"_Overrun": _Overrun, "_str": _str_at, "_NAN": math.nan}
        self.m, self.r = 8, 0  # (p - b) % m == r is known at this point of the code
        self.run_fmt = ""  # pending run of fixed-size fields (one unpack_from)
        self.run_vars: list[str] = []
        self.run_size = 0
        self.tmp = 0

    # -- helpers
    def unpacker(self, fmt: str) -> str:
        name = "_u" + "".join(c if c.isalnum() else "_" for c in fmt)
        if name not in self.ns:
            self.ns[name] = struct.Struct(self.endian + fmt).unpack_from
        return name

    def emit(self, line: str, indent: int) -> None:
        self.lines.append("    " * indent + line)

    def flush(self, indent: int) -> None:
        if self.run_size:
            if self.run_vars:
                u = self.unpacker(self.run_fmt)
                lhs = ", ".join(self.run_vars) + ("," if len(self.run_vars) == 1 else "")
                self.emit(f"{lhs} = {u}(mv, p)", indent)
            self.emit(f"p += {self.run_size}", indent)
        self.run_fmt, self.run_vars, self.run_size = "", [], 0

    def align(self, a: int, indent: int, *, static_ok: bool = True) -> None:
        """Align p to ``a`` bytes; within a run if the padding is known now."""
        if a <= 1:
            return
        if a <= self.m and static_ok:
            pad = (-self.r) % a
            if pad:
                self.run_fmt += f"{pad}x"
                self.run_size += pad
                self.r = (self.r + pad) % self.m
            return
        self.flush(indent)
        self.emit(f"p += (b - p) & {a - 1}", indent)
        self.m, self.r = a, 0

    def advance_static(self, size: int) -> None:
        self.r = (self.r + size) % self.m

    def forget(self, m: int = 1) -> None:
        """After a dynamic-size item: only (p - b) % m == 0 is known."""
        self.m, self.r = m, 0

    def read_u32(self, var: str, indent: int) -> None:
        self.align(4, indent)
        self.flush(indent)
        self.emit(f"{var} = {self.unpacker('I')}(mv, p)[0]", indent)
        self.emit("p += 4", indent)
        self.advance_static(4)

    def new_tmp(self) -> str:
        self.tmp += 1
        return f"n{self.tmp}"

    # -- walking
    def walk(self, spec: MsgSpec, wanted: dict[tuple[str, ...], list[tuple[int | None, str, str]]],
             prefix: tuple[str, ...], remaining: list[int], indent: int) -> bool:
        """Emit code for the fields of ``spec``; returns True once every wanted value is read."""
        if not spec.fields:
            self.run_fmt += "x"
            self.run_size += 1
            self.advance_static(1)
            return remaining[0] == 0
        for f in spec.fields:
            if remaining[0] == 0:
                return True
            key = prefix + (f.name,)
            asks = wanted.get(key, [])
            sub_wanted = any(k[:len(key)] == key and len(k) > len(key) for k in wanted)
            self.field(f.type, key, asks, sub_wanted, wanted, remaining, indent)
        return remaining[0] == 0

    def field(self, t: FieldType, key: tuple[str, ...], asks: list[tuple[int | None, str, str]],
              sub_wanted: bool, wanted: dict[tuple[str, ...], list[tuple[int | None, str, str]]],
              remaining: list[int], indent: int) -> None:
        name = ".".join(key)
        if t.is_primitive and not t.is_array:
            code, size = PRIMITIVE_FORMATS[t.base]
            self.align(size, indent)
            if asks:
                self.run_fmt += code
                self.run_vars.append(asks[0][2])
                remaining[0] -= 1
            else:
                self.run_fmt += f"{size}x"
            self.run_size += size
            self.advance_static(size)
            return
        if t.is_primitive and t.is_fixed_array:
            code, size = PRIMITIVE_FORMATS[t.base]
            n = int(t.array_size or 0)
            if n:
                self.align(size, indent)
            if asks:
                self.flush(indent)
                for idx, kind, var in asks:
                    if kind == "array":
                        self.emit(f"{var} = (p, {n})", indent)
                    elif idx is not None and idx < n:
                        self.emit(f"{var} = {self.unpacker(code)}(mv, p + {idx * size})[0]", indent)
                    else:
                        self.emit(f"{var} = _NAN", indent)
                remaining[0] -= len(asks)
            self.run_fmt += f"{n * size}x" if n else ""
            self.run_size += n * size
            self.advance_static(n * size)
            return
        if t.is_primitive:  # sequence
            code, size = PRIMITIVE_FORMATS[t.base]
            cnt = self.new_tmp()
            self.read_u32(cnt, indent)
            if size > 1:
                if size <= self.m:
                    pad = (-self.r) % size
                    if pad:
                        self.emit(f"if {cnt}: p += {pad}", indent)
                else:
                    self.emit(f"if {cnt}: p += (b - p) & {size - 1}", indent)
            for idx, kind, var in asks:
                if kind == "array":
                    self.emit(f"{var} = (p, {cnt})", indent)
                else:
                    self.emit(f"{var} = {self.unpacker(code)}(mv, p + {idx * size})[0] "
                              f"if {idx} < {cnt} else _NAN", indent)
            remaining[0] -= len(asks)
            self.emit(f"p += {size} * {cnt}", indent)
            k = min(self.m, size)
            while k > 1 and self.r % k:
                k //= 2
            self.forget(k)
            return
        if t.is_string and not t.is_array:
            if t.base == "wstring":
                raise MessageDefinitionError(f"field {name!r}: wstring is not supported")
            cnt = self.new_tmp()
            self.read_u32(cnt, indent)
            for _, _, var in asks:
                self.emit(f"{var} = _str(mv, p, {cnt})", indent)
            remaining[0] -= len(asks)
            self.emit(f"p += {cnt}", indent)
            self.forget()
            return
        if t.is_string:  # array of strings
            if t.base == "wstring":
                raise MessageDefinitionError(f"field {name!r}: wstring[] is not supported")
            if asks:
                raise MessageDefinitionError(f"field {name!r}: arrays of strings are not numeric")
            cnt = self.count(t, indent)
            self.emit(f"if {cnt} * 4 > end - p: raise _Overrun", indent)
            self.emit(f"for _ in range({cnt}):", indent)
            self.emit("p += (b - p) & 3", indent + 1)
            self.emit(f"p += 4 + {self.unpacker('I')}(mv, p)[0]", indent + 1)
            self.forget()
            return
        # nested message
        spec = resolve_type(self.specs, t.base)
        if not t.is_array:
            if asks:
                raise MessageDefinitionError(
                    f"field {name!r} is a message ({spec.name}): ask for one of its numeric fields")
            if sub_wanted:
                self.walk(spec, wanted, key, remaining, indent)
            else:
                self.walk(spec, {}, key, [-1], indent)
            return
        if asks or sub_wanted:
            raise MessageDefinitionError(f"field {name!r}: fields inside arrays of messages are not supported")
        cnt = self.count(t, indent)
        self.flush(indent)
        self.emit(f"if {cnt} > end - p: raise _Overrun", indent)
        self.emit(f"for _ in range({cnt}):", indent)
        self.forget()
        body_start = len(self.lines)
        self.walk(spec, {}, key, [-1], indent + 1)
        self.flush(indent + 1)
        if len(self.lines) == body_start:
            self.emit("pass", indent + 1)
        self.forget()

    def count(self, t: FieldType, indent: int) -> str:
        if t.is_fixed_array:
            self.flush(indent)
            cnt = self.new_tmp()
            self.emit(f"{cnt} = {int(t.array_size or 0)}", indent)
            return cnt
        cnt = self.new_tmp()
        self.read_u32(cnt, indent)
        self.flush(indent)
        return cnt


def _walker(specs: Mapping[str, MsgSpec], root: str, requests: Sequence[tuple[str, FieldRequest]],
            endian: str, indent: int) -> tuple[list[str], dict[str, Any]]:
    """Lines that walk one message at ``o``..``end`` of ``mv``, leaving request i in ``v{i}``."""
    gen = _Gen(specs, endian)
    wanted: dict[tuple[str, ...], list[tuple[int | None, str, str]]] = {}
    for i, (path, req) in enumerate(requests):
        steps = _parse_path(path)
        key = tuple(s for s, _ in steps)
        wanted.setdefault(key, []).append((steps[-1][1], req.kind, f"v{i}"))
    gen.emit("b = o + 4", indent)
    gen.emit("p = b", indent)
    gen.walk(resolve_type(specs, root), wanted, (), [len(requests)], indent)
    gen.flush(indent)
    gen.emit("if p > end: raise _Overrun", indent)
    return gen.lines, gen.ns


def _compile(src: str, ns: dict[str, Any], fname: str, label: str) -> Callable[..., Any]:
    ns = dict(ns)
    exec(compile(src, f"<cdr {label}>", "exec"), ns)  # noqa: S102 - generated from parsed types only
    fn = ns[fname]
    fn.__source__ = src
    return fn  # type: ignore[no-any-return]


def _generate(specs: Mapping[str, MsgSpec], root: str, requests: Sequence[tuple[str, FieldRequest]],
              endian: str, fname: str) -> Callable[..., tuple[Any, ...]]:
    lines, ns = _walker(specs, root, requests, endian, 1)
    lines.append("    return (" + "".join(f"v{i}, " for i in range(len(requests))) + ")")
    src = f"def {fname}(mv, o, end):\n" + "\n".join(lines) + "\n"
    return _compile(src, ns, fname, f"{root} {endian}")


def _classify(specs: Mapping[str, MsgSpec], root: str, path: str) -> FieldRequest:
    spec = resolve_type(specs, root)
    steps = _parse_path(path)
    for depth, (name, idx) in enumerate(steps):
        fld = next((f for f in spec.fields if f.name == name), None)
        if fld is None:
            known = ", ".join(numeric_fields(specs, root)) or "(none)"
            raise MessageDefinitionError(
                f"no field {'.'.join(s for s, _ in steps[:depth + 1])!r} in {short_name(root)}; "
                f"numeric fields: {known}")
        last = depth == len(steps) - 1
        t = fld.type
        if t.is_message:
            if t.is_array:
                raise MessageDefinitionError(f"field {path!r}: fields inside arrays of messages are not supported")
            if idx is not None:
                raise MessageDefinitionError(f"field {name!r} of {path!r} is not an array")
            if last:
                raise MessageDefinitionError(
                    f"field {path!r} is a message ({resolve_type(specs, t.base).name}); numeric fields: "
                    + ", ".join(path + "." + p for p in numeric_fields(specs, t.base)))
            spec = resolve_type(specs, t.base)
            continue
        if not last:
            raise MessageDefinitionError(f"field {name!r} of {path!r} is not a message")
        if t.is_string:
            if t.is_array or idx is not None:
                raise MessageDefinitionError(f"field {path!r}: arrays of strings are not supported")
            return FieldRequest(path, "string", "string")
        if idx is not None:
            if not t.is_array:
                raise MessageDefinitionError(f"field {name!r} of {path!r} is not an array")
            return FieldRequest(path, "element", t.base)
        return FieldRequest(path, "array" if t.is_array else "scalar", t.base)
    raise MessageDefinitionError(f"empty field path {path!r}")


class Extractor:
    """Reads chosen fields out of CDR messages of one type.

    Call ``extractor(buf, start, end)`` with a buffer (bytes, bytearray or memoryview)
    holding one serialised message (with its 4-byte encapsulation header) at
    ``buf[start:end]``; returns a tuple with one entry per request: a number, a str,
    or for ``"array"`` requests a tuple ``(byte offset in buf, count)``.
    """

    def __init__(self, specs: Mapping[str, MsgSpec], root: str, paths: Sequence[str]) -> None:
        self.root = short_name(root)
        self.specs = specs
        paths = list(dict.fromkeys(paths))
        self.paths = tuple(paths)
        self.requests = tuple(_classify(specs, self.root, p) for p in paths)
        reqs = list(zip(paths, self.requests))
        self._le = _generate(specs, self.root, reqs, "<", "_walk_le")
        self._be: Callable[..., tuple[Any, ...]] | None = None
        self._reqs = reqs

    def _big_endian(self) -> Callable[..., tuple[Any, ...]]:
        if self._be is None:
            self._be = _generate(self.specs, self.root, self._reqs, ">", "_walk_be")
        return self._be

    def __call__(self, buf: Any, start: int, end: int) -> tuple[Any, ...]:
        """Decode the requested fields of the message at ``buf[start:end]``.

        Raises
        ------
        CdrError
            If the message is too short for its type or its encapsulation is not CDR.
        """
        if end - start < 4:
            raise CdrError(f"{self.root} message of {end - start} bytes: shorter than the CDR header")
        kind = buf[start + 1]
        try:
            if buf[start] == 0 and kind == 1:
                return self._le(buf, start, end)
            if buf[start] == 0 and kind == 0:
                return self._big_endian()(buf, start, end)
        except (_Overrun, struct.error, IndexError, ValueError) as err:
            raise CdrError(f"{self.root} message of {end - start} bytes is truncated or corrupt") from err
        raise CdrError(f"{self.root} message: unsupported CDR encapsulation 0x{buf[start]:02x}{kind:02x}")

    def make_loop(self, sink_args: Sequence[str], sink_lines: Sequence[str]) -> Callable[..., None]:
        """A function ``loop(buf, mv, items, *sinks)`` decoding many CDR_LE messages in one call.

        ``items`` holds ``(log_time, publish_time, sequence, start, end)`` per message;
        after each message the ``sink_lines`` run with ``v{i}`` (request i) and ``lt``
        (log time) set, calling the sinks passed as ``sink_args``. Raises
        :class:`ForeignMessage` at the first message that is not CDR_LE, and the walker's
        exceptions on damage: the caller rolls back and takes the per-message path.
        """
        lines, ns = _walker(self.specs, self.root, self._reqs, "<", 2)
        ns["ForeignMessage"] = ForeignMessage
        head = ["def _loop(buf, mv, items, " + ", ".join(sink_args) + "):",
                "    for lt, _pt, _sq, o, end in items:",
                "        if buf[o] != 0 or buf[o + 1] != 1: raise ForeignMessage"]
        src = "\n".join(head + lines + ["        " + x for x in sink_lines]) + "\n"
        return _compile(src, ns, "_loop", f"{self.root} loop")

    @property
    def little_endian(self) -> Callable[..., tuple[Any, ...]]:
        """The raw generated walker for CDR_LE messages (no checks; raises on damage)."""
        return self._le

    @property
    def source(self) -> str:
        """The generated code (for inspection)."""
        return str(self._le.__source__)  # type: ignore[attr-defined]


def compile_extractor(type_name: str, schema_text: str, paths: Sequence[str]) -> Extractor:
    """An :class:`Extractor` of ``paths`` for messages of ``type_name`` with schema ``schema_text``."""
    return Extractor(parse_schema(type_name, schema_text), type_name, paths)
