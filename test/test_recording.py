"""MCAP recording of a graph run, reading it back, and replay through the driver and filter."""
from __future__ import annotations

import signal

import numpy as np
import pytest
import rclpy
from mcap.reader import make_reader
from mcap_ros2.decoder import DecoderFactory
from rclpy.context import Context
from rclpy.experimental import EventsExecutor

from children import default_sigint
from hasel_driver.driver_node import StrainDriverNode
from hasel_driver.filter_node import LowPassNode
from hasel_ros.rosutil import topic_qos
from hasel_msgs.msg import Stroke
from hasel_sysid.replay import Replayer, read_raw
from hasel_sysid.steps import run_steps


@pytest.fixture(scope="module")
def recorded(tmp_path_factory):
    path = tmp_path_factory.mktemp("rec") / "steps.mcap"
    res = run_steps("strain", [2.0, 4.0, 6.0, 4.0, 2.0], 0.2, record=str(path), quiet=True)
    return path, res


def test_recorded_file_is_valid_and_counts_match(recorded):
    path, res = recorded
    with path.open("rb") as f:
        reader = make_reader(f, decoder_factories=[DecoderFactory()])
        summary = reader.get_summary()
        assert summary is not None and summary.statistics.message_count > 0
        assert reader.get_header().profile == "ros2"
        counts = {c.topic: summary.statistics.channel_message_counts.get(cid, 0)
                  for cid, c in summary.channels.items()}
        batches = []
        for schema, channel, message, decoded in reader.iter_decoded_messages():
            assert schema.encoding == "ros2msg" and channel.message_encoding == "cdr"
            assert "offered_qos_profiles" in channel.metadata
            if channel.topic == "/plant/batch":
                batches.append(decoded)
    # 1 s of simulated time: 200 ticks, every 10 kHz sample recorded
    assert counts["/plant/batch"] == 200 and len(batches) == 200
    assert counts["/sensor/timing"] >= 200 and counts["/amp/applied"] >= 200
    true = np.concatenate([b.true_stroke_mm for b in batches])
    np.testing.assert_array_equal(true, res["_signals"]["true_stroke_mm"])
    np.testing.assert_array_equal(np.concatenate([b.voltage_kv for b in batches]), res["_signals"]["voltage_kv"])


def test_replaying_raw_timing_through_driver_and_filter_reproduces_the_filtered_stream(recorded):
    path, _ = recorded
    recorded_filtered = [(m.log_time_ns, m.data) for m in read_raw(path, ["/strain/stroke_filtered"])]
    ctx = Context()
    rclpy.init(context=ctx)
    driver, lp = StrainDriverNode(context=ctx), LowPassNode(context=ctx)
    probe = rclpy.create_node("replay_probe", context=ctx)
    out: list[Stroke] = []
    probe.create_subscription(Stroke, "/strain/stroke_filtered", out.append, topic_qos("/strain/stroke_filtered"))
    ex = EventsExecutor(context=ctx)
    for n in (driver, lp, probe):
        ex.add_node(n)
    rep = Replayer(probe)
    try:
        timing = list(read_raw(path, ["/sensor/timing"]))
        pub = rep.publisher("/sensor/timing", timing[0].type_name)
        for _ in range(500):
            if pub.get_subscription_count() and lp.pub.get_subscription_count():
                break
            ex.spin_once(timeout_sec=0.01)
        for m in timing:  # lockstep: each sample through the chain before the next
            n = len(out)
            rep.publish(m)
            while len(out) == n:
                ex.spin_once(timeout_sec=1.0)
    finally:
        ex.shutdown()
        for n in (driver, lp, probe):
            n.destroy_node()
        rclpy.try_shutdown(context=ctx)
    from rclpy.serialization import deserialize_message

    want = [deserialize_message(d, Stroke) for _, d in recorded_filtered]
    assert len(want) >= 199
    got = {(m.header.stamp.sec, m.header.stamp.nanosec): m.stroke_mm for m in out}
    for w in want:  # exactly the same numbers, stamp by stamp
        assert got[(w.header.stamp.sec, w.header.stamp.nanosec)] == w.stroke_mm


@pytest.mark.parametrize("sig", ["SIGINT", "SIGTERM"])
def test_hasel_record_stopped_by_a_signal_leaves_a_complete_file(tmp_path, sig):
    import os
    import subprocess
    import time
    from pathlib import Path

    from hasel_msgs.msg import Reference

    out = tmp_path / "rec.mcap"
    hasel = Path(__file__).resolve().parents[1] / ".venv" / "bin" / "hasel"
    proc = subprocess.Popen([str(hasel), "record", "-o", str(out), "--topics", "/sig_test"], env=dict(os.environ), preexec_fn=default_sigint,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    ctx = Context()
    rclpy.init(context=ctx)
    node = rclpy.create_node("sig_pub", context=ctx)
    pub = node.create_publisher(Reference, "/sig_test", 10)
    try:
        deadline = time.monotonic() + 30
        while pub.get_subscription_count() == 0 and time.monotonic() < deadline:
            time.sleep(0.05)
        assert pub.get_subscription_count() == 1, "the recorder did not subscribe"
        for i in range(100):
            pub.publish(Reference(stroke_mm=float(i)))
            time.sleep(0.002)
        time.sleep(0.5)
        proc.send_signal(getattr(signal, sig))
        stdout, stderr = proc.communicate(timeout=30)
    finally:
        node.destroy_node()
        rclpy.try_shutdown(context=ctx)
    assert proc.returncode == 128 + getattr(signal, sig), stderr  # stopped by the signal, file closed
    assert "Traceback" not in stderr
    with out.open("rb") as f:
        reader = make_reader(f, decoder_factories=[DecoderFactory()])
        summary = reader.get_summary()  # present: the footer and summary were written
        values = [m.stroke_mm for _, ch, _, m in reader.iter_decoded_messages() if ch.topic == "/sig_test"]
    assert summary is not None
    assert values == [float(i) for i in range(100)]
