"""A custom hasel_msgs message crosses between two processes over Fast DDS."""
from __future__ import annotations

import os
import subprocess
import sys
import textwrap
import time

import rclpy
from rclpy.context import Context
from rclpy.executors import SingleThreadedExecutor

from hasel_ros.rosutil import topic_qos
from hasel_msgs.msg import ControllerState

TALKER = textwrap.dedent("""
    import sys, time, rclpy
    from hasel_msgs.msg import ControllerState
    from rclpy.qos import QoSProfile, ReliabilityPolicy
    rclpy.init()
    n = rclpy.create_node("xproc_talker")
    pub = n.create_publisher(ControllerState, "/xproc/state", QoSProfile(depth=100, reliability=ReliabilityPolicy.RELIABLE))
    deadline = time.monotonic() + 20
    while pub.get_subscription_count() == 0 and time.monotonic() < deadline:
        time.sleep(0.01)
    for i in range(200):
        m = ControllerState(reference_mm=4.0, measured_mm=i * 0.01, mode=ControllerState.MODE_RELAXATION,
                            output_kv=3.5, rejected_samples=i)
        m.header.frame_id = "pid"
        pub.publish(m)
        time.sleep(0.005)
    time.sleep(0.5)
    n.destroy_node(); rclpy.shutdown()
""")


def test_custom_message_between_two_processes():
    ctx = Context()
    rclpy.init(context=ctx)
    node = rclpy.create_node("xproc_listener", context=ctx)
    ex = SingleThreadedExecutor(context=ctx)
    ex.add_node(node)
    got: list[ControllerState] = []
    # the graph's profile for this topic, with room for the whole burst: a KEEP_LAST reader of depth 10 that
    # falls behind (a loaded CI machine) overwrites its oldest samples, which reliability does not prevent
    # (194 of 200 arrived once beside a corpus scoring)
    profile = topic_qos("/controller/state")
    profile.depth = 200
    node.create_subscription(ControllerState, "/xproc/state", got.append, profile)
    proc = subprocess.Popen([sys.executable, "-c", TALKER], env=dict(os.environ))
    try:
        deadline = time.monotonic() + 60
        while time.monotonic() < deadline and not (proc.poll() is not None and len(got) >= 200):
            ex.spin_once(timeout_sec=0.05)
        assert proc.wait(timeout=30) == 0
    finally:
        if proc.poll() is None:
            proc.kill()
        ex.shutdown()
        node.destroy_node()
        rclpy.try_shutdown(context=ctx)
    assert len(got) == 200  # reliable QoS after matching: every message arrives
    assert got[0].header.frame_id == "pid" and got[-1].rejected_samples == 199
    assert got[5].mode == ControllerState.MODE_RELAXATION and got[5].measured_mm == 0.05
