"""Low-pass filter node: the strain sensor's 40 Hz 2nd-order digital filter at the loop rate.

Design (see :mod:`hasel.filters`): Butterworth prototype, bilinear transform with the
cut-off pre-warped, so the -3 dB point is exactly ``cutoff_hz`` at ``rate_hz``
(40 Hz at 200 Hz by default); unity DC gain. Subscribes ``/strain/stroke``,
publishes ``/strain/stroke_filtered`` with the input's stamp. A non-finite sample is
passed on as NaN without entering the filter, so one bad reading cannot poison the
filter's state (the decision is :class:`hasel.channels.FilterChannel`'s).
"""
from __future__ import annotations

from collections.abc import Sequence

from rclpy.node import Node

from hasel import paper
from hasel.channels import FilterChannel
from hasel_ros.rosutil import declare, run_node, topic_qos
from hasel_msgs.msg import Stroke

__all__ = ["LowPassNode", "main"]


class LowPassNode(Node):
    """The filter; parameters cutoff_hz, rate_hz (read-only after start), topics."""

    def __init__(self, **kwargs) -> None:
        super().__init__("lowpass_filter", **kwargs)
        cutoff = declare(self, "cutoff_hz", paper.FILTER_CUTOFF_HZ, "-3 dB frequency, Hz", lo=0.1, hi=99.0,
                         read_only=True)
        rate = declare(self, "rate_hz", 1.0 / paper.LOOP_PERIOD_S, "sample rate of the input, Hz", lo=1.0,
                       hi=10000.0, read_only=True)
        in_topic = declare(self, "input_topic", "strain/stroke", "stroke to filter")
        out_topic = declare(self, "output_topic", "strain/stroke_filtered", "filtered stroke")
        self.channel = FilterChannel(cutoff, rate)
        self.pub = self.create_publisher(Stroke, out_topic, topic_qos("/strain/stroke_filtered"))
        self._out = Stroke(source=Stroke.SOURCE_STRAIN_FILTERED)
        self.sub = self.create_subscription(Stroke, in_topic, self.on_stroke, topic_qos("/strain/stroke"))

    def on_stroke(self, msg: Stroke) -> None:
        """Filter one sample; the output keeps its stamp."""
        out = self._out  # one message object, refilled: publish() copies it at once
        out.stroke_mm = self.channel(msg.stroke_mm)
        out.header = msg.header
        self.pub.publish(out)


def main(args: Sequence[str] | None = None) -> int:
    """Entry point of ``ros2 run hasel_driver lowpass_filter``."""
    return run_node(LowPassNode, args)
