"""Loading signals and markers from MCAP logs (ours and rosbag2's), and load_io on MCAP."""
from __future__ import annotations


from realdata import datasets_dir

import numpy as np
import pytest
from mcap.reader import make_reader
from mcap_ros2.decoder import DecoderFactory

from hasel.errors import BadInputError, DataFileError
from hasel.io import (
    Marker, Ros2McapWriter, list_topics, load_io, load_markers, load_signals, marker_segments,
)

from cdrwrite import encode

BATCH = "hasel_msgs/msg/SampleBatch"
ROSBAG2 = datasets_dir() / "rosbag2"


def _stamp(t_ns):
    return {"sec": t_ns // 10**9, "nanosec": t_ns % 10**9}


@pytest.fixture
def rng():
    return np.random.default_rng(5)


def test_batches_unroll_with_their_own_stamp_period_and_length(tmp_path, rng):
    path = tmp_path / "b.mcap"
    batches = []
    with Ros2McapWriter(path, chunk_size=3000) as w:
        c = w.add_topic("/plant/batch", BATCH)
        t_ns = 2_000_000_000
        for i in range(40):
            n = int(rng.integers(0, 30))
            period = float(rng.choice([1e-4, 2e-4]))
            v = rng.normal(size=n)
            e = rng.normal(size=int(rng.integers(0, 5)))
            w.write(c, encode(BATCH, {"header": {"stamp": _stamp(t_ns)}, "sample_period_s": period,
                                      "voltage_kv": v, "elapsed_us": e}), 5, 5)
            batches.append((t_ns, period, v, e))
            t_ns += int(rng.integers(1, 9)) * 1_000_000
    sig = load_signals(path, ["/plant/batch.voltage_kv", "/plant/batch.elapsed_us",
                              "/plant/batch.sample_period_s"])
    v = sig["/plant/batch.voltage_kv"]
    assert v.batched and v.time_source == "header"
    np.testing.assert_array_equal(v.values, np.concatenate([b[2] for b in batches]))
    np.testing.assert_allclose(v.t_s, np.concatenate([b[0] * 1e-9 + b[1] * np.arange(b[2].size) for b in batches]),
                               rtol=0, atol=1e-12)
    e = sig["/plant/batch.elapsed_us"]
    np.testing.assert_array_equal(e.values, np.concatenate([b[3] for b in batches]))
    p = sig["/plant/batch.sample_period_s"]
    assert not p.batched and p.values.size == 40
    np.testing.assert_array_equal(p.t_s, [b[0] * 1e-9 for b in batches])


def test_messages_without_header_use_log_time_and_zero_stamps_too(tmp_path):
    path = tmp_path / "h.mcap"
    with Ros2McapWriter(path) as w:
        f = w.add_topic("/f", "std_msgs/msg/Float64")
        s = w.add_topic("/s", "hasel_msgs/msg/Stroke")
        for i in range(5):
            w.write(f, encode("std_msgs/msg/Float64", {"data": i * 0.5}), 10**9 * (i + 1), 0)
            w.write(s, encode("hasel_msgs/msg/Stroke", {"stroke_mm": float(i)}), 10**9 * (i + 1) + 7, 0)
    sig = load_signals(path, ["/f.data", "/s.stroke_mm", "/s.source"])
    assert sig["/f.data"].time_source == "log"
    np.testing.assert_array_equal(sig["/f.data"].t_s, [1.0, 2.0, 3.0, 4.0, 5.0])
    np.testing.assert_array_equal(sig["/f.data"].values, [0, 0.5, 1, 1.5, 2])
    assert sig["/s.stroke_mm"].time_source == "log"
    np.testing.assert_allclose(sig["/s.stroke_mm"].t_s, np.arange(1, 6) + 7e-9, rtol=0, atol=1e-12)
    assert [t.topic for t in list_topics(path)] == ["/f", "/s"]


def test_markers_become_segments(tmp_path):
    path = tmp_path / "m.mcap"
    marks = [(1.0, "precondition", True, -1.0), (2.0, "precondition", False, -1.0), (2.0, "chirp", True, 3.0),
             (5.0, "chirp", False, 3.0), (6.0, "chirp", True, 5.0), (9.0, "chirp", True, 7.0)]
    with Ros2McapWriter(path) as w:
        c = w.add_topic("/experiment/marker", "hasel_msgs/msg/ExperimentMarker")
        for t, label, start, off in marks:
            t_ns = int(t * 1e9)
            w.write(c, encode("hasel_msgs/msg/ExperimentMarker", {
                "header": {"stamp": _stamp(t_ns)}, "label": label, "signal": "paper", "offset_kv": off,
                "amplitude_kv": 0.5, "f0_hz": 0.1, "f1_hz": 20.0, "duration_s": 2.5, "start": start}), t_ns, t_ns)
    got = load_markers(path)
    assert [(m.t_s, m.label, m.start, m.offset_kv) for m in got] == marks
    assert got[0].signal == "paper" and got[0].f1_hz == 20.0
    segs = marker_segments(got, t_end_s=10.0)
    assert [(s.t_start_s, s.t_end_s, s.label, s.offset_kv) for s in segs] == [
        (1.0, 2.0, "precondition", -1.0), (2.0, 5.0, "chirp", 3.0), (6.0, 9.0, "chirp", 5.0),
        (9.0, 10.0, "chirp", 7.0)]
    assert [tuple(s.as_segment()) for s in segs][1] == (2.0, 5.0, 3.0)
    open_end = marker_segments([Marker(1.0, "x", "", 2.0, 0, 0, 0, 2.5, True)])
    assert [(s.t_start_s, s.t_end_s) for s in open_end] == [(1.0, 3.5)]


def _plant_log(path, rng, n_msgs=60, per=20, *, nan_at=None):
    with Ros2McapWriter(path) as w:
        c = w.add_topic("/plant/batch", BATCH)
        a = w.add_topic("/amp/applied", "hasel_msgs/msg/VoltageCommand")
        m = w.add_topic("/experiment/marker", "hasel_msgs/msg/ExperimentMarker")
        w.write(m, encode("hasel_msgs/msg/ExperimentMarker", {"header": {"stamp": _stamp(10**9)}, "label": "chirp",
                                                             "offset_kv": 4.0, "start": True}), 10**9, 10**9)
        for i in range(n_msgs):
            t_ns = 10**9 + i * per * 100_000
            v = np.sin(np.arange(i * per, (i + 1) * per) * 0.01) + 4
            y = 0.4 * v + rng.normal(scale=0.01, size=per)
            if nan_at == i:
                y[3] = np.nan
            w.write(c, encode(BATCH, {"header": {"stamp": _stamp(t_ns)}, "sample_period_s": 1e-4,
                                      "voltage_kv": v, "stroke_mm": y}), t_ns, t_ns)
            w.write(a, encode("hasel_msgs/msg/VoltageCommand", {"header": {"stamp": _stamp(t_ns)},
                                                               "applied_kv": v[0]}), t_ns, t_ns)


def test_load_io_mcap_same_topic_and_resampled_input(tmp_path, rng):
    path = tmp_path / "p.mcap"
    _plant_log(path, rng)
    d = load_io(path)
    assert d.n == 1200 and d.notes == () and d.input_name == "/plant/batch.voltage_kv"
    assert d.sample_rate_hz == pytest.approx(1e4)
    np.testing.assert_allclose(d.u, np.sin(np.arange(1200) * 0.01) + 4)
    assert d.segments == [(1.0, pytest.approx(d.t_s[-1]), 4.0)]
    assert d.marker_segments[0].label == "chirp"
    r = load_io(path, input="/amp/applied.applied_kv")
    assert len(r.notes) == 1 and "interpolated" in r.notes[0]
    sig = load_signals(path, ["/amp/applied.applied_kv"])["/amp/applied.applied_kv"]
    keep = d.t_s <= sig.t_s[-1]
    np.testing.assert_allclose(r.t_s, d.t_s[keep])
    np.testing.assert_allclose(r.u, np.interp(d.t_s[keep], sig.t_s, sig.values))


def test_load_io_mcap_bad_inputs(tmp_path, rng):
    path = tmp_path / "p.mcap"
    _plant_log(path, rng, nan_at=7)
    with pytest.raises(DataFileError, match=r"stroke_mm has 1 NaN/inf values, the first at t = 1\.0143"):
        load_io(path)
    with pytest.raises(BadInputError, match=r"no topic /nope; topics: /amp/applied \(hasel_msgs/msg/VoltageCommand\)"):
        load_io(path, input="/nope.x")
    with pytest.raises(BadInputError, match=r"no field 'applied' in .*numeric fields: .*applied_kv"):
        load_io(path, input="/amp/applied.applied")
    with pytest.raises(BadInputError, match="is a string"):
        load_io(path, input="/experiment/marker.label", output="/plant/batch.voltage_kv")
    with pytest.raises(BadInputError, match=r"expected /topic.field"):
        load_io(path, input="voltage_kv")
    short = tmp_path / "short.mcap"
    _plant_log(short, rng, n_msgs=1, per=5)
    with pytest.raises(DataFileError, match="has 5 samples; at least 10"):
        load_io(short)
    with pytest.raises(DataFileError, match="no such file"):
        load_io(tmp_path / "missing.mcap")


def test_non_increasing_stamps_are_reported(tmp_path):
    path = tmp_path / "back.mcap"
    with Ros2McapWriter(path) as w:
        c = w.add_topic("/plant/batch", BATCH)
        for i, t in enumerate([3, 4, 2, 5]):
            w.write(c, encode(BATCH, {"header": {"stamp": _stamp(t * 10**9)}, "sample_period_s": 1e-3,
                                      "voltage_kv": np.ones(5), "stroke_mm": np.ones(5)}), i, i)
    with pytest.raises(DataFileError, match="not strictly increasing at sample 10"):
        load_io(path)


def test_array_field_of_unbatched_message_needs_an_index(tmp_path):
    path = tmp_path / "a.mcap"
    with Ros2McapWriter(path) as w:
        c = w.add_topic("/arr", "std_msgs/msg/Float64MultiArray")
        for i in range(3):
            w.write(c, encode("std_msgs/msg/Float64MultiArray", {"data": [i, i + 1.0]}), i + 1, 0)
    with pytest.raises(BadInputError, match=r"ask for one element, e\.g\. /arr\.data\[0\]"):
        load_signals(path, ["/arr.data"])
    sig = load_signals(path, ["/arr.data[1]", "/arr.data[5]"])
    np.testing.assert_array_equal(sig["/arr.data[1]"].values, [1, 2, 3])
    assert np.isnan(sig["/arr.data[5]"].values).all()


@pytest.mark.parametrize("bag,field,count", [
    ("cdr_test_0.mcap", "/test_topic.float64_value", 3),
    ("cdr_test_0.mcap", "/array_topic.int32_values[2]", 4),
    ("talker.mcap", "/rosout.level", 10),
    ("test_bag_for_seek_0.mcap", "topic1.int64_value", 5),
    ("only_topics.mcap", "/parameter_events.stamp.sec", 7),
    ("bag_with_topics_and_service_events.mcap", "/test_topic1.string_value", None),
])
def test_rosbag2_files_load_like_mcap_ros2_decodes_them(bag, field, count):
    if count is None:
        with pytest.raises(BadInputError, match="is a string"):
            load_signals(ROSBAG2 / bag, [field])
        return
    sig = load_signals(ROSBAG2 / bag, [field])[field]
    topic, path = field.split(".", 1)
    want, times = [], []
    with open(ROSBAG2 / bag, "rb") as f:
        for _s, ch, msg, dec in make_reader(f, decoder_factories=[DecoderFactory()]).iter_decoded_messages(
                topics=[topic], log_time_order=False):
            for part in path.split("."):
                name, _, idx = part.partition("[")
                dec = getattr(dec, name)
                if idx:
                    dec = dec[int(idx[:-1])]
            want.append(float(dec))
            times.append(msg.log_time * 1e-9)
    assert sig.values.size == count
    np.testing.assert_array_equal(sig.values, want)
    if sig.time_source == "log":
        np.testing.assert_allclose(sig.t_s, times, rtol=0, atol=1e-6)


def test_undecodable_schema_is_a_data_file_error():
    with pytest.raises(DataFileError, match=r"cannot decode topic /test_service1/_service_event .*'---'"):
        load_signals(ROSBAG2 / "bag_with_topics_and_service_events.mcap", ["/test_service1/_service_event.x"])


def test_big_endian_message_in_a_chunk_takes_the_slow_path(tmp_path):
    """A CDR_BE message among CDR_LE ones: the chunk is redone message by message, same result."""
    import struct

    def be_stroke(sec, stroke):
        payload = struct.pack(">iI", sec, 0) + struct.pack(">I", 1) + b"\x00"
        payload += b"\x00" * ((-len(payload)) % 8) + struct.pack(">d", stroke) + b"\x02"
        return b"\x00\x00\x00\x00" + payload

    path = tmp_path / "be.mcap"
    with Ros2McapWriter(path) as w:
        c = w.add_topic("/s", "hasel_msgs/msg/Stroke")
        for i in range(6):
            data = be_stroke(i + 1, i * 1.5) if i == 3 else encode(
                "hasel_msgs/msg/Stroke", {"header": {"stamp": {"sec": i + 1}}, "stroke_mm": i * 1.5})
            w.write(c, data, i, i)
    sig = load_signals(path, ["/s.stroke_mm"])["/s.stroke_mm"]
    np.testing.assert_array_equal(sig.values, np.arange(6) * 1.5)
    np.testing.assert_array_equal(sig.t_s, np.arange(1, 7))
