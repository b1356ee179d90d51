"""Reference generator node: the paper's step sequence 2 -> 4 -> 6 -> 4 -> 2 mm.

Publishes the whole sequence on ``/reference`` at start, each value stamped with the
time it takes effect (``start_s + i * hold_s``, on the node's clock, which is simulated
time under use_sim_time). The topic is latched (transient local), so a controller that
starts later still receives the schedule.
"""
from __future__ import annotations

import math
from collections.abc import Sequence

from rclpy.node import Node

from hasel import paper
from hasel.errors import BadInputError
from hasel_ros.rosutil import declare, now_s, run_node, to_stamp, topic_qos
from hasel_msgs.msg import Reference

__all__ = ["ReferenceNode", "main"]


class ReferenceNode(Node):
    """Parameters: sequence_mm (list), hold_s, start_s (s; negative = now)."""

    def __init__(self, **kwargs) -> None:
        super().__init__("reference_generator", **kwargs)
        self.sequence = [float(x) for x in declare(self, "sequence_mm", list(paper.STEP_SEQUENCE_MM),
                                                   "stroke references, mm")]
        self.hold_s = declare(self, "hold_s", 1.0, "time per reference, s", lo=0.005, hi=1e6)
        start = declare(self, "start_s", -1.0, "time of the first reference, s (negative: now)", lo=-1.0, hi=1e9)
        if not self.sequence or not all(math.isfinite(x) for x in self.sequence):
            raise BadInputError(f"sequence_mm must be a non-empty list of finite numbers, got {self.sequence}")
        self.start_s = start if start >= 0 else now_s(self)
        self.pub = self.create_publisher(Reference, "reference", topic_qos("/reference"))
        for i, r in enumerate(self.sequence):
            msg = Reference(stroke_mm=r)
            msg.header.stamp = to_stamp(self.start_s + i * self.hold_s)
            self.pub.publish(msg)

    @property
    def end_s(self) -> float:
        """Time the last reference ends, s."""
        return self.start_s + len(self.sequence) * self.hold_s


def main(args: Sequence[str] | None = None) -> int:
    """Entry point of ``ros2 run hasel_control reference_generator``."""
    return run_node(ReferenceNode, args)
