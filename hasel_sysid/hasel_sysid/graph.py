"""The closed-loop node graph built in one process (no launch files) and run in lockstep.

Nodes: sim_plant, strain_driver, lowpass_filter, pid_controller, hv_amplifier,
reference_generator, plus a collector that keeps what the experiment commands need
(and, optionally, the MCAP recorder). Each node is the same class that
``ros2 run <pkg> <exe>`` starts; here they share one executor and their own rclpy
Context, so several graphs can live in one process (tests) without interfering.

Executor: rclpy's EventsExecutor (experimental in Jazzy) by default: a message hop
costs about 14 us there against about 175 us in the SingleThreadedExecutor, and the
graph is driven by messages in lockstep with simulated time, which it handles.
"""
from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np
import rclpy
import rclpy.logging
from rclpy.context import Context
from rclpy.task import Future
from rclpy.executors import SingleThreadedExecutor
from rclpy.node import Node
from rclpy.parameter import Parameter
from rclpy.time_source import TimeSource

from hasel import interrupt, paper
from hasel.errors import HaselError
from hasel.plant import Actuator
from hasel.timeconv import ns_to_s
from hasel_control.amplifier_node import HvAmplifierNode
from hasel_control.controller_node import PidControllerNode
from hasel_control.reference_node import ReferenceNode
from hasel_driver.driver_node import StrainDriverNode
from hasel_driver.filter_node import LowPassNode
from hasel_ros.rosutil import from_stamp, topic_qos
from hasel_msgs.msg import ControllerState, SampleBatch, Stroke, VoltageCommand
from sim_plant.plant_node import PlantNode

__all__ = ["GraphConfig", "Collector", "NodeGraph", "make_executor", "share_sim_clock"]


def make_executor(kind: str, context: Context):
    """'events' (rclpy.experimental.EventsExecutor) or 'single' (SingleThreadedExecutor)."""
    if kind == "events":
        from rclpy.experimental import EventsExecutor

        return EventsExecutor(context=context)
    if kind == "single":
        return SingleThreadedExecutor(context=context)
    raise HaselError(f"unknown executor {kind!r}")


@dataclass
class GraphConfig:
    """What to build. Times in s, strokes in mm."""

    feedback: str = "laser"
    sequence_mm: list[float] = field(default_factory=lambda: list(paper.STEP_SEQUENCE_MM))
    hold_s: float = 1.0
    holds_s: list[float] | None = None  # one hold per reference value (s), overriding hold_s
    seed: int = 0
    variant: str = "nominal"
    actuator: Actuator | None = None
    calibration_file: str = ""
    controller_params: dict = field(default_factory=dict)
    amplifier_params: dict = field(default_factory=dict)
    plant_params: dict = field(default_factory=dict)
    with_reference: bool = True
    with_controller: bool = True
    with_collector: bool = True  # keep the signals in memory (experiments that only record need not)
    executor: str = "events"
    domain_id: int | None = None  # None: a private domain claimed for this process
    shared_clock: bool = True  # one /clock subscription for the process (see share_sim_clock)


def share_sim_clock(nodes: list[Node], keeper: Node) -> TimeSource:
    """Drive the simulated clocks of ``nodes`` from one ``/clock`` subscription (on ``keeper``).

    Under ``use_sim_time`` every rclpy node subscribes to ``/clock`` itself, so in a
    process of seven nodes each tick delivers the same time seven times, each a
    Python callback that sets one clock (about 13 % of a lockstep tick, measured).
    Here the nodes keep ``use_sim_time`` (their timers and ``now()`` follow simulated
    time, as before) but their own ``/clock`` subscriptions are dropped and their
    clocks are attached to one :class:`rclpy.time_source.TimeSource` on ``keeper``.
    Raw subscriptions to ``/clock`` (the recorder's) are left alone.

    Returns the shared time source (keep it alive as long as the nodes).
    """
    shared = TimeSource()
    for n in nodes:
        for sub in list(n.subscriptions):
            if sub.topic_name == "/clock" and isinstance(getattr(sub.callback, "__self__", None), TimeSource):
                n.destroy_subscription(sub)
        if n.get_parameter("use_sim_time").value:
            shared.attach_clock(n.get_clock())
    shared.attach_node(keeper)  # subscribes once, since the keeper has use_sim_time
    return shared


class Collector(Node):
    """Keeps the graph's signals in memory: 10 kHz batches and 200 Hz command/state."""

    def __init__(self, **kwargs) -> None:
        super().__init__("hasel_collector", **kwargs)
        self.batches: list[SampleBatch] = []
        self.applied: list[tuple[float, float, float, int]] = []
        self.states: list[ControllerState] = []
        self.filtered: list[tuple[float, float]] = []
        self.create_subscription(SampleBatch, "plant/batch", self.batches.append, topic_qos("/plant/batch"))
        self.create_subscription(VoltageCommand, "amp/applied", self._on_applied, topic_qos("/amp/applied"))
        self.create_subscription(ControllerState, "controller/state", self.states.append,
                                 topic_qos("/controller/state"))
        self.create_subscription(Stroke, "strain/stroke_filtered",
                                 lambda m: self.filtered.append((from_stamp(m.header.stamp), m.stroke_mm)),
                                 topic_qos("/strain/stroke_filtered"))

    def _on_applied(self, m: VoltageCommand) -> None:
        self.applied.append((from_stamp(m.header.stamp), m.requested_kv, m.applied_kv, m.reason))

    def samples(self) -> dict[str, np.ndarray]:
        """The 10 kHz signals unrolled: t_s, voltage_kv, stroke_mm (laser), true_stroke_mm, elapsed_us."""
        if not self.batches:
            return {k: np.empty(0) for k in ("t_s", "voltage_kv", "stroke_mm", "true_stroke_mm", "elapsed_us")}
        t = np.concatenate([from_stamp(b.header.stamp) + b.sample_period_s * np.arange(len(b.voltage_kv))
                            for b in self.batches])
        out = {"t_s": t}
        for name in ("voltage_kv", "stroke_mm", "true_stroke_mm", "elapsed_us"):
            out[name] = np.concatenate([np.asarray(getattr(b, name)) for b in self.batches])
        return out


class NodeGraph:
    """Builds, runs and tears down one closed-loop graph in simulated time."""

    def __init__(self, config: GraphConfig | None = None, extra_nodes: list[Callable[[Context], Node]] = (),
                 quiet: bool = True):
        self.config = cfg = config or GraphConfig()
        # from here to the end of close() a stop signal is only recorded: run() polls it
        # and stops, close() commands 0 kV and closes every file, then it is raised
        self._deferred = interrupt.deferred()
        self._deferred.__enter__()
        self.context = Context()
        # a private domain: nothing outside this job can reach into the graph, or hear it
        from hasel.rosenv import private_domain

        self.domain_id = private_domain() if cfg.domain_id is None else cfg.domain_id
        rclpy.init(context=self.context, domain_id=self.domain_id)
        sim = [Parameter("use_sim_time", value=True)]

        def params(d: dict) -> list[Parameter]:
            return sim + [Parameter(k, value=v) for k, v in d.items()]

        kw = {"context": self.context}
        if quiet:
            for name in ("sim_plant", "strain_driver", "lowpass_filter", "hv_amplifier", "pid_controller",
                         "reference_generator", "hasel_collector"):
                rclpy.logging.set_logger_level(name, rclpy.logging.LoggingSeverity.WARN)
        self.nodes: list[Node] = []
        try:
            self.plant = PlantNode(cfg.actuator, **kw, parameter_overrides=params(
                {"autostart": False, "seed": cfg.seed, "variant": cfg.variant, **cfg.plant_params}))
            self.driver = StrainDriverNode(**kw, parameter_overrides=params(
                {"calibration_file": cfg.calibration_file}))
            self.filter = LowPassNode(**kw, parameter_overrides=params({}))
            self.amplifier = HvAmplifierNode(**kw, parameter_overrides=params(cfg.amplifier_params))
            self.nodes = [self.plant, self.driver, self.filter, self.amplifier]
            self.controller = None
            if cfg.with_controller:
                self.controller = PidControllerNode(**kw, parameter_overrides=params(
                    {"feedback": cfg.feedback, **cfg.controller_params}))
                self.nodes.append(self.controller)
            self.reference = None
            if cfg.with_reference:
                self.reference = ReferenceNode(**kw, parameter_overrides=params(
                    {"sequence_mm": [float(x) for x in cfg.sequence_mm], "hold_s": float(cfg.hold_s),
                     "start_s": 0.0, **({} if cfg.holds_s is None else {"holds_s": [float(x) for x in cfg.holds_s]})}))
                self.nodes.append(self.reference)
            self.collector = None
            if cfg.with_collector:
                self.collector = Collector(**kw, parameter_overrides=params({}))
                self.nodes.append(self.collector)
            self.nodes += [make(self.context) for make in extra_nodes]
            if cfg.shared_clock:
                self.time_source = share_sim_clock(self.nodes, self.plant)
            self.executor = make_executor(cfg.executor, self.context)
            for n in self.nodes:
                self.executor.add_node(n)
        except BaseException:
            self.close()
            raise

    def wait_ready(self, timeout_s: float = 10.0) -> None:
        """Spin until every link of the loop is matched (and the schedule is delivered)."""
        p, d, f, a, c = self.plant, self.driver, self.filter, self.amplifier, self.controller
        checks = [lambda: p.timing_pub.get_subscription_count() >= 1,
                  lambda: self.config.feedback != "laser" or p.laser_pub.get_subscription_count() >= 1,
                  lambda: d.pub.get_subscription_count() >= 1,
                  lambda: a.applied_pub.get_subscription_count() >= 1 + (self.collector in self.nodes)]
        if c is not None:
            # the filtered strain feeds the controller only with strain feedback
            checks += [lambda: f.pub.get_subscription_count() >= (self.config.feedback == "strain"),
                       lambda: c.cmd_pub.get_subscription_count() >= 1,
                       lambda: self.reference is None or len(c.references) == len(self.config.sequence_mm)]
        deadline = time.monotonic() + timeout_s
        while not all(ok() for ok in checks):
            interrupt.check()
            if time.monotonic() > deadline:
                raise HaselError("the node graph did not connect within "
                                 f"{timeout_s} s (DDS discovery); is ROS_DOMAIN_ID shared with a busy network?")
            self.executor.spin_once(timeout_sec=0.02)

    def run(self, duration_s: float, progress: Callable[[float], None] | None = None,
            wall_timeout_s: float | None = None) -> None:
        """Run the loop in lockstep until ``duration_s`` of simulated time."""
        self.plant.stop_at_s = float(duration_s)
        self.wait_ready()
        self.plant.start()
        limit = None if wall_timeout_s is None else time.monotonic() + wall_timeout_s
        # spin in long stretches (one call per simulated chunk): each return to Python costs
        chunk = max(ns_to_s(self.plant.period_ns), min(1.0, duration_s / 20))
        while not self.plant.done:
            target = min(duration_s, self.plant.now_s() + chunk)
            fut = Future()
            self.plant.notify_at(target, fut)
            # a bounded wait: a signal handler only sets a flag, checked here
            self.executor.spin_until_future_complete(fut, timeout_sec=0.25)
            interrupt.check()
            if progress is not None:
                progress(self.plant.now_s())
            if limit is not None and time.monotonic() > limit:
                raise HaselError(f"the graph stalled at t = {self.plant.now_s():.3f} s of {duration_s} s")
        # let the last messages land
        for _ in range(20):
            self.executor.spin_once(timeout_sec=0.001)

    def close(self) -> None:
        """Destroy the nodes and shut the context down (0 kV is commanded on the way; the
        recorder's file gets its summary and footer). Safe to call twice."""
        try:
            amp = getattr(self, "amplifier", None)
            if amp is not None:
                amp.on_shutdown()
            ex = getattr(self, "executor", None)
            if ex is not None:
                ex.shutdown()
            for n in getattr(self, "nodes", []):
                n.destroy_node()
            self.nodes = []
            rclpy.try_shutdown(context=self.context)
        finally:
            if self._deferred is not None:
                self._deferred.__exit__(None, None, None)
                self._deferred = None

    def __enter__(self) -> NodeGraph:
        return self

    def __exit__(self, *exc) -> None:
        self.close()
        if exc[0] is None:
            interrupt.check()  # a signal that came while closing still ends the command
