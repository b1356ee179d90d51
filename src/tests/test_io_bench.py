"""The I/O benchmark compares like with like: both writers hold the same messages; the loader reads every sample."""
from __future__ import annotations

import math

import numpy as np
from mcap.reader import make_reader
from mcap.writer import CompressionType

from hasel_bench import iospeed


def _contents(path) -> list[tuple[str, str, int, int, bytes]]:
    with open(path, "rb") as f:
        return [(ch.topic, sc.name, m.log_time, m.publish_time, m.data)
                for sc, ch, m in make_reader(f).iter_messages(log_time_order=False)]


def test_our_writer_and_the_bare_one_write_the_same_messages(tmp_path):
    msgs = iospeed._messages(300, np.random.default_rng(0))
    iospeed._write_ours(tmp_path / "ours.mcap", msgs, "zstd", 3)
    iospeed._write_bare(tmp_path / "bare.mcap", msgs, CompressionType.ZSTD)
    ours, bare = _contents(tmp_path / "ours.mcap"), _contents(tmp_path / "bare.mcap")
    assert len(ours) == 300 and ours == bare
    assert {(t, s) for t, s, *_ in ours} == {("/plant/batch", "hasel_msgs/msg/SampleBatch"),
                                             ("/sensor/stroke", "hasel_msgs/msg/Stroke")}


def test_writer_overhead_small():
    r = iospeed.writer_overhead(n_messages=400, repeats=1)
    assert r["messages"] == 400
    for k in ("ours_us", "bare_us", "ours_none_us", "bare_none_us"):
        assert math.isfinite(r[k]) and r[k] > 0


def test_load_speed_reads_every_sample():
    r = iospeed.load_speed(segments=2, segment_s=0.25, rate_hz=10_000, batch=50, repeats=1)
    assert r["samples"] == 5000  # 2 x 0.25 s at 10 kHz, 100 batches of 50
    assert r["file_mib"] > 0 and r["load_cpu_s"] > 0
