"""Serial bridge to a real rig: the MCU that times the 555 and drives the amplifier's DAC.

Protocol: :mod:`hasel.serialproto` (NMEA-style ASCII lines with an XOR checksum).
From the MCU it publishes ``/sensor/timing`` (``T`` frames) and ``/laser/stroke``
(``L`` frames) stamped with the host's receive time; to the MCU it forwards every
``/amp/applied`` command as a ``V`` frame (the amplifier node's limits have already
acted; the firmware clamps again) and sends a heartbeat ``H`` every loop period.

Lost link: when no frame has arrived from the MCU for ``link_timeout_periods`` loop
periods, the bridge sends ``Z`` (0 kV), stops publishing sensor data (the controller
then sees stale input and the amplifier node's watchdog holds 0 kV) and reports a
diagnostic ERROR; the firmware itself drives 0 kV after three periods without a host
frame, so a dead host, cable or bridge also ends at 0 kV. Shutdown sends ``Z``.
"""
from __future__ import annotations

import time
from collections.abc import Sequence

from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus
from rclpy.clock import Clock, ClockType
from rclpy.node import Node

from hasel import paper
from hasel.errors import BadInputError
from hasel.serialproto import LineBuffer, encode
from hasel_ros.rosutil import declare, diagnostic, now_s, run_node, topic_qos
from hasel_msgs.msg import SensorTiming, Stroke, VoltageCommand

__all__ = ["SerialBridgeNode", "main"]


class SerialBridgeNode(Node):
    """Parameters: port, baud, period_s, link_timeout_periods."""

    def __init__(self, **kwargs) -> None:
        super().__init__("serial_bridge", **kwargs)
        port = declare(self, "port", "", "serial device of the MCU, e.g. /dev/ttyACM0", read_only=True)
        baud = declare(self, "baud", 115200, "baud rate", lo=1200, hi=12_000_000, read_only=True)
        self.period_s = declare(self, "period_s", paper.LOOP_PERIOD_S, "loop period, s", lo=1e-4, hi=1.0,
                                read_only=True)
        self.timeout_periods = declare(self, "link_timeout_periods", 3.0, "silence that counts as a lost link, periods",
                                       lo=1.0, hi=100.0)
        if not port:
            raise BadInputError("parameter 'port' is required (e.g. -p port:=/dev/ttyACM0)")
        import serial  # pyserial

        try:
            self.serial = serial.Serial(port, baud, timeout=0, write_timeout=0.05)
        except (serial.SerialException, OSError) as err:
            raise BadInputError(f"cannot open {port}: {err}") from err
        self.lines = LineBuffer()
        self.seq = 0
        self.last_rx = time.monotonic()
        self.link_ok = True
        self.rx_frames = 0
        self.timing_pub = self.create_publisher(SensorTiming, "sensor/timing", topic_qos("/sensor/timing"))
        self.laser_pub = self.create_publisher(Stroke, "laser/stroke", topic_qos("/laser/stroke"))
        self.diag_pub = self.create_publisher(DiagnosticArray, "/diagnostics", topic_qos("/diagnostics"))
        self.create_subscription(VoltageCommand, "amp/applied", self.on_applied, topic_qos("/amp/applied"))
        steady = Clock(clock_type=ClockType.STEADY_TIME)
        self.create_timer(min(self.period_s / 5, 0.001), self.on_poll, clock=steady)  # read often: low latency
        self.create_timer(self.period_s, self.on_heartbeat, clock=steady)

    def _send(self, kind: str, *fields: float) -> None:
        self.seq = (self.seq + 1) % 2**32
        try:
            self.serial.write(encode(kind, self.seq, *fields))
        except Exception as err:  # noqa: BLE001 - a broken port is a lost link, reported below
            self.get_logger().error(f"serial write failed: {err}", throttle_duration_sec=1.0)

    def on_applied(self, msg: VoltageCommand) -> None:
        """Forward the amplifier node's applied command to the DAC."""
        if self.link_ok:
            self._send("V", msg.applied_kv)
        else:
            self._send("Z")

    def on_heartbeat(self) -> None:
        """Heartbeat to the MCU, and the lost-link check."""
        self._send("H", int(time.monotonic() * 1e6))
        silent = time.monotonic() - self.last_rx
        if self.link_ok and silent > self.timeout_periods * self.period_s:
            self.link_ok = False
            self._send("Z")
            self.diag_pub.publish(diagnostic(self, DiagnosticStatus.ERROR, "MCU link lost: 0 kV commanded",
                                             now_s(self), silent_s=silent,
                                             bad_lines=self.lines.bad))

    def on_poll(self) -> None:
        """Read what arrived; publish sensor frames."""
        try:
            data = self.serial.read(4096)
        except Exception:  # noqa: BLE001 - port gone: the heartbeat check reports the lost link
            return
        if not data:
            return
        now = self.get_clock().now().to_msg()
        for f in self.lines.feed(data):
            self.last_rx = time.monotonic()
            self.rx_frames += 1
            if not self.link_ok:
                self.link_ok = True
                self.diag_pub.publish(diagnostic(self, DiagnosticStatus.OK, "MCU link back",
                                                 now_s(self)))
            if f.kind == "T":
                m = SensorTiming(elapsed_us=f.fields[2], period_us=1e6 / paper.TIMER_TRIGGER_HZ,
                                 sequence=int(f.fields[0]) % 2**32)
                m.header.stamp = now
                self.timing_pub.publish(m)
            elif f.kind == "L":
                m = Stroke(stroke_mm=f.fields[2], source=Stroke.SOURCE_LASER)
                m.header.stamp = now
                self.laser_pub.publish(m)

    def on_shutdown(self) -> None:
        """0 kV on the way out."""
        try:
            self._send("Z")
            self.serial.flush()
        except Exception:  # noqa: BLE001
            pass


def main(args: Sequence[str] | None = None) -> int:
    """Entry point of ``ros2 run hasel_driver serial_bridge --ros-args -p port:=/dev/ttyACM0``."""
    return run_node(SerialBridgeNode, args)
