"""``hasel chirp``: the paper's identification experiment on the plant, recorded to MCAP.

Table I: offsets v_s in {2, ..., 7} kV, A = 1 kV, f_0 = 0.001 Hz, f_f = 20 Hz,
t_tot = 20 s, three chirps back to back, 10 kHz, and -1 kV held before each test to
reverse accumulated charge. The excitation goes out as 10 kHz waveforms, one
``/amp/command_batch`` per 5 ms tick, through the amplifier node's limits (so even an
experiment cannot exceed 9 kV); the charge reversal goes through the amplifier's
separate, deliberate ``/amp/precondition`` path. Each part is marked on ``/markers``
(hasel_msgs/ExperimentMarker: which excitation, offset, amplitude, band), so the log
says which chirp formula it used and ``hasel identify`` finds the operating points.

``--chirp paper`` is the paper's formula (4)-(5), whose instantaneous frequency ends
near 2 f_f; ``--chirp linear`` a textbook linear chirp f_0 -> f_f; ``--chirp multisine``
an odd random-phase multisine (Pintelon and Schoukens) that separates noise from
nonlinear distortion.
"""
from __future__ import annotations

import argparse
import math
import time
from collections.abc import Sequence
from pathlib import Path

import numpy as np
from rclpy.node import Node
from rclpy.parameter import Parameter
from rosgraph_msgs.msg import Clock as ClockMsg

from hasel import paper
from hasel.errors import BadInputError
from hasel.signals import Schedule, protocol_schedule
from hasel.timeconv import s_to_ns
from hasel.validate import finite, seed
from hasel_ros.rosutil import stamp_ns, to_stamp, topic_qos
from hasel_msgs.msg import ExperimentMarker, SampleBatch, VoltageCommand

__all__ = ["ExperimentNode", "run", "run_chirp"]


class ExperimentNode(Node):
    """Plays a :class:`hasel.signals.Schedule` into the amplifier, tick by tick, on /clock."""

    def __init__(self, schedule: Schedule, period_s: float = paper.LOOP_PERIOD_S, **kwargs) -> None:
        super().__init__("hasel_experiment", **kwargs)
        self.schedule = schedule
        self.n_per_tick = int(round(period_s * schedule.rate_hz))
        self.period_ns = s_to_ns(period_s)
        self.n_ticks = int(math.ceil(schedule.command_kv.size / self.n_per_tick))
        self.pre = np.zeros(self.n_ticks, dtype=bool)  # ticks that are charge reversal
        for r in schedule.records:
            if r.kind == "precondition":
                a, b = (int(round(x / period_s)) for x in (r.start_s, r.end_s))
                self.pre[a:b] = True
        self.batch_pub = self.create_publisher(SampleBatch, "amp/command_batch", topic_qos("/amp/command_batch"))
        self.pre_pub = self.create_publisher(VoltageCommand, "amp/precondition", topic_qos("/amp/precondition"))
        self.marker_pub = self.create_publisher(ExperimentMarker, "markers", topic_qos("/markers"))
        self.create_subscription(ClockMsg, "/clock", self.on_clock, topic_qos("/clock"))
        self.last_tick = -1

    def publish_markers(self, excitation: str, amplitude_kv: float, f0: float, f1: float, duration: float) -> None:
        """Start and end markers of every part of the schedule (latched)."""
        for r in self.schedule.records:
            for start, t in ((True, r.start_s), (False, r.end_s)):
                m = ExperimentMarker(label=r.kind, signal=r.excitation or ("constant" if r.kind != "excitation"
                                                                          else excitation),
                                     offset_kv=r.offset, amplitude_kv=amplitude_kv if r.kind == "excitation" else 0.0,
                                     f0_hz=f0, f1_hz=f1, duration_s=duration, start=start)
                m.header.stamp = to_stamp(t)
                self.marker_pub.publish(m)

    def on_clock(self, msg: ClockMsg) -> None:
        """Publish the command of the tick that starts at this time."""
        ns = stamp_ns(msg.clock)
        k = int(round(ns / self.period_ns))
        if k == self.last_tick or k >= self.n_ticks:
            return
        self.last_tick = k
        seg = self.schedule.command_kv[k * self.n_per_tick:(k + 1) * self.n_per_tick]
        if seg.size < self.n_per_tick:
            seg = np.concatenate([seg, np.full(self.n_per_tick - seg.size, seg[-1] if seg.size else 0.0)])
        if self.pre[k]:
            cmd = VoltageCommand(requested_kv=float(seg.min()))
            cmd.header.stamp = msg.clock
            self.pre_pub.publish(cmd)
        else:
            b = SampleBatch(sample_period_s=1.0 / self.schedule.rate_hz, voltage_kv=seg)
            b.header.stamp = msg.clock
            self.batch_pub.publish(b)


def run_chirp(schedule: Schedule, out: str, *, seed: int = 0, plant: str = "nominal", actuator=None,
              quiet: bool = False, excitation: str = "paper", amplitude_kv: float = 1.0, f0: float = 0.001,
              f1: float = 20.0, duration: float = 20.0) -> dict:
    """Run ``schedule`` open loop through the graph, recording every topic to ``out``."""
    from hasel_sysid.graph import GraphConfig, NodeGraph
    from hasel_sysid.progress import Progress
    from hasel_sysid.recording import recorder_factory

    total = schedule.command_kv.size / schedule.rate_hz
    holder: list[ExperimentNode] = []

    def make_experiment(context):
        node = ExperimentNode(schedule, context=context, parameter_overrides=[Parameter("use_sim_time", value=True)])
        holder.append(node)
        return node

    cfg = GraphConfig(seed=seed, variant=plant, actuator=actuator, with_controller=False, with_reference=False,
                      with_collector=False)  # everything goes to the recording
    Path(out).parent.mkdir(parents=True, exist_ok=True)
    with NodeGraph(cfg, extra_nodes=[make_experiment, recorder_factory(out)]) as g:
        holder[0].publish_markers(excitation, amplitude_kv, f0, f1, duration)
        prog = None if quiet else Progress(total, f"chirp ({excitation})")
        t0 = time.monotonic()
        g.run(total, progress=prog)
        wall = prog.done() if prog is not None else time.monotonic() - t0
    return {"file": out, "simulated_s": total, "wall_s": wall, "segments": len(schedule.markers())}


def _floats(name: str, text: str) -> list[float]:
    try:
        vals = [float(x) for x in str(text).split(",") if x.strip()]
    except ValueError as err:
        raise BadInputError(f"{name} must be comma-separated numbers, got {text!r}") from err
    if not vals or not all(math.isfinite(v) for v in vals):
        raise BadInputError(f"{name} must hold finite numbers, got {text!r}")
    return vals


def check_excitation(offsets_kv: list[float], amplitude_kv: float, f0_hz: float, f1_hz: float, kind: str,
                     repeats: int, rate_hz: float = paper.PLANT_RATE_HZ) -> None:
    """Refuse an excitation the amplifier or the sampling cannot carry, naming the limit.

    Every offset +- amplitude (kV) must stay within the amplifier's 0 .. 9 kV (outside,
    the command is clipped and the log identifies the clipping, not the plant); the
    highest frequency the excitation reaches (``kind="paper"``: about 2 f1, see
    :func:`hasel.signals.paper_chirp`) must be below the Nyquist frequency rate_hz / 2.
    """
    a = finite("--amplitude", amplitude_kv)
    if a <= 0:
        raise BadInputError(f"--amplitude must be > 0 kV, got {a:g}")
    top = paper.V_MAX_KV
    for v in offsets_kv:
        if v - a < 0 or v + a > top:
            raise BadInputError(f"--offsets: {v:g} kV with amplitude {a:g} kV spans {v - a:g} .. {v + a:g} kV, "
                                f"outside the amplifier's 0 .. {top:g} kV; offsets must be in "
                                f"[{a:g}, {top - a:g}] kV")
    f0, f1 = finite("--f0", f0_hz), finite("--f1", f1_hz)
    if f0 < 0 or f1 <= f0:
        raise BadInputError(f"the band needs 0 <= --f0 < --f1, got {f0:g} and {f1:g} Hz")
    highest = 2.0 * (f1 - f0) if kind == "paper" else f1
    nyquist = rate_hz / 2.0
    if highest >= nyquist:
        extra = f" (the paper's formula ends near 2 f1 = {highest:g} Hz)" if kind == "paper" else ""
        raise BadInputError(f"--f1 {f1:g} Hz: the excitation reaches {highest:g} Hz{extra}, above the "
                            f"{nyquist:g} Hz Nyquist frequency of the {rate_hz:g} Hz sampling")
    if repeats < 1:
        raise BadInputError(f"--repeats must be >= 1, got {repeats}")


def run(args: argparse.Namespace) -> int:
    """CLI: ``hasel chirp``."""
    offsets = _floats("--offsets", args.offsets)
    for name in ("duration", "precondition_s", "settle_s"):
        v = getattr(args, name)
        if not math.isfinite(v) or v < 0 or abs(v / paper.LOOP_PERIOD_S - round(v / paper.LOOP_PERIOD_S)) > 1e-6:
            raise BadInputError(f"--{name.replace('_', '-')} must be >= 0 and a multiple of 5 ms, got {v}")
    if args.duration <= 0:
        raise BadInputError("--duration must be > 0 s")
    check_excitation(offsets, args.amplitude, args.f0, args.f1, args.chirp, args.repeats)
    from sim_plant.plant_node import make_actuator

    make_actuator(args.plant)
    schedule = protocol_schedule(offsets, args.amplitude, args.f0, args.f1, args.duration, args.repeats,
                                 paper.PLANT_RATE_HZ, kind=args.chirp, precondition_s=args.precondition_s,
                                 settle_s=args.settle_s, rng=np.random.default_rng(args.seed))
    if float(np.max(schedule.command_kv)) > 9.0:
        raise BadInputError("offsets + amplitude exceed the 9 kV ceiling")
    res = run_chirp(schedule, args.out, seed=args.seed, plant=args.plant, excitation=args.chirp,
                    amplitude_kv=args.amplitude, f0=args.f0, f1=args.f1, duration=args.duration)
    print(f"recorded {res['segments']} operating points ({res['simulated_s']:.1f} s simulated, "
          f"{args.chirp} excitation) to {args.out}")
    print(f"next: hasel identify {args.out} --json model.json --plot bode.png --report report/")
    return 0


def add_arguments(p: argparse.ArgumentParser, defaults: Sequence | None = None) -> None:
    """Options of ``hasel chirp`` (defaults: the paper's Table I)."""
    pr = paper.CHIRP_PROTOCOL
    p.add_argument("--out", default="chirp.mcap", help="MCAP file to record (default chirp.mcap)")
    p.add_argument("--chirp", choices=["paper", "linear", "multisine"], default="paper",
                   help="excitation: the paper's formula (ends near 2 f_f), a linear chirp, or an odd multisine")
    p.add_argument("--offsets", default=",".join(f"{v:g}" for v in pr["offsets_kv"]), help="DC offsets v_s, kV")
    p.add_argument("--amplitude", type=float, default=pr["amplitude_kv"], help="excitation amplitude A, kV")
    p.add_argument("--f0", type=float, default=pr["f0_hz"], help="start frequency f_0, Hz")
    p.add_argument("--f1", type=float, default=pr["f1_hz"], help="final frequency f_f, Hz")
    p.add_argument("--duration", type=float, default=pr["duration_s"], help="one excitation t_tot, s")
    p.add_argument("--repeats", type=int, default=pr["repeats"], help="excitations back to back per offset")
    p.add_argument("--precondition-s", dest="precondition_s", type=float, default=2.0,
                   help="charge reversal (-1 kV) before each test, s")
    p.add_argument("--settle-s", dest="settle_s", type=float, default=0.0, help="hold at the offset first, s")
    p.add_argument("--plant", default="nominal", help="plant variant (default nominal)")
    p.add_argument("--seed", type=seed, default=0, help="noise (and multisine phase) seed, 0 .. 2^31-1")
