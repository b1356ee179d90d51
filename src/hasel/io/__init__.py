"""ROS-free MCAP and CSV I/O: write logs as rosbag2 does, read them fast, survive damage.

- :class:`Ros2McapWriter` writes ROS 2 MCAP logs (rosbag2's layout) from the CDR bytes
  rclpy received; :func:`message_definition` builds the schema text.
- :func:`load_signals` reads numeric fields (batched samples unrolled),
  :func:`load_markers` the experiment markers, :func:`load_io` an input/output record
  from ``.mcap``, ``.csv`` or ``.mat``.
- :func:`iter_messages` streams the raw messages in log-time order (replay).
- :func:`info` and :func:`salvage` summarise and repair damaged files.

Times: float seconds in the API, integer nanoseconds only in MCAP records
(:mod:`hasel.timeconv`).
"""
from hasel.io.cdr import CdrError
from hasel.io.dataset import IOData, load_io
from hasel.io.info import InfoReport, TopicStats, format_info, info
from hasel.io.loader import (
    Marker, MarkerSegment, Segment, Signal, TopicInfo, list_topics, load_markers, load_signals,
    load_signals_and_markers, marker_segments,
)
from hasel.io.mcapfile import RawMessage, iter_messages
from hasel.io.msgdefs import MessageDefinitionError, message_definition, type_hash
from hasel.io.salvage import SalvageReport, salvage
from hasel.io.writer import QosProfile, Ros2McapWriter, offered_qos_yaml

__all__ = [
    "Ros2McapWriter", "QosProfile", "offered_qos_yaml", "message_definition", "type_hash",
    "MessageDefinitionError", "CdrError", "RawMessage", "iter_messages",
    "Signal", "TopicInfo", "Marker", "Segment", "MarkerSegment", "list_topics", "load_signals", "load_markers",
    "load_signals_and_markers", "marker_segments", "IOData", "load_io", "InfoReport", "TopicStats", "info", "format_info",
    "SalvageReport", "salvage",
]
