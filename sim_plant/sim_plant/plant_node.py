"""Simulated HASEL plant node: the paper's P(s) behind the amplifier, with its sensors.

Inside, :class:`hasel.simulator.PlantSimulator` integrates the actuator at 10 kHz by
exact zero-order hold (amplifier 5 kV/V and its 500 Hz output filter, then P(s)),
and models the laser (3 mm/V, 12-bit ADC) and the capacitive strain sensor read by an
LMC555 at 4.5 kHz with field-dependent noise. Per 200 Hz tick it publishes
``/sensor/timing`` (555 elapsed time), ``/laser/stroke`` and the period's 10 kHz
samples batched on ``/plant/batch``. It applies the amplifier node's output
(``/amp/applied``: held for one period; ``/amp/applied_batch``: 10 kHz waveform).

Clock modes (parameter ``clock_mode``):

- ``sim``: the plant owns time. It publishes ``/clock`` and steps in lockstep: after
  publishing tick k it waits for the amplifier output stamped t_k, then integrates one
  period. The whole graph is deterministic and runs as fast as the machine allows.
  If no output arrives within ``lockstep_timeout_s`` of wall time (counted by the
  plant's own watch, so that a stall of its process is not the amplifier's silence)
  the plant steps anyway, holding the last command as a DAC would, and after three missed periods
  it models the MCU's own watchdog by applying 0 kV. An output of the amplifier's
  watchdog answers a tick at the instant the clock moves, ahead of that tick's
  messages still on their way through the graph; the plant lets them land (a few
  ms of wall time) before stepping on it, so the graph never runs ahead of its own
  controller and stays deterministic.
- ``wall``: a steady timer steps the plant in real time with the latest command.

Plant variants are pluggable (parameter ``variant``): see :func:`make_actuator`; parameter
``model_file`` runs a plant-model file instead (:mod:`hasel.plantfile`: e.g. ``model.json``
from ``hasel identify`` or ``hasel diagnose --export-plant``). A malformed file stops the
node at start with one line and exit code 2, before it publishes anything.
"""
from __future__ import annotations

import time
from collections.abc import Sequence

import numpy as np
from rclpy.clock import Clock, ClockType
from rclpy.node import Node
from rosgraph_msgs.msg import Clock as ClockMsg

from hasel import paper
from hasel.errors import BadInputError
from hasel import plantspec
from hasel.amplifier import HeldOutput, Reason
from hasel.plant import Actuator
from hasel.sensors import LaserConfig, StrainConfig
from hasel.simulator import PlantBlock, PlantSimulator
from hasel.timeconv import ns_to_s, ns_to_stamp, s_to_ns
from hasel_ros.rosutil import declare, float64_array, run_node, stamp_ns, topic_qos
from hasel_msgs.msg import SampleBatch, SensorTiming, Stroke, VoltageCommand

__all__ = ["PlantNode", "main", "make_actuator"]

# the most wall time the tick's messages get to land after the amplifier's watchdog answered
# it, s (a quarter of lockstep_timeout_s below that): a hop costs tens of microseconds, this
# leaves room for a busy machine, and it is spent only while the watchdog holds 0 kV
_SETTLE_S = 0.05

def make_actuator(variant: str) -> Actuator:
    """The actuator model of a variant: ``nominal``, ``truth``, or ``truth:EFFECT(p=v)+...``
    (see :mod:`hasel.plantspec`); BadInputError explains a bad one."""
    return plantspec.make_actuator(variant)


class PlantNode(Node):
    """The plant. Parameters: clock_mode, variant, seed, noise levels, lockstep_timeout_s, stop_at_s."""

    def __init__(self, actuator: Actuator | None = None, **kwargs) -> None:
        super().__init__("sim_plant", **kwargs)
        self.clock_mode = declare(self, "clock_mode", "sim", "sim (publish /clock, lockstep) | wall", read_only=True)
        if self.clock_mode not in ("sim", "wall"):
            raise BadInputError(f"clock_mode must be 'sim' or 'wall', got {self.clock_mode!r}")
        variant = declare(self, "variant", "nominal",
                          "plant model: nominal | truth | truth:EFFECT(param=value)+... (unmodelled effects)",
                          read_only=True)
        model_file = declare(self, "model_file", "",
                             "plant-model file (hasel-plant JSON or identify's model.json); empty: use variant",
                             read_only=True)
        seed = declare(self, "seed", 0, "seed of the sensor noise", lo=0, hi=2**31 - 1, read_only=True)
        period = declare(self, "period_s", paper.LOOP_PERIOD_S, "loop period, s", lo=1e-4, hi=1.0, read_only=True)
        laser_noise = declare(self, "laser_noise_mm", LaserConfig().noise_mm, "laser noise (std), mm",
                              lo=0.0, hi=1.0, read_only=True)
        strain_noise = declare(self, "strain_noise_us", StrainConfig().noise_us, "555 noise at 0 kV (std), us",
                               lo=0.0, hi=100.0, read_only=True)
        strain_noise_kv = declare(self, "strain_noise_us_per_kv", StrainConfig().noise_us_per_kv,
                                  "extra 555 noise per applied kV, us/kV", lo=0.0, hi=100.0, read_only=True)
        self.lockstep_timeout_s = declare(self, "lockstep_timeout_s", 0.25,
                                          "wall time to wait for the amplifier before stepping anyway, s",
                                          lo=0.001, hi=60.0)
        self.stop_at_s = declare(self, "stop_at_s", -1.0, "simulated time to stop at, s (negative: never)",
                                 lo=-1.0, hi=1e9)
        autostart = declare(self, "autostart", True, "start stepping by itself (sim mode)")
        self.publish_batch = declare(self, "publish_batch", True, "publish the 10 kHz samples")
        if model_file and variant != "nominal" and actuator is None:
            raise BadInputError(f"give either model_file ({model_file}) or variant ({variant}), not both")
        act = actuator or (plantspec.from_file(model_file) if model_file else make_actuator(variant))
        self.sim = PlantSimulator(act, period_s=period, seed=seed, laser=LaserConfig(noise_mm=laser_noise),
                                  strain=StrainConfig(noise_us=strain_noise, noise_us_per_kv=strain_noise_kv),
                                  strain_curve=getattr(act, "strain_curve", None))
        self.get_logger().info(f"plant: {plantspec.describe(act)}")
        self.period_ns = s_to_ns(period)
        self.trigger_period_us = 1e6 / self.sim.strain.config.trigger_hz
        self.held = HeldOutput(3)  # the DAC holds; the MCU's own watchdog zeroes after 3 missed periods
        self._watchdog_answer: float | None = None  # an amplifier-watchdog output waiting for the tick to settle
        self.running = False
        self.done = False
        self.sequence = 0
        self._progress()
        self._waiters: list[tuple[float, object]] = []

        self.clock_pub = self.create_publisher(ClockMsg, "/clock", topic_qos("/clock")) \
            if self.clock_mode == "sim" else None
        self.timing_pub = self.create_publisher(SensorTiming, "sensor/timing", topic_qos("/sensor/timing"))
        self.laser_pub = self.create_publisher(Stroke, "laser/stroke", topic_qos("/laser/stroke"))
        self.batch_pub = self.create_publisher(SampleBatch, "plant/batch", topic_qos("/plant/batch"))
        self._clock_msg = ClockMsg()
        self._timing_msg = SensorTiming(period_us=self.trigger_period_us)
        self._laser_msg = Stroke(source=Stroke.SOURCE_LASER)
        self._batch_msg = SampleBatch()
        self.create_subscription(VoltageCommand, "amp/applied", self.on_applied, topic_qos("/amp/applied"))
        self.create_subscription(SampleBatch, "amp/applied_batch", self.on_applied_batch,
                                 topic_qos("/amp/applied_batch"))
        steady = Clock(clock_type=ClockType.STEADY_TIME)
        if self.clock_mode == "wall":
            self.create_timer(period, self.on_wall_tick, clock=steady)
        else:
            self._watch_s = min(self.lockstep_timeout_s / 2, 0.05)
            self.create_timer(self._watch_s, self.on_lockstep_watch, clock=steady)
            self._settle = self.create_timer(min(self.lockstep_timeout_s / 4, _SETTLE_S), self._on_settled,
                                             clock=steady)
            self._settle.cancel()
            if autostart:
                self._autostart = self.create_timer(1.0, self._start_once, clock=steady)

    # -- time ---------------------------------------------------------------------------
    def tick_stamp_ns(self) -> int:
        """Stamp of the current tick, ns (exact integer arithmetic: no drift)."""
        return self.sim.tick * self.period_ns

    def now_s(self) -> float:
        """Simulated time of the current tick, s."""
        return ns_to_s(self.tick_stamp_ns())

    def _stamp(self, msg, ns: int) -> None:
        msg.header.stamp.sec, msg.header.stamp.nanosec = ns_to_stamp(ns)

    def notify_at(self, t_s: float, future) -> None:
        """Complete ``future`` once simulated time reaches ``t_s`` (or the run is done)."""
        if self.done or self.now_s() >= t_s - 1e-12:
            future.set_result(self.now_s())
        else:
            self._waiters.append((t_s, future))

    def _notify(self) -> None:
        now = self.now_s()
        keep = []
        for t, fut in self._waiters:
            if self.done or now >= t - 1e-12:
                fut.set_result(now)
            else:
                keep.append((t, fut))
        self._waiters = keep

    # -- lockstep -----------------------------------------------------------------------
    def _start_once(self) -> None:
        self._autostart.cancel()
        self.start()

    def start(self) -> None:
        """Begin stepping (sim mode): publish time and the readings of tick 0."""
        if self.running:
            return
        self.running = True
        self._progress()
        self._publish_tick()

    def on_applied(self, msg: VoltageCommand) -> None:
        """The amplifier's output for one tick (held for one period)."""
        self._on_command(msg.header.stamp, msg.applied_kv, msg.reason == Reason.WATCHDOG)

    def on_applied_batch(self, msg: SampleBatch) -> None:
        """The amplifier's output as a 10 kHz waveform for one period."""
        cmd = np.asarray(msg.voltage_kv, dtype=float)
        if cmd.size != self.sim.samples_per_period:
            self.get_logger().error(f"applied batch has {cmd.size} samples, need {self.sim.samples_per_period}")
            return
        self._on_command(msg.header.stamp, cmd)

    def _on_command(self, stamp, command, watchdog: bool = False) -> None:
        if self.clock_mode == "wall":
            self.held.fresh(command)
            return
        ns = stamp_ns(stamp)
        if not self.running or self.done or ns != self.tick_stamp_ns() or self._watchdog_answer is not None:
            return  # not for this tick (late, duplicate, early, or after its first answer): ignore
        if watchdog:  # the tick's first answer, but its messages may still be in flight: step once they land
            self._watchdog_answer = command
            self._settle.reset()
            return
        self._advance(self.held.fresh(command))

    def _on_settled(self) -> None:
        """Step on the amplifier watchdog's answer once the tick's messages have landed."""
        self._settle.cancel()
        command, self._watchdog_answer = self._watchdog_answer, None
        if command is not None and self.running and not self.done:
            self._advance(self.held.fresh(command))

    def _progress(self) -> None:
        """The graph moved (a step or the start): the quiet is counted again from now."""
        self._last_watch = time.monotonic()
        self._quiet_s = 0.0

    def on_lockstep_watch(self) -> None:
        """Wall-time guard of lockstep: step anyway if the amplifier has gone quiet.

        The quiet (s of wall time) is counted by this watch's own calls, each gap at
        most one watch period: when this process is stalled (descheduled on a loaded
        machine, or a garbage collection) the amplifier's answer waits in the queue
        behind this call, and the stall is not its silence. Without the cap a 0.2 s
        stall made the plant step on a held command once in a loaded `make test`.
        """
        now = time.monotonic()
        gap, self._last_watch = now - self._last_watch, now
        self._quiet_s += min(gap, self._watch_s)
        if not self.running or self.done or self._watchdog_answer is not None:
            return
        if self._quiet_s < self.lockstep_timeout_s:
            return
        self._advance(self.held.missing())

    def _advance(self, command_kv: float | np.ndarray) -> None:
        block = self.sim.step(command_kv)
        self._progress()
        if self.publish_batch and self.batch_pub.get_subscription_count():  # nobody listening: skip the work
            self._publish_batch(block)
        if self.stop_at_s >= 0 and self.now_s() >= self.stop_at_s - 1e-12:
            self.done = True
        self._publish_tick()
        if self._waiters:
            self._notify()

    # -- wall mode ----------------------------------------------------------------------
    def on_wall_tick(self) -> None:
        """Real-time mode: step with the latest command, stamp with the node's clock."""
        block = self.sim.step(self.held.value)
        if self.publish_batch and self.batch_pub.get_subscription_count():
            self._publish_batch(block, self.get_clock().now().nanoseconds - self.period_ns)
        self._publish_tick(self.get_clock().now().nanoseconds)

    # -- publishing ---------------------------------------------------------------------

    def _publish_batch(self, block: PlantBlock, t0_ns: int | None = None) -> None:
        msg = self._batch_msg  # refilled each tick: publish() copies it at once
        msg.sample_period_s = block.dt_s
        start_ns = (self.tick_stamp_ns() - self.period_ns) if t0_ns is None else t0_ns
        self._stamp(msg, start_ns + s_to_ns(block.dt_s))  # first sample: end of the first 0.1 ms
        msg.voltage_kv = float64_array(block.applied_kv)
        msg.stroke_mm = float64_array(block.laser_mm)
        msg.true_stroke_mm = float64_array(block.true_stroke_mm)
        msg.elapsed_us = float64_array(block.elapsed_us)
        self.batch_pub.publish(msg)

    def _publish_tick(self, ns: int | None = None) -> None:
        ns = self.tick_stamp_ns() if ns is None else ns
        rd = self.sim.latest()
        # one message object per topic, refilled each tick: publish() copies it at once
        if self.clock_pub is not None:
            c = self._clock_msg
            c.clock.sec, c.clock.nanosec = ns_to_stamp(ns)
            self.clock_pub.publish(c)
        self.sequence += 1
        timing = self._timing_msg
        timing.elapsed_us, timing.sequence = rd.elapsed_us, self.sequence
        self._stamp(timing, ns)
        laser = self._laser_msg
        laser.stroke_mm = rd.laser_mm
        self._stamp(laser, ns)
        self.timing_pub.publish(timing)
        if self.laser_pub.get_subscription_count():  # a publish costs about 9 us even when nobody listens
            self.laser_pub.publish(laser)


def main(args: Sequence[str] | None = None) -> int:
    """Entry point of ``ros2 run sim_plant plant``."""
    return run_node(PlantNode, args)
