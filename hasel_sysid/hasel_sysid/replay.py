"""``hasel replay FILE`` and ``hasel record``: MCAP logs back into the graph, and recording.

Replay publishes each recorded message, raw (the recorded CDR bytes, no decoding), on
its topic (or a remapped one), in log-time order, with the recorded timing scaled by
``--rate`` (``--rate 0``: as fast as possible). ``--clock`` also publishes ``/clock``
from the log times, so nodes under use_sim_time run on the log's time. QoS: what the
log's ``offered_qos_profiles`` says, made reliable with a deep queue so that fast replay
drops nothing.
"""
from __future__ import annotations

import argparse
import signal
import time
from collections.abc import Iterator, Sequence
from pathlib import Path

import rclpy
from rclpy.node import Node
from rclpy.signals import SignalHandlerOptions
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
from rosgraph_msgs.msg import Clock as ClockMsg

from hasel import interrupt
from hasel.errors import BadInputError
from hasel.io.mcapfile import RawMessage, iter_messages
from hasel.timeconv import ns_to_s, ns_to_stamp
from hasel_ros.rosutil import message_class

__all__ = ["RawMessage", "read_raw", "Replayer", "parse_remaps", "run_replay", "run_record"]


def read_raw(path: str | Path, topics: Sequence[str] | None = None) -> Iterator[RawMessage]:
    """Recorded messages of ``path`` in log-time order, streamed by the project's MCAP reader.

    Raises
    ------
    BadInputError
        No such file.
    DataFileError
        A damaged or non-MCAP file (says where; ``hasel info`` and ``hasel salvage`` help).
    """
    p = Path(path)
    if not p.is_file():
        raise BadInputError(f"no such file: {p}")
    return iter_messages(p, topics)


def parse_remaps(remaps: Sequence[str]) -> dict[str, str]:
    """``["/a:=/b", ...]`` -> ``{"/a": "/b"}``."""
    out = {}
    for r in remaps:
        if ":=" not in r:
            raise BadInputError(f"a remap is FROM:=TO, got {r!r}")
        a, b = r.split(":=", 1)
        if not a.startswith("/") or not b.startswith("/"):
            raise BadInputError(f"remapped topics must be absolute (/name), got {r!r}")
        out[a] = b
    return out


class Replayer:
    """Publishes recorded messages through ``node``; one call of :meth:`publish` per message."""

    def __init__(self, node: Node, remap: dict[str, str] | None = None, clock: bool = False) -> None:
        self.node = node
        self.remap = remap or {}
        self.pubs: dict[str, object] = {}
        self.clock_pub = node.create_publisher(ClockMsg, "/clock", 10) if clock else None
        self.count = 0

    def publisher(self, topic: str, type_name: str):
        """The (cached) raw publisher of a recorded topic."""
        pub = self.pubs.get(topic)
        if pub is None:
            try:
                cls = message_class(type_name)
            except ValueError as err:
                raise BadInputError(f"cannot replay {topic}: {err}") from err
            profile = QoSProfile(depth=1000, reliability=ReliabilityPolicy.RELIABLE,
                                 durability=DurabilityPolicy.VOLATILE)
            pub = self.node.create_publisher(cls, self.remap.get(topic, topic), profile)
            self.pubs[topic] = pub
        return pub

    def publish(self, m: RawMessage) -> None:
        """Publish one recorded message (and /clock at its log time when asked)."""
        if self.clock_pub is not None and m.topic != "/clock":
            c = ClockMsg()
            c.clock.sec, c.clock.nanosec = ns_to_stamp(m.log_time_ns)
            self.clock_pub.publish(c)
        self.publisher(m.topic, m.type_name).publish(m.data)
        self.count += 1


def run_replay(args: argparse.Namespace) -> int:
    """CLI: ``hasel replay FILE [--rate R] [--topics ...] [--remap FROM:=TO] [--clock]``."""
    if not 0 <= args.rate < float("inf"):
        raise BadInputError(f"--rate must be >= 0 (0: as fast as possible), got {args.rate}")
    if not 0 <= args.wait <= 3600:
        raise BadInputError(f"--wait must be between 0 and 3600 s, got {args.wait}")
    remap = parse_remaps(args.remap or [])
    topics = [t for t in (args.topics or "").split(",") if t] or None
    first = next(read_raw(args.file, topics), None)  # validates the file before ROS starts
    if first is None:
        raise BadInputError(f"{args.file}: no messages{' on ' + ','.join(topics) if topics else ''}")
    rclpy.init(signal_handler_options=SignalHandlerOptions.NO)  # hasel.interrupt handles the signals
    node = rclpy.create_node("hasel_replay")
    rep = Replayer(node, remap, clock=args.clock)
    try:
        # publishers first, then a moment for discovery so the first messages are not lost
        for m in read_raw(args.file, topics):
            rep.publisher(m.topic, m.type_name)
        time.sleep(args.wait)
        t0_log, t0_wall = None, time.monotonic()
        for m in read_raw(args.file, topics):
            if t0_log is None:
                t0_log = m.log_time_ns
            if args.rate > 0:
                due = t0_wall + ns_to_s(m.log_time_ns - t0_log) / args.rate
                delay = due - time.monotonic()
                if delay > 0:
                    time.sleep(delay)
            rep.publish(m)
        time.sleep(0.2)
    finally:
        node.destroy_node()
        rclpy.try_shutdown()
    print(f"replayed {rep.count} messages on {len(rep.pubs)} topics from {args.file}")
    return 0


def run_record(args: argparse.Namespace) -> int:
    """CLI: ``hasel record -o FILE.mcap [--topics a,b] [--duration S]``: until the duration or a signal.

    SIGINT, SIGTERM and SIGHUP stop it alike: the spin loop notices the flag the handler
    set, the file is closed with its summary and footer, and the command exits with
    128 + the signal number (a complete file either way).
    """
    from rclpy.executors import SingleThreadedExecutor

    from hasel_sysid.recorder_node import RecorderNode

    out = Path(args.output)
    if args.duration is not None and not (args.duration > 0 and args.duration < float("inf")):
        raise BadInputError(f"--duration must be a positive number of seconds, got {args.duration}")
    out.parent.mkdir(parents=True, exist_ok=True)
    topics = [t for t in (args.topics or "").split(",") if t] or None
    with interrupt.deferred():
        rclpy.init(signal_handler_options=SignalHandlerOptions.NO)
        node = None
        try:
            node = RecorderNode(str(out), topics)
            ex = SingleThreadedExecutor()
            ex.add_node(node)
            end = None if args.duration is None else time.monotonic() + args.duration
            while not interrupt.requested() and (end is None or time.monotonic() < end):
                ex.spin_once(timeout_sec=0.1)
        finally:
            if node is not None:
                node.destroy_node()  # closes the file: summary and footer
            rclpy.try_shutdown()
    total = sum(node.counts.values())
    stopped = f" (stopped by {signal.Signals(interrupt.requested()).name})" if interrupt.requested() else ""
    print(f"recorded {total} messages on {sum(1 for c in node.counts.values() if c)} topics to {out}{stopped}")
    interrupt.check()
    return 0
