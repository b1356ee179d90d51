"""The node graph's topics, their message types and their QoS, stated once.

QoS choices (ROS-free description; the nodes turn it into rclpy profiles):

- sensor streams (raw timing, laser, strain stroke, filtered stroke): best effort,
  keep last 10. A late sensor sample is worthless to a 200 Hz loop; retransmitting it
  would only add latency.
- batched 10 kHz samples: reliable, keep last 50, so a recorder keeps every sample.
- commands (controller -> amplifier -> plant) and controller state: reliable, keep
  last 10. A lost command is a safety event, not noise.
- reference and experiment markers: reliable, transient local (latched): a node that
  starts late still gets the current reference and the markers.
- /clock: best effort, keep last 1 (as ROS 2 publishes simulated time).
- /diagnostics: reliable, keep last 10.
"""
from __future__ import annotations

from dataclasses import dataclass

__all__ = ["QosSpec", "Topic", "TOPICS", "SENSOR", "BATCH", "COMMAND", "LATCHED", "CLOCK", "topic"]


@dataclass(frozen=True)
class QosSpec:
    """A QoS profile in plain values: reliability, durability, history depth."""

    reliable: bool
    transient_local: bool
    depth: int


SENSOR = QosSpec(reliable=False, transient_local=False, depth=10)
BATCH = QosSpec(reliable=True, transient_local=False, depth=50)
COMMAND = QosSpec(reliable=True, transient_local=False, depth=10)
LATCHED = QosSpec(reliable=True, transient_local=True, depth=1000)
CLOCK = QosSpec(reliable=False, transient_local=False, depth=1)


@dataclass(frozen=True)
class Topic:
    """A topic of the graph: default name, message type, QoS, and what it carries."""

    name: str
    type: str
    qos: QosSpec
    doc: str


TOPICS: dict[str, Topic] = {t.name: t for t in [
    Topic("/clock", "rosgraph_msgs/msg/Clock", CLOCK, "simulated time (plant, sim mode)"),
    Topic("/sensor/timing", "hasel_msgs/msg/SensorTiming", SENSOR, "555 elapsed time at each 200 Hz tick"),
    Topic("/laser/stroke", "hasel_msgs/msg/Stroke", SENSOR, "laser stroke at each tick, mm"),
    Topic("/strain/stroke", "hasel_msgs/msg/Stroke", SENSOR, "strain-sensor stroke after calibration, mm"),
    Topic("/strain/stroke_filtered", "hasel_msgs/msg/Stroke", SENSOR, "the same after the 40 Hz low-pass, mm"),
    Topic("/plant/batch", "hasel_msgs/msg/SampleBatch", BATCH, "10 kHz samples: applied kV, laser mm, true mm, 555 us"),
    Topic("/reference", "hasel_msgs/msg/Reference", LATCHED, "stroke reference, mm, effective at its stamp"),
    Topic("/amp/command", "hasel_msgs/msg/VoltageCommand", COMMAND, "controller's request to the amplifier, kV"),
    Topic("/amp/command_batch", "hasel_msgs/msg/SampleBatch", BATCH, "open-loop 10 kHz request (voltage_kv), kV"),
    Topic("/amp/precondition", "hasel_msgs/msg/VoltageCommand", COMMAND, "deliberate charge reversal (-1 kV)"),
    Topic("/amp/applied", "hasel_msgs/msg/VoltageCommand", COMMAND, "amplifier command after the hard limits, kV"),
    Topic("/amp/applied_batch", "hasel_msgs/msg/SampleBatch", BATCH, "open-loop 10 kHz command after the limits, kV"),
    Topic("/controller/state", "hasel_msgs/msg/ControllerState", COMMAND, "dual-mode PID state each tick"),
    Topic("/markers", "hasel_msgs/msg/ExperimentMarker", LATCHED, "experiment segments (operating points)"),
    Topic("/diagnostics", "diagnostic_msgs/msg/DiagnosticArray", COMMAND, "clamp, watchdog, sensor faults"),
]}


def topic(name: str) -> Topic:
    """The :class:`Topic` of a default topic name (KeyError lists the known ones)."""
    try:
        return TOPICS[name]
    except KeyError:
        raise KeyError(f"unknown topic {name!r}; known: {', '.join(TOPICS)}") from None
