"""Strain-sensor driver node: 555 elapsed time (us) -> stroke (mm) through the calibration.

Subscribes ``/sensor/timing`` (hasel_msgs/SensorTiming), publishes ``/strain/stroke``
(hasel_msgs/Stroke, source STRAIN) with the reading's own stamp. The calibration is
a YAML file written by ``hasel calibrate`` (parameter ``calibration_file``) or, when
that is empty, the line ``slope_mm_per_us`` / ``offset_mm``. A non-finite or
non-positive elapsed time gives a NaN stroke, which the controller treats as missing
(the decision is :class:`hasel.channels.StrainChannel`'s).
"""
from __future__ import annotations

from collections.abc import Sequence

from rclpy.node import Node

from hasel.calibration import Calibration
from hasel.channels import StrainChannel, default_calibration
from hasel_ros.rosutil import declare, run_node, topic_qos, validate_with
from hasel_msgs.msg import SensorTiming, Stroke

__all__ = ["StrainDriverNode", "main"]


class StrainDriverNode(Node):
    """The driver; parameters: calibration_file, slope_mm_per_us, offset_mm, topics."""

    def __init__(self, **kwargs) -> None:
        super().__init__("strain_driver", **kwargs)
        ideal = default_calibration()
        self.calibration_file = declare(self, "calibration_file", "", "YAML from `hasel calibrate` ('' = use slope/offset)")
        slope = declare(self, "slope_mm_per_us", ideal.slope_mm_per_us, "calibration slope, mm/us", lo=-100.0, hi=100.0)
        offset = declare(self, "offset_mm", ideal.offset_mm, "calibration offset, mm", lo=-1e4, hi=1e4)
        in_topic = declare(self, "input_topic", "sensor/timing", "raw 555 timing topic")
        out_topic = declare(self, "output_topic", "strain/stroke", "calibrated stroke topic")
        self.calibration = (Calibration.from_yaml(self.calibration_file) if self.calibration_file
                            else Calibration.line(slope, offset, "parameters"))
        self.add_on_set_parameters_callback(validate_with(self._check))
        self.pub = self.create_publisher(Stroke, out_topic, topic_qos("/strain/stroke"))
        self._out = Stroke(source=Stroke.SOURCE_STRAIN)
        self.sub = self.create_subscription(SensorTiming, in_topic, self.on_timing, topic_qos("/sensor/timing"))
        self.get_logger().info(f"calibration {self.calibration.coeffs} ({self.calibration.source})")

    def _check(self, new: dict) -> None:
        if "calibration_file" in new and new["calibration_file"]:
            self.calibration = Calibration.from_yaml(new["calibration_file"])
        if "slope_mm_per_us" in new or "offset_mm" in new:
            slope = new.get("slope_mm_per_us", self.calibration.slope_mm_per_us)
            offset = new.get("offset_mm", self.calibration.offset_mm)
            self.calibration = Calibration.line(slope, offset, "parameters")

    @property
    def calibration(self) -> Calibration:
        """The calibration in use (elapsed time us -> stroke mm)."""
        return self.channel.calibration

    @calibration.setter
    def calibration(self, cal: Calibration) -> None:
        self.channel = StrainChannel(cal)

    def on_timing(self, msg: SensorTiming) -> None:
        """Convert one reading; the output keeps the reading's stamp."""
        out = self._out  # one message object, refilled: publish() copies it at once
        out.stroke_mm = self.channel(msg.elapsed_us)
        out.header = msg.header
        self.pub.publish(out)


def main(args: Sequence[str] | None = None) -> int:
    """Entry point of ``ros2 run hasel_driver strain_driver``."""
    return run_node(StrainDriverNode, args)
