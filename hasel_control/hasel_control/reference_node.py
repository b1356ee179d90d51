"""Reference generator node: the paper's step sequence 2 -> 4 -> 6 -> 4 -> 2 mm.

Publishes the whole sequence on ``/reference`` at start, each value stamped with the
time it takes effect (``start_s + i * hold_s``, or after the holds ``holds_s`` when they are
given, one per value: a rig's uneven test replayed; on the node's clock, which is simulated
time under use_sim_time). The topic is latched (transient local), so a controller that
starts later still receives the schedule.
"""
from __future__ import annotations

import math
from collections.abc import Sequence

from rcl_interfaces.msg import ParameterDescriptor
from rclpy.node import Node
from rclpy.parameter import Parameter

from hasel import paper
from hasel.errors import BadInputError
from hasel.metrics import reference_starts
from hasel_ros.rosutil import declare, now_s, run_node, to_stamp, topic_qos
from hasel_msgs.msg import Reference

__all__ = ["ReferenceNode", "main"]


class ReferenceNode(Node):
    """Parameters: sequence_mm (list, mm), hold_s (s), holds_s (list, s; one per value, overrides
    hold_s), start_s (s; negative = now)."""

    def __init__(self, **kwargs) -> None:
        super().__init__("reference_generator", **kwargs)
        self.sequence = [float(x) for x in declare(self, "sequence_mm", list(paper.STEP_SEQUENCE_MM),
                                                   "stroke references, mm")]
        self.hold_s = declare(self, "hold_s", 1.0, "time per reference, s", lo=0.005, hi=1e6)
        holds = self.declare_parameter("holds_s", Parameter.Type.DOUBLE_ARRAY, ParameterDescriptor(
            description="time per reference, one per value, s (unset: hold_s for each)")).value
        start = declare(self, "start_s", -1.0, "time of the first reference, s (negative: now)", lo=-1.0, hi=1e9)
        if not self.sequence or not all(math.isfinite(x) for x in self.sequence):
            raise BadInputError(f"sequence_mm must be a non-empty list of finite numbers, got {self.sequence}")
        self.start_s = start if start >= 0 else now_s(self)
        self.starts_s = self.start_s + reference_starts(len(self.sequence), self.hold_s if holds is None else list(holds))
        self.pub = self.create_publisher(Reference, "reference", topic_qos("/reference"))
        for t, r in zip(self.starts_s, self.sequence):
            msg = Reference(stroke_mm=r)
            msg.header.stamp = to_stamp(float(t))
            self.pub.publish(msg)

    @property
    def end_s(self) -> float:
        """Time the last reference ends, s."""
        return float(self.starts_s[-1])


def main(args: Sequence[str] | None = None) -> int:
    """Entry point of ``ros2 run hasel_control reference_generator``."""
    return run_node(ReferenceNode, args)
