"""The MCAP writer: round trips through mcap's own reader and decoder, rosbag2's layout, crash safety."""
from __future__ import annotations

import os
import signal
import subprocess
import sys
import textwrap
import time

from realdata import datasets_dir

import numpy as np
import pytest
import yaml
from mcap.reader import make_reader
from mcap_ros2.decoder import DecoderFactory

from hasel.errors import BadInputError
from hasel.io import (
    QosProfile, Ros2McapWriter, load_signals, message_definition, offered_qos_yaml, salvage,
)
from hasel.io.writer import INFINITE_NS

from cdrwrite import encode

BATCH = "hasel_msgs/msg/SampleBatch"
STROKE = "hasel_msgs/msg/Stroke"
ROSBAG2 = datasets_dir() / "rosbag2"


def _write_log(path, rng, n=120, **opts):
    """A log with batched samples and a scalar topic; returns what was written."""
    written = {"batch": [], "stroke": []}
    with Ros2McapWriter(path, **opts) as w:
        cb = w.add_topic("/plant/batch", BATCH)
        cs = w.add_topic("/sensor/stroke", STROKE, qos=QosProfile(reliability="best_effort", depth=5))
        for i in range(n):
            t_ns = 1_700_000_000_000_000_000 + i * 5_000_000
            k = int(rng.integers(0, 60))
            v, y = rng.normal(size=k), rng.normal(size=k)
            stamp = {"sec": t_ns // 10**9, "nanosec": t_ns % 10**9}
            w.write(cb, encode(BATCH, {"header": {"stamp": stamp}, "sample_period_s": 1e-4, "voltage_kv": v,
                                       "stroke_mm": y}), t_ns + 17, t_ns + 3, i)
            s = float(rng.normal())
            w.write(cs, encode(STROKE, {"header": {"stamp": stamp}, "stroke_mm": s, "source": 2}), t_ns + 20, t_ns)
            written["batch"].append((t_ns, v, y, i))
            written["stroke"].append((t_ns, s))
    return written


@pytest.mark.parametrize("compression", ["zstd", "lz4", "none"])
@pytest.mark.parametrize("chunk_size", [2048, 768 * 1024])
def test_round_trip_through_mcap_reader_and_loader(tmp_path, compression, chunk_size):
    rng = np.random.default_rng(11)
    path = tmp_path / "log.mcap"
    written = _write_log(path, rng, compression=compression, chunk_size=chunk_size)
    with open(path, "rb") as f:
        reader = make_reader(f, validate_crcs=True, decoder_factories=[DecoderFactory()])
        header = reader.get_header()
        assert header.profile == "ros2"
        summary = reader.get_summary()
        assert summary is not None and summary.statistics is not None
        assert summary.statistics.message_count == 240
        assert summary.statistics.channel_message_counts == {1: 120, 2: 120}
        assert len(summary.chunk_indexes) == summary.statistics.chunk_count >= 1
        if chunk_size == 2048:
            assert summary.statistics.chunk_count > 10
        assert {ci.compression for ci in summary.chunk_indexes} == {"" if compression == "none" else compression}
        schemas = {s.name: s for s in summary.schemas.values()}
        assert schemas[BATCH].encoding == "ros2msg"
        assert schemas[BATCH].data.decode() == message_definition(BATCH)
        channels = {c.topic: c for c in summary.channels.values()}
        assert channels["/plant/batch"].message_encoding == "cdr"
        qos = yaml.safe_load(channels["/sensor/stroke"].metadata["offered_qos_profiles"])
        assert qos[0]["reliability"] == "best_effort" and qos[0]["depth"] == 5
        assert channels["/plant/batch"].metadata["topic_type_hash"].startswith("RIHS01_")
        got_batch, got_stroke = [], []
        for _schema, channel, message, decoded in reader.iter_decoded_messages(log_time_order=False):
            if channel.topic == "/plant/batch":
                got_batch.append((message.log_time, message.publish_time, message.sequence, decoded))
            else:
                got_stroke.append((message.log_time, decoded))
    assert len(got_batch) == len(got_stroke) == 120
    for (lt, pt, seq, dec), (t_ns, v, y, i) in zip(got_batch, written["batch"]):
        assert (lt, pt, seq) == (t_ns + 17, t_ns + 3, i)
        np.testing.assert_array_equal(dec.voltage_kv, v)
        np.testing.assert_array_equal(dec.stroke_mm, y)
        assert dec.header.stamp.sec * 10**9 + dec.header.stamp.nanosec == t_ns
    assert [d.stroke_mm for _, d in got_stroke] == [s for _, s in written["stroke"]]
    # our loader: the same numbers, per-sample times stamp + i * period
    sig = load_signals(path, ["/plant/batch.voltage_kv", "/sensor/stroke.stroke_mm"])
    v_all = np.concatenate([v for _, v, _, _ in written["batch"]])
    t_all = np.concatenate([t * 1e-9 + np.arange(v.size) * 1e-4 for t, v, _, _ in written["batch"]])
    np.testing.assert_array_equal(sig["/plant/batch.voltage_kv"].values, v_all)
    np.testing.assert_allclose(sig["/plant/batch.voltage_kv"].t_s, t_all, rtol=0, atol=1e-9)
    np.testing.assert_array_equal(sig["/sensor/stroke.stroke_mm"].values, [s for _, s in written["stroke"]])


def test_qos_yaml_is_rosbag2_jazzy_format():
    text = offered_qos_yaml(QosProfile(history=3, depth=0, reliability=1, durability="transient_local",
                                       deadline=INFINITE_NS, lifespan=(10, 0), liveliness=1,
                                       liveliness_lease_duration=INFINITE_NS))
    assert text == textwrap.dedent("""\
        - history: unknown
          depth: 0
          reliability: reliable
          durability: transient_local
          deadline:
            sec: 9223372036
            nsec: 854775807
          lifespan:
            sec: 10
            nsec: 0
          liveliness: automatic
          liveliness_lease_duration:
            sec: 9223372036
            nsec: 854775807
          avoid_ros_namespace_conventions: false""")
    # the same keys, in the same order, as rosbag2 writes them (an older, numeric-enum bag)
    with open(ROSBAG2 / "only_topics.mcap", "rb") as f:
        summary = make_reader(f).get_summary()
    recorded = next(c for c in summary.channels.values() if c.topic == "/rosout").metadata["offered_qos_profiles"]
    keys = [line.split(":")[0] for line in recorded.splitlines()]
    assert [line.split(":")[0] for line in text.splitlines()] == keys
    two = offered_qos_yaml([{"depth": 1}, QosProfile()])
    assert [p["depth"] for p in yaml.safe_load(two)] == [1, 10]
    assert offered_qos_yaml([]) == "[]"
    with pytest.raises(BadInputError, match="reliability"):
        offered_qos_yaml(QosProfile(reliability="sometimes"))


def test_writer_refuses_misuse(tmp_path):
    w = Ros2McapWriter(tmp_path / "a.mcap")
    cid = w.add_topic("/s", STROKE)
    assert w.add_topic("/s", STROKE) == cid
    with pytest.raises(BadInputError, match="already added with type"):
        w.add_topic("/s", BATCH)
    with pytest.raises(BadInputError, match="unknown channel id 9"):
        w.write(9, b"\x00\x01\x00\x00", 1, 1)
    with pytest.raises(BadInputError, match="uint64"):
        w.write(cid, b"\x00\x01\x00\x00", -1, 1)
    w.add_metadata("run", {"seed": 3})
    w.close()
    w.close()
    with pytest.raises(BadInputError, match="closed"):
        w.write(cid, b"\x00\x01\x00\x00", 1, 1)
    with open(tmp_path / "a.mcap", "rb") as f:
        reader = make_reader(f, validate_crcs=True)
        assert [(m.name, m.metadata) for m in reader.iter_metadata()] == [("run", {"seed": "3"})]
        assert reader.get_summary().statistics.message_count == 0


def test_chunks_close_on_log_time_span(tmp_path):
    path = tmp_path / "span.mcap"
    data = encode(STROKE, {"stroke_mm": 1.0})
    with Ros2McapWriter(path, max_chunk_span_s=0.1) as w:
        c = w.add_topic("/s", STROKE)
        for i in range(100):  # 1 s of 100 Hz messages: a new chunk every 0.1 s
            w.write(c, data, i * 10_000_000, 0)
    with open(path, "rb") as f:
        assert make_reader(f).get_summary().statistics.chunk_count == 10


STROKE_HEX = encode(STROKE, {"stroke_mm": 1.0}).hex()

CHILD = """
import sys, time
from hasel.io import Ros2McapWriter
data = bytes.fromhex(sys.argv[2])  # one serialised Stroke
w = Ros2McapWriter(sys.argv[1], chunk_size=4000, max_chunk_span_s=None, fsync_interval_s=0.05)
c = w.add_topic('/s', 'hasel_msgs/msg/Stroke')
chunks = 0
i = 0
while True:
    w.write(c, data, 10**9 + i, 10**9 + i, i)
    i += 1
    if w.chunk_count != chunks:
        chunks = w.chunk_count
        print(i, flush=True)  # every message so far is in a closed chunk
        time.sleep(0.01)
"""


def test_sigkill_loses_only_the_open_chunk(tmp_path):
    path = tmp_path / "killed.mcap"
    proc = subprocess.Popen([sys.executable, "-c", CHILD, str(path), STROKE_HEX], stdout=subprocess.PIPE, text=True)
    try:
        reported = 0
        deadline = time.monotonic() + 60
        while reported < 200 and time.monotonic() < deadline:
            line = proc.stdout.readline()
            if not line:
                break
            reported = int(line)
    finally:
        os.kill(proc.pid, signal.SIGKILL)
        proc.wait()
        proc.stdout.close()
    assert reported >= 200, "the writer never reported closed chunks"
    report = salvage(path, tmp_path / "fixed.mcap")
    assert not report.intact
    assert report.messages >= reported
    with open(tmp_path / "fixed.mcap", "rb") as f:
        reader = make_reader(f, validate_crcs=True, decoder_factories=[DecoderFactory()])
        seqs = [m.sequence for _, _, m, _ in reader.iter_decoded_messages(log_time_order=False)]
    assert seqs == list(range(report.messages))


SIGTERM_CHILD = """
import signal, sys
from hasel.io import Ros2McapWriter
w = Ros2McapWriter(sys.argv[1], chunk_size=3000)
c = w.add_topic('/s', 'hasel_msgs/msg/Stroke')
stop = []
signal.signal(signal.SIGTERM, lambda signum, frame: stop.append(signum))  # the handler only flags
data = bytes.fromhex(sys.argv[2])  # one serialised Stroke
i = 0
while not stop:
    w.write(c, data, i + 1, i + 1, i % 2**32)
    i += 1
    if i == 2000:
        print('ready', flush=True)
w.close()  # the shutdown path closes, as the recorder node does after SIGINT/SIGTERM
"""


def test_sigterm_then_close_on_the_shutdown_path_leaves_a_valid_file(tmp_path):
    path = tmp_path / "term.mcap"
    proc = subprocess.Popen([sys.executable, "-c", SIGTERM_CHILD, str(path), STROKE_HEX], stdout=subprocess.PIPE, text=True)
    assert proc.stdout.readline().strip() == "ready"
    time.sleep(0.05)
    proc.send_signal(signal.SIGTERM)
    assert proc.wait(timeout=30) == 0
    proc.stdout.close()
    with open(path, "rb") as f:
        reader = make_reader(f, validate_crcs=True)
        stats = reader.get_summary().statistics
        seqs = [m.sequence for _, _, m in reader.iter_messages(log_time_order=False)]
    assert stats.message_count == len(seqs) >= 2000
    assert seqs == list(range(len(seqs)))
    with open(path, "rb") as f:  # the message indexes agree with the records
        indexed = sum(1 for _ in make_reader(f).iter_messages(log_time_order=True))
    assert indexed == len(seqs)
