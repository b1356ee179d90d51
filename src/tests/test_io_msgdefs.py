"""Message definitions: rosbag2's schema text, byte for byte, and the .msg parser."""
from __future__ import annotations

import json
import sys
from pathlib import Path

from realdata import datasets_dir

REPO = Path(__file__).resolve().parents[2]  # the repository root

import pytest
from mcap.reader import make_reader

from hasel.io.msgdefs import (
    DELIMITER, MessageDefinitionError, message_definition, parse_msg, parse_schema, short_name, type_hash,
)

ROSBAG2 = datasets_dir() / "rosbag2"
SEP = "\n" + "=" * 80 + "\n"


def _recorded_schema(bag: str, type_name: str) -> str:
    with open(ROSBAG2 / bag, "rb") as f:
        summary = make_reader(f).get_summary()
    assert summary is not None
    return next(s.data.decode() for s in summary.schemas.values() if s.name == type_name)


def _share_tree_from(text: str, type_name: str, root: Path) -> None:
    """Write each section of a recorded rosbag2 schema back as a .msg file under root/share."""
    sections = text.split(SEP)
    names = [type_name] + [s.split("\n", 1)[0].removeprefix("MSG: ") for s in sections[1:]]
    bodies = [sections[0]] + [s.split("\n", 1)[1] for s in sections[1:]]
    for name, body in zip(names, bodies):
        parts = name.split("/")
        pkg, typ = parts[0], parts[-1]
        d = root / "share" / pkg / "msg"
        d.mkdir(parents=True, exist_ok=True)
        (d / f"{typ}.msg").write_text(body, newline="")


@pytest.mark.parametrize("bag,type_name", [
    ("only_topics.mcap", "rcl_interfaces/msg/ParameterEvent"),
    ("only_topics.mcap", "rcl_interfaces/msg/Log"),
    ("cdr_test_0.mcap", "test_msgs/msg/Arrays"),
    ("bag_with_topics_and_service_events.mcap", "test_msgs/msg/Strings"),
])
def test_definition_text_matches_what_rosbag2_recorded(tmp_path, bag, type_name):
    recorded = _recorded_schema(bag, type_name)
    _share_tree_from(recorded, type_name, tmp_path)
    assert message_definition(type_name, [tmp_path]) == recorded


def test_dependencies_depth_first_sorted_each_once(tmp_path):
    share = tmp_path / "share"
    files = {
        "pkg/msg/Top.msg": "# top\npkg/Zeta z\nAlpha[] a   # relative name\nbuiltin_interfaces/Time t\n",
        "pkg/msg/Alpha.msg": "builtin_interfaces/Time stamp\nstring<=5 s\nfloat64[3] v [1.0, 2.0, 3.0]\n",
        "pkg/msg/Zeta.msg": "int32 K=3\nbuiltin_interfaces/Duration d",  # no final newline
        "builtin_interfaces/msg/Time.msg": "int32 sec\nuint32 nanosec\n",
        "builtin_interfaces/msg/Duration.msg": "int32 sec\nuint32 nanosec\n",
    }
    for rel, text in files.items():
        (share / rel).parent.mkdir(parents=True, exist_ok=True)
        (share / rel).write_text(text)
    # rosbag2: deps of a type in sorted order (std::set), visited depth first, each once
    expected = (files["pkg/msg/Top.msg"]
                + SEP + "MSG: builtin_interfaces/Time\n" + files["builtin_interfaces/msg/Time.msg"]
                + SEP + "MSG: pkg/Alpha\n" + files["pkg/msg/Alpha.msg"]
                + SEP + "MSG: pkg/Zeta\n" + files["pkg/msg/Zeta.msg"]
                + SEP + "MSG: builtin_interfaces/Duration\n" + files["builtin_interfaces/msg/Duration.msg"])
    assert message_definition("pkg/msg/Top", [tmp_path]) == expected


def _installed(rel: str) -> str:
    for prefix in (REPO / "install" / "hasel_msgs", Path(sys.prefix)):
        p = prefix / "share" / rel
        if p.is_file():
            return p.read_text()
    return (REPO / rel).read_text()


def test_sample_batch_definition_layout():
    text = message_definition("hasel_msgs/msg/SampleBatch")
    expected = (_installed("hasel_msgs/msg/SampleBatch.msg")
                + SEP + "MSG: std_msgs/Header\n" + _installed("std_msgs/msg/Header.msg")
                + SEP + "MSG: builtin_interfaces/Time\n" + _installed("builtin_interfaces/msg/Time.msg"))
    assert text == expected
    assert text.count(DELIMITER) == 2


def test_missing_type_names_the_type_and_where_it_looked(tmp_path):
    with pytest.raises(MessageDefinitionError, match=r"no definition of 'nopkg/msg/Nope'.*msg/Nope\.msg.*"
                       + str(tmp_path)):
        message_definition("nopkg/msg/Nope", [tmp_path])
    (tmp_path / "share/a/msg").mkdir(parents=True)
    (tmp_path / "share/a/msg/A.msg").write_text("b/Missing m\n")
    with pytest.raises(MessageDefinitionError, match=r"'b/Missing'.*needed by a/msg/A"):
        message_definition("a/msg/A", [tmp_path])
    with pytest.raises(MessageDefinitionError, match="invalid message type name"):
        message_definition("not a type")


def test_type_hash_is_rosidls():
    path = REPO / "install/hasel_msgs/share/hasel_msgs/msg/SampleBatch.json"
    if not path.is_file():
        pytest.skip("hasel_msgs not built")
    want = json.loads(path.read_text())["type_hashes"][0]["hash_string"]
    assert want.startswith("RIHS01_")
    assert type_hash("hasel_msgs/msg/SampleBatch") == want
    assert type_hash("nopkg/msg/Nope") == ""


def test_parser_handles_bounded_strings_defaults_constants_arrays():
    spec = parse_msg(_recorded_schema("bag_with_topics_and_service_events.mcap", "test_msgs/msg/Strings"),
                     "test_msgs/msg/Strings")
    assert [f.name for f in spec.fields][:2] == ["string_value", "string_value_default1"]
    assert len(spec.fields) == 12
    assert [c.name for c in spec.constants] == ["STRING_CONST"]
    assert spec.constants[0].value == '"Hello world!"'
    bounded = {f.name: f.type.string_bound for f in spec.fields}
    assert bounded["bounded_string_value"] == 22 and bounded["string_value"] is None
    arrays = parse_schema("test_msgs/msg/Arrays", _recorded_schema("cdr_test_0.mcap", "test_msgs/msg/Arrays"))
    root = arrays["test_msgs/Arrays"]
    kinds = {f.name: (f.type.base, f.type.array_size, f.type.is_fixed_array) for f in root.fields}
    assert kinds["basic_types_values"] == ("test_msgs/BasicTypes", 3, True)
    assert kinds["uint64_values_default"] == ("uint64", 3, True)
    assert "test_msgs/Constants" in arrays and len(arrays["test_msgs/Constants"].constants) == 13
    seq = parse_msg("float64[<=4] a\nstring<=3[] b\nint8[] c\n", "p/msg/T")
    assert [(f.type.is_upper_bound, f.type.array_size, f.type.string_bound) for f in seq.fields] == [
        (True, 4, None), (False, None, 3), (False, None, None)]


def test_parser_rejects_service_definitions_and_garbage():
    with pytest.raises(MessageDefinitionError, match="'---'"):
        parse_msg("int32 a\n---\nint32 b\n", "p/srv/S")
    with pytest.raises(MessageDefinitionError, match="invalid type"):
        parse_msg("float64[x] a\n", "p/msg/T")
    with pytest.raises(MessageDefinitionError, match="not defined"):
        parse_schema("p/msg/T", "q/Other o\n")


def test_short_names():
    assert short_name("hasel_msgs/msg/Stroke") == "hasel_msgs/Stroke"
    assert short_name("test_msgs/BasicTypes") == "test_msgs/BasicTypes"
