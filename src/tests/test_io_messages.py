"""Raw messages in log-time order (what replay publishes), against the mcap library's own reader."""
from __future__ import annotations

import numpy as np
import pytest
from mcap.reader import make_reader

from hasel.errors import DataFileError
from hasel.io import Ros2McapWriter, iter_messages

from cdrwrite import encode

STROKE = "hasel_msgs/msg/Stroke"
REF = "hasel_msgs/msg/Reference"


def _reference_order(path, topics=None):
    with open(path, "rb") as f:
        return [(c.topic, m.log_time, m.publish_time, m.data)
                for _, c, m in make_reader(f).iter_messages(topics=topics, log_time_order=True)]


def _ours(path, topics=None):
    return [(m.topic, m.log_time_ns, m.publish_time_ns, m.data) for m in iter_messages(path, topics)]


def test_overlapping_chunks_come_out_in_log_time_order(tmp_path):
    # two topics whose log times interleave out of file order: chunks overlap in time
    path = tmp_path / "overlap.mcap"
    rng = np.random.default_rng(5)
    times = rng.permutation(np.arange(1, 601)) * 1_000_000 + 10**9  # unique, shuffled
    with Ros2McapWriter(path, chunk_size=600) as w:
        a = w.add_topic("/a", STROKE)
        b = w.add_topic("/b", REF)
        for i, t in enumerate(times):
            if i % 3:
                w.write(a, encode(STROKE, {"stroke_mm": float(i)}), int(t), int(t) + 7, i)
            else:
                w.write(b, encode(REF, {"stroke_mm": float(i)}), int(t), int(t) + 9, i)
        assert w.chunk_count > 20
    ours = _ours(path)
    assert [m[1] for m in ours] == sorted(int(t) for t in times)
    assert ours == _reference_order(path)
    assert _ours(path, ["/b"]) == _reference_order(path, ["/b"])
    assert {m.type_name for m in iter_messages(path)} == {STROKE, REF}


def test_equal_log_times_keep_file_order(tmp_path):
    path = tmp_path / "ties.mcap"
    with Ros2McapWriter(path, chunk_size=300) as w:
        a, b = w.add_topic("/a", STROKE), w.add_topic("/b", STROKE)
        for i in range(60):
            w.write(a if i % 2 else b, encode(STROKE, {"stroke_mm": float(i)}), 10**9 + (i // 4) * 1000, 0, i)
    data = [m.data for m in iter_messages(path)]
    assert data == [encode(STROKE, {"stroke_mm": float(i)}) for i in range(60)]


def test_a_truncated_file_raises_data_file_error(tmp_path):
    path = tmp_path / "cut.mcap"
    with Ros2McapWriter(path, chunk_size=400) as w:
        a = w.add_topic("/a", STROKE)
        for i in range(200):
            w.write(a, encode(STROKE, {"stroke_mm": float(i)}), 10**9 + i, 0, i)
    raw = path.read_bytes()
    path.write_bytes(raw[: len(raw) * 2 // 3])
    with pytest.raises(DataFileError, match="salvage"):
        list(iter_messages(path))
