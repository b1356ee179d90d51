"""ROS 2 message definitions without ROS: find ``.msg`` files, build rosbag2's schema text, parse it.

An MCAP schema of the ROS 2 profile (encoding ``ros2msg``) holds the *complete* message
definition: the top-level ``.msg`` text, then every type it depends on, transitively and
once each, each preceded by a line of 80 ``=`` and a line ``MSG: pkg/Type``. This module
builds that text exactly the way rosbag2's ``LocalMessageDefinitionSource`` does
(dependencies found with the same field-type pattern, visited depth first in sorted
order, the raw file text kept byte for byte), and parses such texts back into field
layouts for the CDR decoder (:mod:`hasel.io.cdr`).

Where ``.msg`` files are searched: every prefix of ``AMENT_PREFIX_PATH``, the Python
prefix (``sys.prefix``, where the ROS 2 wheels install ``share/<pkg>/msg``), the
workspace's colcon install space (``install/<pkg>``) and its source tree; the standard
``std_msgs/Header`` and ``builtin_interfaces/Time`` / ``Duration`` of Jazzy are built in
as a last resort so that the core can write logs on a machine without ROS.
"""
from __future__ import annotations

import json
import os
import re
import sys
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass
from functools import lru_cache
from pathlib import Path

from hasel.errors import BadInputError

__all__ = [
    "MessageDefinitionError", "FieldType", "Field", "Constant", "MsgSpec", "PRIMITIVE_FORMATS",
    "default_search_prefixes", "find_definition_file", "message_definition", "type_hash",
    "parse_msg", "parse_schema", "short_name", "full_name", "DELIMITER",
]

DELIMITER = "=" * 80
MAX_DEPTH = 50  # rosbag2's ROSBAG2_CPP_LOCAL_MESSAGE_DEFINITION_SOURCE_MAX_RECURSION_DEPTH

#: struct format and size of each fixed-size ROS 2 primitive as CDR serialises it.
PRIMITIVE_FORMATS: dict[str, tuple[str, int]] = {
    "bool": ("?", 1), "byte": ("B", 1), "char": ("B", 1), "int8": ("b", 1), "uint8": ("B", 1),
    "int16": ("h", 2), "uint16": ("H", 2), "int32": ("i", 4), "uint32": ("I", 4),
    "int64": ("q", 8), "uint64": ("Q", 8), "float32": ("f", 4), "float64": ("d", 8),
}
STRING_TYPES = ("string", "wstring")
# rosbag2's list: what its dependency scan skips (note: no wstring there; a wstring
# field would make rosbag2 look for "pkg/wstring" and fall back to IDL; we skip it too)
_RB2_PRIMITIVES = frozenset(PRIMITIVE_FORMATS) | {"string", "wstring"}

# rosbag2's MSG_FIELD_TYPE_REGEX: the type at the start of a line, an optional [..]
_DEP_RE = re.compile(r"(?:^|\n)\s*([a-zA-Z0-9_/]+)(?:\[[^\]]*\])?\s+")
_NAME = r"[A-Za-z][A-Za-z0-9_]*"
_TYPE_RE = re.compile(rf"^({_NAME}(?:/{_NAME}){{0,2}})(?:<=(\d+))?(?:\[(<=)?(\d*)\])?$")
_LINE_RE = re.compile(rf"^(\S+)\s+({_NAME})\s*(=)?")
_TYPENAME_RE = re.compile(rf"^({_NAME})/(?:({_NAME})/)?({_NAME})$")

_BUILTIN_TEXTS = {  # Jazzy's files, byte for byte (used only if no installed copy is found)
    "std_msgs/msg/Header": (
        "# Standard metadata for higher-level stamped data types.\n# This is generally used to "
        "communicate timestamped data\n# in a particular coordinate frame.\n\n# Two-integer "
        "timestamp that is expressed as seconds and nanoseconds.\nbuiltin_interfaces/Time stamp\n\n"
        "# Transform frame with which this data is associated.\nstring frame_id\n"),
    "builtin_interfaces/msg/Time": (
        "# This message communicates ROS Time defined here:\n# https://design.ros2.org/articles/"
        "clock_and_time.html\n\n# The seconds component, valid over all int32 values.\nint32 sec\n\n"
        "# The nanoseconds component, valid in the range [0, 1e9), to be added to the seconds "
        "component. \n# e.g.\n# The time -1.7 seconds is represented as {sec: -2, nanosec: 3e8}\n"
        "# The time 1.7 seconds is represented as {sec: 1, nanosec: 7e8}\nuint32 nanosec\n"),
    "builtin_interfaces/msg/Duration": (
        "# Duration defines a period between two time points.\n# Messages of this datatype are of "
        "ROS Time following this design:\n# https://design.ros2.org/articles/clock_and_time.html\n\n"
        "# The seconds component, valid over all int32 values.\nint32 sec\n\n# The nanoseconds "
        "component, valid in the range [0, 1e9), to be added to the seconds component. \n# e.g.\n"
        "# The duration -1.7 seconds is represented as {sec: -2, nanosec: 3e8}\n# The duration 1.7 "
        "seconds is represented as {sec: 1, nanosec: 7e8}\nuint32 nanosec\n"),
}


class MessageDefinitionError(BadInputError):
    """A message type cannot be found, or its definition cannot be parsed."""


# --------------------------------------------------------------------------- names


def _split_type_name(type_name: str) -> tuple[str, str, str]:
    m = _TYPENAME_RE.match(type_name)
    if m is None:
        raise MessageDefinitionError(
            f"invalid message type name {type_name!r}: expected 'pkg/msg/Type' or 'pkg/Type'")
    return m.group(1), m.group(2) or "msg", m.group(3)


def short_name(type_name: str) -> str:
    """``pkg/msg/Type`` or ``pkg/Type`` -> ``pkg/Type`` (the key of parsed definitions)."""
    pkg, _, name = _split_type_name(type_name)
    return f"{pkg}/{name}"


def full_name(type_name: str) -> str:
    """``pkg/Type`` or ``pkg/msg/Type`` -> ``pkg/msg/Type`` (the name rosbag2 gives a schema)."""
    pkg, ns, name = _split_type_name(type_name)
    return f"{pkg}/{ns}/{name}"


# --------------------------------------------------------------------------- search


def _repo_root() -> Path | None:
    root = Path(__file__).resolve().parents[3]  # src/hasel/io/msgdefs.py -> repo
    return root if (root / "src" / "hasel").is_dir() else None


def default_search_prefixes() -> list[Path]:
    """Where ``.msg`` files are looked for, in order.

    Returns
    -------
    list of Path
        Each prefix ``P`` is searched as ``P/share/<pkg>/msg/<Type>.msg`` and
        ``P/<pkg>/msg/<Type>.msg`` (a source tree): the prefixes of
        ``AMENT_PREFIX_PATH``, ``sys.prefix``, then the workspace's ``install/<pkg>``
        prefixes and its source root.
    """
    out: list[Path] = [Path(p) for p in os.environ.get("AMENT_PREFIX_PATH", "").split(os.pathsep) if p]
    out.append(Path(sys.prefix))
    root = _repo_root()
    if root is not None:
        install = root / "install"
        if install.is_dir():
            out += sorted(p for p in install.iterdir() if (p / "share").is_dir())
        out.append(root)
    seen: set[Path] = set()
    unique = []
    for p in out:
        if p not in seen:
            seen.add(p)
            unique.append(p)
    return unique


def _candidates(prefix: Path, pkg: str, ns: str, name: str, ext: str) -> tuple[Path, Path]:
    return prefix / "share" / pkg / ns / f"{name}{ext}", prefix / pkg / ns / f"{name}{ext}"


def find_definition_file(type_name: str, search_prefixes: Sequence[str | os.PathLike[str]] | None = None,
                         ext: str = ".msg") -> Path | None:
    """The first ``<Type>.msg`` (or ``ext``) file of ``type_name`` found, or None."""
    pkg, ns, name = _split_type_name(type_name)
    prefixes = default_search_prefixes() if search_prefixes is None else [Path(p) for p in search_prefixes]
    for prefix in prefixes:
        for cand in _candidates(prefix, pkg, ns, name, ext):
            if cand.is_file():
                return cand
    return None


@lru_cache(maxsize=512)
def _read_text_cached(path: str, mtime_ns: int) -> str:
    del mtime_ns  # part of the cache key only
    with open(path, encoding="utf-8", newline="") as f:
        return f.read()


def _load_text(type_name: str, prefixes: Sequence[Path] | None) -> str:
    path = find_definition_file(type_name, prefixes)
    if path is not None:
        return _read_text_cached(str(path), path.stat().st_mtime_ns)
    builtin = _BUILTIN_TEXTS.get(full_name(type_name))
    if builtin is not None:
        return builtin
    pkg, ns, name = _split_type_name(type_name)
    looked = prefixes if prefixes is not None else default_search_prefixes()
    raise MessageDefinitionError(
        f"no definition of {type_name!r}: looked for {ns}/{name}.msg of package {pkg!r} under "
        f"{', '.join(str(p) for p in looked) or '(no search prefixes)'} "
        "(build the workspace or source its setup, or set AMENT_PREFIX_PATH)")


def _dependencies(text: str, package: str) -> list[str]:
    deps: set[str] = set()
    for m in _DEP_RE.finditer(text):
        t = m.group(1)
        if t in _RB2_PRIMITIVES:
            continue
        deps.add(t if "/" in t else f"{package}/{t}")
    return sorted(deps)


def message_definition(type_name: str, search_prefixes: Sequence[str | os.PathLike[str]] | None = None) -> str:
    """The complete ``ros2msg`` schema text of ``type_name``, as rosbag2 writes it.

    Parameters
    ----------
    type_name : str
        ``pkg/msg/Type`` (or ``pkg/Type``), e.g. ``"hasel_msgs/msg/Stroke"``.
    search_prefixes : sequence of path, optional
        Install prefixes to search (``P/share/<pkg>/msg/<Type>.msg``); default
        :func:`default_search_prefixes`.

    Returns
    -------
    str
        The top-level ``.msg`` text, then for each transitive dependency (depth first,
        dependencies of a type in sorted order, each type once) ``"\\n"``, a line of 80
        ``=``, a line ``MSG: <name as written in the field>`` and that type's text.

    Raises
    ------
    MessageDefinitionError
        If a type (the top level or a dependency) is not found: names the type and the
        places searched; or if the dependency chain is deeper than rosbag2 allows.
    """
    prefixes = None if search_prefixes is None else [Path(p) for p in search_prefixes]
    seen: set[str] = set()

    def append(name: str, depth: int) -> str:
        if depth <= 0:
            raise MessageDefinitionError(f"reached maximum recursion depth resolving definition of {type_name}")
        text = _load_text(name, prefixes)
        out = text
        for dep in _dependencies(text, _split_type_name(name)[0]):
            if dep not in seen:
                seen.add(dep)
                try:
                    out += "\n" + DELIMITER + "\n" + "MSG: " + dep + "\n" + append(dep, depth - 1)
                except MessageDefinitionError as err:
                    raise MessageDefinitionError(f"{err} (needed by {name})") from None
        return out

    return append(type_name, MAX_DEPTH)


def type_hash(type_name: str, search_prefixes: Sequence[str | os.PathLike[str]] | None = None) -> str:
    """The ``RIHS01_...`` type-description hash rosidl generated for ``type_name``, or ``""``.

    Read from the ``<Type>.json`` file installed beside the ``.msg`` (what rosbag2 Jazzy
    stores as the channel's ``topic_type_hash``).
    """
    path = find_definition_file(type_name, search_prefixes, ext=".json")
    if path is None:
        return ""
    try:
        data = json.loads(_read_text_cached(str(path), path.stat().st_mtime_ns))
        want = full_name(type_name)
        for entry in data.get("type_hashes", []):
            if entry.get("type_name") == want:
                return str(entry.get("hash_string", ""))
    except (ValueError, AttributeError, TypeError):
        return ""
    return ""


# --------------------------------------------------------------------------- parsing


@dataclass(frozen=True)
class FieldType:
    """Type of a field.

    Attributes
    ----------
    base : str
        A primitive (``float64``...), ``string``/``wstring``, or a message ``pkg/Type``.
    is_array : bool
        True for ``T[N]``, ``T[]`` and ``T[<=N]``.
    array_size : int or None
        ``N`` of ``T[N]`` or ``T[<=N]``; None for an unbounded sequence.
    is_upper_bound : bool
        True for a bounded sequence ``T[<=N]`` (serialised like ``T[]``).
    string_bound : int or None
        ``N`` of ``string<=N`` (serialised like ``string``).
    """

    base: str
    is_array: bool = False
    array_size: int | None = None
    is_upper_bound: bool = False
    string_bound: int | None = None

    @property
    def is_primitive(self) -> bool:
        """A fixed-size primitive (not a string, not a message)."""
        return self.base in PRIMITIVE_FORMATS

    @property
    def is_string(self) -> bool:
        """``string`` or ``wstring`` (bounded or not)."""
        return self.base in STRING_TYPES

    @property
    def is_message(self) -> bool:
        """A nested message type."""
        return not (self.is_primitive or self.is_string)

    @property
    def is_fixed_array(self) -> bool:
        """``T[N]``: no length prefix on the wire."""
        return self.is_array and self.array_size is not None and not self.is_upper_bound


@dataclass(frozen=True)
class Field:
    """A field of a message: ``name`` and :class:`FieldType`."""

    name: str
    type: FieldType


@dataclass(frozen=True)
class Constant:
    """A constant of a message (not serialised): ``type``, ``name``, raw ``value`` text."""

    type: str
    name: str
    value: str


@dataclass(frozen=True)
class MsgSpec:
    """A parsed message definition: ``name`` (``pkg/Type``), ``fields``, ``constants``."""

    name: str
    fields: tuple[Field, ...]
    constants: tuple[Constant, ...] = ()


def _parse_type(text: str, package: str, where: str) -> FieldType:
    m = _TYPE_RE.match(text)
    if m is None:
        raise MessageDefinitionError(f"{where}: invalid type {text!r}")
    base, sbound, upper, size = m.group(1), m.group(2), m.group(3), m.group(4)
    is_array = "[" in text
    if sbound is not None and base not in STRING_TYPES:
        raise MessageDefinitionError(f"{where}: only strings can be bounded with <=, got {text!r}")
    if upper and not size:
        raise MessageDefinitionError(f"{where}: bounded sequence without a bound in {text!r}")
    parts = base.split("/")
    if len(parts) == 1:
        if base not in PRIMITIVE_FORMATS and base not in STRING_TYPES:
            base = f"{package}/{base}"  # relative name: same package
    else:
        base = f"{parts[0]}/{parts[-1]}"
    return FieldType(base=base, is_array=is_array, array_size=int(size) if size else None,
                     is_upper_bound=bool(upper), string_bound=int(sbound) if sbound else None)


def parse_msg(text: str, name: str) -> MsgSpec:
    """Parse one ``.msg`` text of type ``name`` (``pkg/Type`` or ``pkg/msg/Type``).

    Raises
    ------
    MessageDefinitionError
        On a line that is neither a comment, a field nor a constant (e.g. the ``---`` of a
        service definition).
    """
    key = short_name(name)
    package = key.split("/")[0]
    fields: list[Field] = []
    constants: list[Constant] = []
    for lineno, raw in enumerate(text.splitlines(), start=1):
        line = raw.strip()
        if not line or line.startswith("#"):
            continue
        where = f"{key} line {lineno}"
        if re.fullmatch(r"-{3,}", line):
            raise MessageDefinitionError(f"{where}: '---' separator: a service or action definition, not a message")
        m = _LINE_RE.match(line)
        if m is None:
            raise MessageDefinitionError(f"{where}: cannot parse {raw.strip()!r}")
        ftype = _parse_type(m.group(1), package, where)
        if m.group(3):
            if ftype.is_array or ftype.is_message:
                raise MessageDefinitionError(f"{where}: constants must be primitives or strings")
            value = line[m.end():].strip()
            constants.append(Constant(ftype.base, m.group(2), value))
        else:
            fields.append(Field(m.group(2), ftype))
    return MsgSpec(key, tuple(fields), tuple(constants))


_SECTION_SPLIT = re.compile(r"^={3,}\s*$", re.MULTILINE)
_MSG_LINE = re.compile(r"^\s*MSG:\s*(\S+)\s*$", re.MULTILINE)


def parse_schema(schema_name: str, text: str) -> dict[str, MsgSpec]:
    """Parse a complete ``ros2msg`` schema text into ``{"pkg/Type": MsgSpec}``.

    The first section is ``schema_name``; each later section names its type on a
    ``MSG:`` line. ``builtin_interfaces/Time`` and ``Duration`` are added if the text
    lacks them (some writers omit them).

    Raises
    ------
    MessageDefinitionError
        If a section cannot be parsed, has no ``MSG:`` line, or a field's type is
        defined nowhere in the text.
    """
    specs: dict[str, MsgSpec] = {}
    sections = _SECTION_SPLIT.split(text)
    for i, section in enumerate(sections):
        name = schema_name
        if i > 0:
            m = _MSG_LINE.search(section)
            if m is None:
                if not section.strip():
                    continue
                if re.search(r"^\s*IDL:", section, re.MULTILINE):
                    raise MessageDefinitionError(f"schema {schema_name!r}: IDL sections are not supported")
                raise MessageDefinitionError(f"schema {schema_name!r}: section {i} has no 'MSG: pkg/Type' line")
            name = m.group(1)
            section = section[:m.start()] + section[m.end():]
        spec = parse_msg(section, name)
        specs.setdefault(spec.name, spec)
    for builtin in ("builtin_interfaces/msg/Time", "builtin_interfaces/msg/Duration"):
        key = short_name(builtin)
        if key not in specs:
            specs[key] = parse_msg(_BUILTIN_TEXTS[builtin], builtin)
    root = short_name(schema_name)
    _check_resolved(specs, root)
    return specs


def resolve_type(specs: Mapping[str, MsgSpec], base: str) -> MsgSpec:
    """The spec of a nested type ``base`` (``pkg/Type``); ``pkg/Header`` falls back to std_msgs."""
    spec = specs.get(base)
    if spec is None and base.endswith("/Header"):
        spec = specs.get("std_msgs/Header")
    if spec is None:
        raise MessageDefinitionError(f"type {base!r} is used but not defined in the schema")
    return spec


def _check_resolved(specs: Mapping[str, MsgSpec], root: str) -> None:
    stack: list[tuple[str, tuple[str, ...]]] = [(root, ())]
    while stack:
        name, chain = stack.pop()
        if name in chain:
            raise MessageDefinitionError(f"recursive message definition: {' -> '.join(chain + (name,))}")
        spec = resolve_type(specs, name)
        for f in spec.fields:
            if f.type.is_message:
                stack.append((resolve_type(specs, f.type.base).name, chain + (name,)))


def iter_dependencies(specs: Mapping[str, MsgSpec], root: str) -> Iterable[str]:
    """Names of ``root`` and every type it uses (each once)."""
    seen: set[str] = set()
    stack = [root]
    while stack:
        name = resolve_type(specs, stack.pop()).name
        if name in seen:
            continue
        seen.add(name)
        yield name
        stack.extend(f.type.base for f in specs[name].fields if f.type.is_message)
