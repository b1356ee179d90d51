"""CDR: the generated field extractor against mcap_ros2's serializer and real rosbag2 data."""
from __future__ import annotations

import struct

from realdata import datasets_dir

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from mcap.reader import make_reader
from mcap_ros2._dynamic import serialize_dynamic
from mcap_ros2.decoder import DecoderFactory

from hasel.io.cdr import CdrError, Extractor, compile_extractor, numeric_fields
from hasel.io.msgdefs import MessageDefinitionError, message_definition, parse_schema

from cdrwrite import encode

ROSBAG2 = datasets_dir() / "rosbag2"
SEP = "\n" + "=" * 80 + "\n"
COMPLEX = ("std_msgs/Header header\nbool flag\nuint8 small\nfloat64 value\nint64[3] fixed\nfloat32[<=5] bounded\n"
           "Inner inner\nInner[] inners\nstring[] names\nuint64 big\nchar c\nbyte b\nint8 i8\nuint16 u16\n"
           "float64[] tail\n"
           + SEP + "MSG: pkg/Inner\nfloat32 x\nint16[] seq\nstring name\n"
           + SEP + "MSG: std_msgs/Header\nbuiltin_interfaces/Time stamp\nstring frame_id\n"
           + SEP + "MSG: builtin_interfaces/Time\nint32 sec\nuint32 nanosec\n")
f32 = st.floats(width=32, allow_nan=False, allow_infinity=False)
f64 = st.floats(allow_nan=False, allow_infinity=False)
inner = st.fixed_dictionaries({"x": f32, "seq": st.lists(st.integers(-2**15, 2**15 - 1), max_size=4),
                               "name": st.text(max_size=6)})
complex_msg = st.fixed_dictionaries({
    "header": st.fixed_dictionaries({"stamp": st.fixed_dictionaries({
        "sec": st.integers(0, 2**31 - 1), "nanosec": st.integers(0, 10**9 - 1)}), "frame_id": st.text(max_size=9)}),
    "flag": st.booleans(), "small": st.integers(0, 255), "value": f64,
    "fixed": st.lists(st.integers(-2**63, 2**63 - 1), min_size=3, max_size=3),
    "bounded": st.lists(f32, max_size=5), "inner": inner, "inners": st.lists(inner, max_size=3),
    "names": st.lists(st.text(max_size=4), max_size=3), "big": st.integers(0, 2**64 - 1),
    "c": st.integers(0, 127), "b": st.integers(0, 255), "i8": st.integers(-128, 127), "u16": st.integers(0, 2**16 - 1),
    "tail": st.lists(f64, max_size=7),
})
SCALARS = ["header.stamp.sec", "header.stamp.nanosec", "flag", "small", "value", "inner.x", "big", "c", "b", "i8",
           "u16"]


def _get(msg, path):
    for part in path.split("."):
        msg = msg[part]
    return msg


@settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(complex_msg)
def test_extractor_reads_what_mcap_ros2_serialised(msg):
    ref = serialize_dynamic("pkg/msg/Complex", COMPLEX)["pkg/msg/Complex"](msg)
    paths = SCALARS + ["fixed[0]", "fixed[2]", "bounded", "tail", "inner.seq", "header.frame_id", "tail[1]"]
    ex = compile_extractor("pkg/msg/Complex", COMPLEX, paths)
    out = dict(zip(paths, ex(ref, 0, len(ref))))
    for p in SCALARS:
        assert out[p] == _get(msg, p), p
    assert out["fixed[0]"] == msg["fixed"][0] and out["fixed[2]"] == msg["fixed"][2]
    for name, dtype in (("bounded", "<f4"), ("tail", "<f8")):
        off, n = out[name]
        np.testing.assert_array_equal(np.frombuffer(ref, dtype, n, off), msg[name])
    off, n = out["inner.seq"]
    np.testing.assert_array_equal(np.frombuffer(ref, "<i2", n, off), msg["inner"]["seq"])
    assert out["header.frame_id"] == msg["header"]["frame_id"]
    if len(msg["tail"]) > 1:
        assert out["tail[1]"] == msg["tail"][1]
    else:
        assert np.isnan(out["tail[1]"])


def test_sample_batch_extraction_with_numpy_arrays():
    rng = np.random.default_rng(3)
    t = "hasel_msgs/msg/SampleBatch"
    text = message_definition(t)
    for counts in [(50, 50, 0, 0), (0, 3, 1, 2), (7, 0, 0, 9)]:
        arrays = [rng.normal(size=n) for n in counts]
        msg = {"header": {"stamp": {"sec": 5, "nanosec": 7}, "frame_id": "x" * int(rng.integers(0, 9))},
               "sample_period_s": 1e-4, "voltage_kv": arrays[0], "stroke_mm": arrays[1],
               "true_stroke_mm": arrays[2], "elapsed_us": arrays[3]}
        data = encode(t, msg)
        fields = ["voltage_kv", "stroke_mm", "true_stroke_mm", "elapsed_us"]
        ex = compile_extractor(t, text, ["sample_period_s"] + fields)
        r = ex(b"\x00" * 3 + data, 3, 3 + len(data))  # at an odd offset inside a larger buffer
        assert r[0] == 1e-4
        for (off, n), want in zip(r[1:], arrays):
            np.testing.assert_array_equal(np.frombuffer(b"\x00" * 3 + data, "<f8", n, off), want)


def test_big_endian_messages_decode():
    text = message_definition("hasel_msgs/msg/Stroke")
    payload = struct.pack(">iI", 3, 250) + struct.pack(">I", 4) + b"abc\x00"  # stamp, frame_id "abc"
    payload += b"\x00" * ((-len(payload)) % 8) + struct.pack(">d", 2.5) + struct.pack(">B", 2)
    data = b"\x00\x00\x00\x00" + payload
    ex = compile_extractor("hasel_msgs/msg/Stroke", text, ["header.stamp.sec", "header.stamp.nanosec", "stroke_mm",
                                                           "source"])
    assert ex(data, 0, len(data)) == (3, 250, 2.5, 2)


def test_truncated_or_foreign_messages_raise_cdr_error():
    t = "hasel_msgs/msg/SampleBatch"
    data = encode(t, {"header": {"frame_id": "abc"}, "voltage_kv": np.ones(5), "elapsed_us": np.ones(4)})
    ex = compile_extractor(t, message_definition(t), ["elapsed_us"])
    assert ex(data, 0, len(data))[0][1] == 4
    for cut in range(len(data)):
        with pytest.raises(CdrError):
            ex(data, 0, cut)
    with pytest.raises(CdrError, match="encapsulation"):
        ex(b"\x00\x07" + data[2:], 0, len(data))
    (off, n), = compile_extractor(t, message_definition(t), ["voltage_kv"])(data, 0, len(data))
    cpos = data.rindex(struct.pack("<I", 5), 0, off)  # the sequence's count, before its (aligned) elements
    assert n == 5 and off - 8 <= cpos <= off - 4
    huge = bytearray(data)
    huge[cpos:cpos + 4] = struct.pack("<I", 2**31)  # a count far past the end
    with pytest.raises(CdrError):
        ex(bytes(huge), 0, len(huge))


def test_unsupported_requests_name_the_fields():
    text = message_definition("hasel_msgs/msg/SampleBatch")
    specs = parse_schema("hasel_msgs/msg/SampleBatch", text)
    with pytest.raises(MessageDefinitionError, match=r"no field 'nope'.*numeric fields: header\.stamp\.sec"):
        Extractor(specs, "hasel_msgs/msg/SampleBatch", ["nope"])
    with pytest.raises(MessageDefinitionError, match="is a message"):
        Extractor(specs, "hasel_msgs/msg/SampleBatch", ["header"])
    assert numeric_fields(specs, "hasel_msgs/msg/SampleBatch") == [
        "header.stamp.sec", "header.stamp.nanosec", "sample_period_s", "voltage_kv[]", "stroke_mm[]",
        "true_stroke_mm[]", "elapsed_us[]"]
    with pytest.raises(MessageDefinitionError, match="inside arrays of messages"):
        compile_extractor("pkg/msg/Complex", COMPLEX, ["inners.x"])


def test_real_rosbag2_messages_decode_like_mcap_ros2():
    """Every numeric field of the BasicTypes and Arrays messages rosbag2 recorded."""
    with open(ROSBAG2 / "cdr_test_0.mcap", "rb") as f:
        reader = make_reader(f, decoder_factories=[DecoderFactory()])
        seen = 0
        for schema, _ch, message, decoded in reader.iter_decoded_messages():
            specs = parse_schema(schema.name, schema.data.decode())
            fields = [p for p in numeric_fields(specs, schema.name) if "char" not in p]
            ex = Extractor(specs, schema.name, [p.removesuffix("[]") for p in fields])
            got = ex(message.data, 0, len(message.data))
            for path, value, req in zip(fields, got, ex.requests):
                want = getattr(decoded, path.removesuffix("[]"))
                if req.kind == "array":
                    off, n = value
                    arr = np.frombuffer(message.data, req.dtype, n, off)
                    if isinstance(want, (bytes, bytearray)):
                        want = list(want)
                    np.testing.assert_array_equal(arr, np.asarray(want), err_msg=path)
                elif isinstance(want, float):
                    assert value == pytest.approx(want, rel=1e-7), path
                else:
                    assert value == want, path
            seen += 1
    assert seen == 7
