"""MCAP recorder node: every chosen topic, as raw serialized CDR, the way rosbag2 writes it.

Subscriptions are raw (``raw=True``): the bytes DDS delivered go to the file without a
deserialize/serialize round trip. The file has rosbag2's MCAP layout (profile ``ros2``,
``ros2msg`` schemas with the full definition text, ``cdr`` channels with
``offered_qos_profiles``, zstd chunks); see :class:`hasel.io.writer.Ros2McapWriter`.
log_time is the recorder's clock when a message arrives (simulated time under
use_sim_time, as rosbag2 does), publish_time the publisher's source timestamp when the
executor provides it.

Topics: the parameter ``topics`` (empty: all of the graph's topics, plus any other
topic that appears, discovered every second with its publishers' QoS).
Nothing lost: on SIGINT/SIGTERM or shutdown the file is closed with its summary and
footer; chunks are flushed to disk as they close, so a SIGKILL loses at most the chunk
being filled, and ``hasel salvage`` recovers the rest.
"""
from __future__ import annotations

from collections.abc import Sequence

from rclpy.clock import Clock, ClockType
from rclpy.node import Node
from rclpy.qos import QoSProfile, ReliabilityPolicy

from hasel.io.writer import QosProfile, Ros2McapWriter
from hasel.topics import TOPICS
from hasel_ros.rosutil import declare, message_class, qos, run_node

__all__ = ["RecorderNode", "main"]


def _qos_record(profile: QoSProfile) -> QosProfile:
    """An rclpy QoS profile as the writer records it (rmw enum values)."""
    return QosProfile(history=int(profile.history), depth=int(profile.depth),
                      reliability=int(profile.reliability), durability=int(profile.durability))


class RecorderNode(Node):
    """Records topics to ``path``. Parameters: path, topics, discover, chunk_size, compression."""

    def __init__(self, path: str | None = None, topics: Sequence[str] | None = None, **kwargs) -> None:
        super().__init__("hasel_recorder", **kwargs)
        self.path = declare(self, "path", path or "hasel.mcap", "MCAP file to write", read_only=True)
        chosen = declare(self, "topics", list(topics) if topics else [""],
                         "topics to record ([''] = all of the graph's and any discovered)", read_only=True)
        self.discover = declare(self, "discover", not topics, "also record topics that appear later",
                                read_only=True)
        chunk = declare(self, "chunk_size", 768 * 1024, "uncompressed chunk size, bytes", lo=1024, hi=1 << 30,
                        read_only=True)
        comp = declare(self, "compression", "zstd", "zstd | lz4 | none", read_only=True)
        self.writer = Ros2McapWriter(self.path, chunk_size=chunk, compression=comp)
        self.writer.add_metadata("hasel", {"recorder": "hasel_sysid/recorder", "clock":
                                           "sim" if self.get_parameter("use_sim_time").value else "wall"})
        self.counts: dict[str, int] = {}
        self._subs = {}
        names = [t for t in chosen if t] or [t for t in TOPICS]
        for name in names:
            if name in TOPICS:
                self._record(name, TOPICS[name].type, qos(TOPICS[name].qos))
        self._pending = [t for t in names if t not in TOPICS]
        if self.discover or self._pending:
            self.create_timer(1.0, self._discover, clock=Clock(clock_type=ClockType.STEADY_TIME))

    def _record(self, name: str, type_name: str, profile: QoSProfile, offered=None) -> None:
        if name in self._subs:
            return
        msg_type = message_class(type_name)
        # the graph's topics are relative (a namespaced graph records its own); /clock and
        # /diagnostics stay global
        sub_name = name if name in ("/clock", "/diagnostics") or name not in TOPICS else name.lstrip("/")
        self.counts[name] = 0
        clock = self.get_clock()
        write = self.writer.write
        cid_box: list[int] = []

        def on_message(data: bytes, info=None, _name=name) -> None:
            now = clock.now().nanoseconds
            pub = info.get("source_timestamp", now) if isinstance(info, dict) else now
            write(cid_box[0], data, now, pub or now)
            self.counts[_name] += 1

        sub = self.create_subscription(msg_type, sub_name, on_message, profile, raw=True)
        cid_box.append(self.writer.add_topic(sub.topic_name, type_name, qos=offered or _qos_record(profile)))
        self._subs[name] = sub

    def _discover(self) -> None:
        """Subscribe to topics that appeared (all, or the requested ones not yet seen)."""
        for name, types in self.get_topic_names_and_types():
            if name in self._subs or not types or name == "/rosout" and not self._pending:
                continue
            if not self.discover and name not in self._pending:
                continue
            infos = self.get_publishers_info_by_topic(name)
            if not infos:
                continue
            offered = [_qos_record(i.qos_profile) for i in infos]
            best_effort = any(i.qos_profile.reliability == ReliabilityPolicy.BEST_EFFORT for i in infos)
            profile = QoSProfile(depth=100, reliability=ReliabilityPolicy.BEST_EFFORT if best_effort
                                 else ReliabilityPolicy.RELIABLE)
            try:
                self._record(name, types[0], profile, offered)
            except Exception as err:  # noqa: BLE001 - an unknown type must not stop the recording
                self.get_logger().warning(f"not recording {name} ({types[0]}): {err}")
                self._subs[name] = None

    def on_shutdown(self) -> None:
        """Close the file: summary and footer written, so it is complete and valid."""
        if not self.writer.closed:
            self.writer.close()

    def destroy_node(self) -> None:
        """Closing the node closes the file."""
        self.on_shutdown()
        super().destroy_node()


def main(args: Sequence[str] | None = None) -> int:
    """Entry point of ``ros2 run hasel_sysid recorder --ros-args -p path:=run.mcap``."""
    return run_node(RecorderNode, args)
