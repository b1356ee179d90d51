"""`hasel info` and `hasel salvage` through the real CLI entry point."""
from __future__ import annotations

import json

from realdata import datasets_dir

import numpy as np
import pytest
from mcap.reader import make_reader

from hasel.cli import main
from hasel.io import Ros2McapWriter

from cdrwrite import encode

ROSBAG2 = datasets_dir() / "rosbag2"


@pytest.fixture
def log(tmp_path):
    path = tmp_path / "run.mcap"
    with Ros2McapWriter(path, chunk_size=1000) as w:
        c = w.add_topic("/sensor/stroke", "hasel_msgs/msg/Stroke")
        for i in range(101):  # 100 Hz for 1 s
            t = 1_700_000_000 * 10**9 + i * 10_000_000
            w.write(c, encode("hasel_msgs/msg/Stroke", {"stroke_mm": float(i)}), t, t)
    return path


def test_info_of_an_intact_log(log, capsys, tmp_path):
    assert main(["info", str(log), "--json", str(tmp_path / "i.json")]) == 0
    out = capsys.readouterr().out
    assert "Files:             run.mcap" in out
    assert "Storage id:        mcap" in out
    assert "Duration:          1.000s" in out
    assert "Messages:          101" in out
    assert ("Topic information: Topic: /sensor/stroke | Type: hasel_msgs/msg/Stroke | Count: 101 | "
            "Serialization Format: cdr") in out
    assert "/sensor/stroke: 100 Hz (101 messages over 1.000 s)" in out
    assert "Status:            intact" in out
    doc = json.loads((tmp_path / "i.json").read_text())
    assert doc["topics"][0]["rate_hz"] == pytest.approx(100.0)
    assert doc["complete"] is True


@pytest.mark.parametrize("bag,topic_line", [
    ("talker.mcap", "Topic: /topic | Type: std_msgs/msg/String | Count: 10 | Serialization Format: cdr"),
    ("cdr_test_0.mcap", "Topic: /array_topic | Type: test_msgs/msg/Arrays | Count: 4 | Serialization Format: cdr"),
    ("only_topics.mcap", "Topic: /parameter_events | Type: rcl_interfaces/msg/ParameterEvent | Count: 7"),
    ("test_bag_for_seek_0.mcap", "Topic: topic1 | Type: test_msgs/BasicTypes | Count: 5"),
    ("bag_with_topics_and_service_events.mcap",
     "Topic: /test_service1/_service_event | Type: test_msgs/srv/BasicTypes_Event | Count: 4"),
])
def test_info_reads_rosbag2s_own_files(bag, topic_line, capsys):
    assert main(["info", str(ROSBAG2 / bag)]) == 0
    out = capsys.readouterr().out
    assert topic_line in out
    if bag.startswith("bag_with"):
        assert "Undecodable:       /test_service2/_service_event (test_msgs/srv/BasicTypes_Event)" in out
        assert "Count: 0" in out  # /events/write_split: in the summary only
    if bag == "only_topics.mcap":
        assert "ROS Distro:        rolling" in out


def test_info_and_salvage_of_a_killed_recording(log, tmp_path, capsys):
    data = log.read_bytes()
    cut = tmp_path / "cut.mcap"
    cut.write_bytes(data[:len(data) // 2])
    assert main(["info", str(cut)]) == 2
    captured = capsys.readouterr()
    assert "Status:            damaged:" in captured.out
    assert "Recoverable:" in captured.out
    err = captured.err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("hasel info: error:") and "hasel salvage" in err[0]
    out = tmp_path / "fixed.mcap"
    assert main(["salvage", str(cut), str(out)]) == 0
    said = capsys.readouterr().out
    with open(out, "rb") as f:
        stats = make_reader(f, validate_crcs=True).get_summary().statistics
    assert 30 < stats.message_count < 101
    assert f"{stats.message_count} messages on 1 topic " in said
    assert main(["info", str(out)]) == 0
    capsys.readouterr()
    assert main(["salvage", str(cut), str(out)]) == 2  # exists
    assert "exists" in capsys.readouterr().err
    assert main(["salvage", str(cut), str(out), "--overwrite"]) == 0


def test_bad_input_is_one_line_exit_2(tmp_path, capsys):
    assert main(["info", str(tmp_path / "none.mcap")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert err == [f"hasel info: error: no such file: {tmp_path / 'none.mcap'}"]
    junk = tmp_path / "junk.mcap"
    junk.write_bytes(np.random.default_rng(1).bytes(300))
    assert main(["info", str(junk)]) == 2
    assert "not an MCAP file" in capsys.readouterr().err
    assert main(["salvage", str(junk), str(junk)]) == 2
    assert "is also an input of this command" in capsys.readouterr().err


def test_salvage_of_a_file_whose_only_chunk_was_cut_says_so(tmp_path, capsys):
    path = tmp_path / "one.mcap"
    with Ros2McapWriter(path, chunk_size=1 << 20) as w:  # every message in one chunk
        c = w.add_topic("/sensor/stroke", "hasel_msgs/msg/Stroke")
        for i in range(50):  # 0.5 s: within one chunk
            t = 10**9 + i * 10_000_000
            w.write(c, encode("hasel_msgs/msg/Stroke", {"stroke_mm": float(i)}), t, t)
    with open(path, "rb") as f:
        chunks = make_reader(f).get_summary().chunk_indexes
    assert len(chunks) == 1
    cut = tmp_path / "cut.mcap"
    cut.write_bytes(path.read_bytes()[:chunks[0].chunk_start_offset + chunks[0].chunk_length // 2])
    out = tmp_path / "fixed.mcap"
    assert main(["salvage", str(cut), str(out)]) == 2
    captured = capsys.readouterr()
    assert "no intact chunk was lost" not in captured.out
    assert "1 damaged chunk lost" in captured.out and "no message could be recovered" in captured.out
    assert captured.err.strip().startswith("hasel salvage: error: no message") and len(captured.err.splitlines()) == 1
    with open(out, "rb") as f:  # still a valid file, with the topic and no message
        summary = make_reader(f).get_summary()
    assert summary.statistics.message_count == 0 and [ch.topic for ch in summary.channels.values()] == ["/sensor/stroke"]
