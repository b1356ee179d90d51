"""``hasel demo``: the end-to-end story (grows with every capability)."""
from __future__ import annotations

import argparse


def run(args: argparse.Namespace) -> int:
    """Run the demo; files go to ``args.out``. Returns the exit code."""
    import rclpy

    import hasel_msgs.msg

    rclpy.init()
    node = rclpy.create_node("hasel_demo")
    pub = node.create_publisher(hasel_msgs.msg.Stroke, "/demo/stroke", 10)
    msg = hasel_msgs.msg.Stroke(stroke_mm=2.0, source=hasel_msgs.msg.Stroke.SOURCE_LASER)
    pub.publish(msg)
    node.destroy_node()
    rclpy.try_shutdown()
    print("demo: graph placeholder ok")
    return 0
