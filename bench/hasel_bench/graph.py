"""Measurements of the node graph for ``hasel bench``: simulated-time speed and the recorder's cost.

- :func:`graph_speed`: the closed loop (plant, driver, filter, controller, amplifier,
  reference) with the MCAP recorder, in one process, lockstep in simulated time
  (:class:`~hasel_sysid.graph.NodeGraph`); simulated seconds per wall second. The
  graph's in-memory collector (what steps and calibrate read their signals from) is
  detached, so the graph measured is the one a recorded experiment needs. The
  recording is then read back to check that simulated time worked: one amplifier
  output per 5 ms tick, on the exact 5 ms grid, and every 10 kHz sample present.
- :func:`recorder_vs_bare`: CPU time of the recorder node's message path (its raw
  subscription callback: receive time from the node's clock, then
  :class:`~hasel.io.writer.Ros2McapWriter`) against a bare ``mcap.writer.Writer``
  writing the same serialised bytes with the same chunk size, both uncompressed.
- :func:`ring_floor`: the least a tick can cost on this machine with this stack: an
  empty ring of ``n`` nodes passing one message around (each callback only
  re-publishes what it got), with the same executor, plus the plant's own 10 kHz
  simulation of one period (:class:`hasel.simulator.PlantSimulator`, no ROS). Any
  graph in which every node of the loop handles every tick costs at least that, so
  ``period / floor`` is a ceiling on its simulated-time speed and
  ``cores * period / cpu_floor`` a ceiling on the loops that fit on the machine. A
  second ring with one more (do-nothing) subscriber per hop splits a hop into the
  cost of a publish and of a delivery, so :func:`pattern_ceiling` prices the graph's
  own message pattern (its publishes and deliveries per tick) with empty callbacks.
"""
from __future__ import annotations

import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

import numpy as np

from hasel import paper

__all__ = ["graph_speed", "graph_speed_split", "recorder_vs_bare", "bench_messages", "ring_floor",
           "pattern_ceiling"]

_BATCH = "hasel_msgs/msg/SampleBatch"
_LOOP_TOPICS = ("/clock", "/sensor/timing", "/laser/stroke", "/strain/stroke", "/strain/stroke_filtered",
                "/plant/batch", "/amp/command", "/amp/applied", "/controller/state")
_STROKE = "hasel_msgs/msg/Stroke"


def graph_speed(executor: str, duration_s: float, domain_id: int, directory: str | os.PathLike[str],
                seed: int = 0) -> dict[str, Any]:
    """Run the recorded graph for ``duration_s`` simulated seconds with ``executor``.

    Parameters
    ----------
    executor : {"events", "single"}
        rclpy's EventsExecutor or SingleThreadedExecutor.
    duration_s : float
        Simulated time, s.
    domain_id : int
        ROS domain of the graph.
    directory : path-like
        Where the recording goes (deleted by the caller).

    Returns
    -------
    dict
        ``sim_s``, ``wall_s``, ``speed`` (simulated s per wall s), ``cpu_cores`` (process
        CPU time per wall second, DDS threads included), ``recorded`` (messages per
        topic), ``subscribers`` (per topic), ``callbacks_per_tick`` (deliveries plus
        timers on the simulated clock), ``us_per_callback`` (wall time per tick divided
        by them), ``publishes_per_tick`` and ``deliveries_per_tick`` (of messages on
        the loop's topics), ``timers_per_tick``, ``sim_time_ok`` and ``sim_time_detail``.
    """
    from hasel.io import info, load_signals
    from hasel_sysid.graph import GraphConfig, NodeGraph
    from hasel_sysid.recording import recorder_factory

    path = Path(directory) / f"graph_{executor}.mcap"
    seq = [2.0, 4.0, 6.0, 4.0, 2.0]
    cfg = GraphConfig(sequence_mm=seq, hold_s=duration_s / len(seq), seed=seed, executor=executor,
                      domain_id=domain_id)
    with NodeGraph(cfg, extra_nodes=[recorder_factory(str(path))]) as g:
        g.executor.remove_node(g.collector)
        g.collector.destroy_node()
        g.nodes.remove(g.collector)
        g.wait_ready()
        w0, c0 = time.perf_counter(), time.process_time()
        g.run(duration_s, wall_timeout_s=600.0)
        wall, cpu = time.perf_counter() - w0, time.process_time() - c0
        ticks = g.plant.sim.tick
        subscribers = {t: g.plant.count_subscribers(t) for t in _LOOP_TOPICS}
        # timers on the simulated clock that fire every tick (a Deadline pushed back by
        # each message, period longer than a tick, never fires while the loop is healthy)
        timers = sum(1 for n in g.nodes for t in n.timers if t.clock.clock_type == t.clock.clock_type.ROS_TIME
                     and not t.is_canceled() and t.timer_period_ns <= g.plant.period_ns)
    rep = info(path)
    recorded = {t.topic: int(t.count) for t in rep.topics if t.count}
    sig = load_signals(path, ["/amp/applied.applied_kv", "/plant/batch.voltage_kv"])
    t_app = sig["/amp/applied.applied_kv"].t_s
    n_samples = sig["/plant/batch.voltage_kv"].values.size
    steps = np.diff(t_app)
    period = paper.LOOP_PERIOD_S
    on_grid = bool(t_app.size and np.all(np.abs(t_app / period - np.round(t_app / period)) < 1e-6))
    regular = bool(steps.size and np.all(np.abs(steps - period) < 1e-9))
    want_samples = int(round(ticks * period * paper.PLANT_RATE_HZ))
    ok = on_grid and regular and t_app.size >= ticks and n_samples == want_samples
    detail = (f"{t_app.size} outputs for {ticks} ticks, on the 5 ms grid: {on_grid}, regular: {regular}; "
              f"{n_samples} of {want_samples} 10 kHz samples")
    # executor callbacks per tick: every delivery of every message, plus the timers on the simulated clock
    deliveries = sum(recorded.get(t, 0) * n for t, n in subscribers.items()) / max(ticks, 1)
    publishes = sum(recorded.get(t, 0) for t, n in subscribers.items() if n) / max(ticks, 1)
    per_tick = deliveries + timers
    return {"executor": executor, "sim_s": float(duration_s), "wall_s": wall, "speed": duration_s / wall,
            "cpu_cores": cpu / wall, "ticks": int(ticks), "recorded": recorded, "subscribers": subscribers,
            "callbacks_per_tick": per_tick, "us_per_callback": 1e6 * wall / max(ticks, 1) / per_tick,
            "publishes_per_tick": publishes, "deliveries_per_tick": deliveries, "timers_per_tick": timers,
            "sim_time_ok": ok, "sim_time_detail": detail}


def bench_messages(n: int, rng: np.random.Generator) -> list[tuple[str, bytes, int]]:
    """``n`` serialised messages, half 50-sample SampleBatch, half Stroke: (topic, bytes, time ns)."""
    from hasel_bench.iospeed import encode, encode_sample_batch

    out = []
    for i in range(n):
        t = 10**9 + i * 2_500_000
        if i % 2 == 0:
            out.append(("/plant/batch", encode_sample_batch(t, 1e-4, rng.normal(size=50), rng.normal(size=50),
                                                            rng.normal(size=50), rng.normal(size=50)), t))
        else:
            out.append(("/laser/stroke", encode(_STROKE, {"header": {"stamp": {"sec": t // 10**9,
                                                                               "nanosec": t % 10**9}},
                                                          "stroke_mm": float(rng.normal()), "source": 2}), t))
    return out


def recorder_vs_bare(n_messages: int = 20000, repeats: int = 3, domain_id: int = 0) -> dict[str, Any]:
    """CPU time per message: the recorder node's path against a bare mcap writer (best of ``repeats``).

    Returns
    -------
    dict
        ``messages``, ``recorder_us``, ``bare_us`` (per message), ``ratio``,
        ``recorder_bytes``, ``bare_bytes`` (file sizes).
    """
    import rclpy
    from mcap.writer import CompressionType, Writer
    from rclpy.context import Context
    from rclpy.parameter import Parameter

    from hasel.io.msgdefs import message_definition
    from hasel.io.writer import DEFAULT_CHUNK_SIZE
    from hasel_sysid.recorder_node import RecorderNode

    msgs = bench_messages(n_messages, np.random.default_rng(3))
    defs = {t: message_definition(t).encode() for t in (_BATCH, _STROKE)}
    ctx = Context()
    rclpy.init(args=["--ros-args", "--log-level", "warn"], context=ctx, domain_id=domain_id)
    best_rec = best_bare = float("inf")
    sizes = [0, 0]
    try:
        with tempfile.TemporaryDirectory() as tmp:
            for r in range(repeats):
                path = Path(tmp) / f"rec{r}.mcap"
                node = RecorderNode(str(path), ["/plant/batch", "/laser/stroke"], context=ctx,
                                    parameter_overrides=[Parameter("use_sim_time", value=False),
                                                         Parameter("compression", value="none"),
                                                         Parameter("chunk_size", value=DEFAULT_CHUNK_SIZE)])
                cbs = {s.topic_name: s.callback for s in node.subscriptions if s.topic_name in
                       ("/plant/batch", "/laser/stroke")}
                calls = [(cbs[t], d) for t, d, _ in msgs]
                c0 = time.process_time()
                for cb, d in calls:
                    cb(d)
                node.destroy_node()  # closes the file: summary and footer
                best_rec = min(best_rec, time.process_time() - c0)
                sizes[0] = path.stat().st_size

                bpath = Path(tmp) / f"bare{r}.mcap"
                c0 = time.process_time()
                with open(bpath, "wb") as fh:
                    w = Writer(fh, chunk_size=DEFAULT_CHUNK_SIZE, compression=CompressionType.NONE)
                    w.start("ros2", "bare")
                    ids = {}
                    for topic, tname in (("/plant/batch", _BATCH), ("/laser/stroke", _STROKE)):
                        sid = w.register_schema(tname, "ros2msg", defs[tname])
                        ids[topic] = w.register_channel(topic, "cdr", sid)
                    for topic, d, t in msgs:
                        now = time.time_ns()  # the recorder stamps arrival with its clock, so does this
                        w.add_message(ids[topic], now, d, t)
                    w.finish()
                best_bare = min(best_bare, time.process_time() - c0)
                sizes[1] = bpath.stat().st_size
    finally:
        rclpy.try_shutdown(context=ctx)
    n = len(msgs)
    return {"messages": n, "recorder_us": 1e6 * best_rec / n, "bare_us": 1e6 * best_bare / n,
            "ratio": best_rec / best_bare, "recorder_bytes": sizes[0], "bare_bytes": sizes[1]}


def ring_floor(n_nodes: int = 5, rounds: int = 5000, domain_id: int = 0, executor: str = "events",
               sim_ticks: int = 2000) -> dict[str, Any]:
    """The cheapest possible tick: an empty ring of ``n_nodes`` nodes, plus one plant step.

    Parameters
    ----------
    n_nodes : int
        Nodes in the ring (the loop's plant, driver, filter, controller, amplifier: 5).
    rounds : int
        Messages sent around the ring (after 200 rounds of warm-up).
    domain_id : int
        ROS domain of the ring.
    executor : {"events", "single"}
        Executor of the ring (one, in one process).
    sim_ticks : int
        Periods the plant simulator is stepped for its own cost.

    Returns
    -------
    dict
        ``round_us`` and ``round_cpu_us`` (wall and process CPU time per round, DDS threads
        included), ``hop_us``, ``delivery_us`` (one more subscriber on every hop, from a
        second ring with a do-nothing sink on each topic; each ring run twice, alternated,
        the fastest kept; 0 when the machine's noise hides it) and ``publish_us`` (the rest of
        a hop), ``sim_step_us`` (one 5 ms period of the 10 kHz plant and its sensors),
        ``tick_floor_us`` (a round, one more hop for ``/clock``, and a plant step),
        ``speed_ceiling`` (simulated s per wall s) and ``cpu_per_loop_floor_us``.
    """
    import rclpy
    from rclpy.context import Context
    from rclpy.node import Node
    from rclpy.qos import QoSProfile
    from rclpy.task import Future

    from hasel.simulator import PlantSimulator
    from hasel_msgs.msg import Stroke
    from hasel_sysid.graph import make_executor

    if n_nodes < 1 or rounds < 1:
        raise ValueError("the ring needs at least one node and one round")

    class _Sink(Node):
        """A second subscriber on every ring topic, doing nothing: the cost of one more delivery."""

        def __init__(self, ctx: Context) -> None:
            super().__init__("ring_sink", context=ctx)
            self.count = 0
            for i in range(n_nodes):
                self.create_subscription(Stroke, f"ring{i}", self.on_message, QoSProfile(depth=10))

        def on_message(self, msg: Stroke) -> None:
            self.count += 1

    class _Hop(Node):
        def __init__(self, i: int, ctx: Context) -> None:
            super().__init__(f"ring_hop{i}", context=ctx)
            self.pub = self.create_publisher(Stroke, f"ring{(i + 1) % n_nodes}", QoSProfile(depth=10))
            self.create_subscription(Stroke, f"ring{i}", self.on_message, QoSProfile(depth=10))
            self.count, self.stop_after, self.done = 0, 0, None

        def on_message(self, msg: Stroke) -> None:
            self.count += 1
            if self.done is not None and self.count >= self.stop_after:
                self.done.set_result(self.count)
                return
            self.pub.publish(msg)

    def run_ring(sink: bool) -> tuple[float, float]:
        """Wall and CPU time (s) of ``rounds`` rounds, with or without a second subscriber per hop."""
        ctx = Context()
        rclpy.init(args=["--ros-args", "--log-level", "warn"], context=ctx, domain_id=domain_id)
        nodes: list[Node] = []
        try:
            nodes = [_Hop(i, ctx) for i in range(n_nodes)]
            hops = list(nodes)
            if sink:
                nodes.append(_Sink(ctx))
            ex = make_executor(executor, ctx)
            for n in nodes:
                ex.add_node(n)
            deadline = time.monotonic() + 10.0
            while not all(n.pub.get_subscription_count() >= 1 + sink for n in hops):
                if time.monotonic() > deadline:
                    raise RuntimeError("the ring did not connect within 10 s")
                ex.spin_once(timeout_sec=0.01)
            head = hops[0]
            for count in (200, rounds):  # warm-up, then the measured stretch
                head.done, head.count, head.stop_after = Future(), 0, count
                w0, c0 = time.perf_counter(), time.process_time()
                head.pub.publish(Stroke())
                ex.spin_until_future_complete(head.done, timeout_sec=120.0)
                wall, cpu = time.perf_counter() - w0, time.process_time() - c0
                if not head.done.done():
                    raise RuntimeError("the ring lost its message")
            ex.shutdown()
        finally:
            for n in nodes:
                n.destroy_node()
            rclpy.try_shutdown(context=ctx)
        return wall, cpu

    # alternated and the fastest of each kept: the difference of two wall times is what is
    # measured, and another process's burst during one run would otherwise decide it
    runs = [(run_ring(False), run_ring(True)) for _ in range(2)]
    wall, cpu = min((r[0] for r in runs), key=lambda wc: wc[0])
    wall2 = min(r[1][0] for r in runs)
    sim = PlantSimulator(seed=0)
    sim.step(1.0)
    w0 = time.perf_counter()
    for k in range(sim_ticks):
        sim.step(3.0 + 0.001 * (k % 100))
    step_us = 1e6 * (time.perf_counter() - w0) / sim_ticks
    round_us, round_cpu_us = 1e6 * wall / rounds, 1e6 * cpu / rounds
    hop_us = round_us / n_nodes
    # a hop is one publish and one delivery; the sink adds one delivery per hop
    delivery_us = max(0.0, (1e6 * wall2 / rounds - round_us) / n_nodes)
    publish_us = max(0.0, hop_us - delivery_us)
    floor = round_us + hop_us + step_us
    return {"n_nodes": n_nodes, "rounds": rounds, "executor": executor, "round_us": round_us,
            "round_cpu_us": round_cpu_us, "hop_us": hop_us, "delivery_us": delivery_us,
            "publish_us": publish_us, "sim_step_us": step_us, "tick_floor_us": floor,
            "speed_ceiling": 1e6 * paper.LOOP_PERIOD_S / floor,
            "cpu_per_loop_floor_us": round_cpu_us + step_us}


def pattern_ceiling(floor: dict[str, Any], publishes: float, deliveries: float, timers: float = 0.0) -> float:
    """Simulated s per wall s of a lockstep graph that only moves its messages.

    ``publishes`` and ``deliveries`` per tick (and timers, costed as deliveries) at the
    empty costs measured by :func:`ring_floor`, plus its plant step: what a graph with
    this message pattern could reach if every callback did no work at all.
    """
    tick_us = publishes * floor["publish_us"] + (deliveries + timers) * floor["delivery_us"] + floor["sim_step_us"]
    return 1e6 * paper.LOOP_PERIOD_S / tick_us


def graph_speed_split(duration_s: float, domain_id: int, directory: str | os.PathLike[str],
                      seed: int = 0) -> dict[str, Any]:
    """The same recorded graph with the recorder in a process of its own (the other core).

    The loop's nodes run lockstep in this process with ``EventsExecutor``; a child
    process runs the recorder node (same QoS, same topics) on its own executor. The
    loop does not wait for the recorder, so what it cannot keep up with is lost:
    the messages recorded are compared with those the loop published.

    Returns
    -------
    dict
        ``speed`` (simulated s per wall s), ``cpu_us_per_tick`` (the loop's process),
        ``recorder_cpu_us_per_tick``, ``published`` and ``recorded`` (messages on the
        loop's topics), ``lost``.
    """
    from hasel_sysid.graph import GraphConfig, NodeGraph

    path = Path(directory) / "graph_split.mcap"
    stop = Path(str(path) + ".stop")
    env = dict(os.environ, OPENBLAS_NUM_THREADS="1")
    child = subprocess.Popen([sys.executable, "-m", "hasel_bench.graph", "recorder", str(path),
                              str(domain_id)], stdout=subprocess.PIPE, text=True, env=env)
    try:
        seq = [2.0, 4.0, 6.0, 4.0, 2.0]
        cfg = GraphConfig(sequence_mm=seq, hold_s=duration_s / len(seq), seed=seed, executor="events",
                          domain_id=domain_id, with_collector=False)
        with NodeGraph(cfg) as g:
            pubs = {"/clock": g.plant.clock_pub, "/sensor/timing": g.plant.timing_pub,
                    "/laser/stroke": g.plant.laser_pub, "/plant/batch": g.plant.batch_pub,
                    "/strain/stroke": g.driver.pub, "/strain/stroke_filtered": g.filter.pub,
                    "/amp/command": g.controller.cmd_pub, "/controller/state": g.controller.state_pub,
                    "/amp/applied": g.amplifier.applied_pub}
            deadline = time.monotonic() + 30.0
            # the recorder in the other process must be matched on every loop topic first
            while not all(p.get_subscription_count() >= 1 + (t in ("/amp/applied",)) for t, p in pubs.items()):
                if time.monotonic() > deadline or child.poll() is not None:
                    raise RuntimeError("the recorder process did not connect within 30 s")
                g.executor.spin_once(timeout_sec=0.05)
            g.wait_ready()
            sent = {t: 0 for t in pubs}
            for t, p in pubs.items():  # count what the loop really publishes (skipped ones are not sent)
                p.publish = _counting(p.publish, sent, t)
            w0, c0 = time.perf_counter(), time.process_time()
            g.run(duration_s, wall_timeout_s=600.0)
            wall, cpu = time.perf_counter() - w0, time.process_time() - c0
            ticks = g.plant.sim.tick
            time.sleep(1.0)  # let the recorder drain what is still in flight
            stop.touch()
            line = child.stdout.readline()
        child.wait(timeout=30)
        rec = json.loads(line)
    finally:
        if child.poll() is None:
            child.kill()
            child.wait()
    from hasel.io import info

    counts = {t.topic: int(t.count) for t in info(path).topics}
    recorded = sum(counts.get(t, 0) for t in pubs)
    published = sum(sent.values())
    return {"sim_s": float(duration_s), "wall_s": wall, "speed": duration_s / wall, "ticks": int(ticks),
            "cpu_us_per_tick": 1e6 * cpu / max(ticks, 1),
            "recorder_cpu_us_per_tick": 1e6 * rec["cpu_s"] / max(ticks, 1),
            "published": published, "recorded": recorded, "lost": published - recorded, "per_topic": counts,
            "sent_per_topic": sent}


def _counting(publish, counts: dict[str, int], topic: str):
    """``publish`` that also counts its calls in ``counts[topic]``."""
    def wrapped(msg) -> None:
        counts[topic] += 1
        publish(msg)
    return wrapped


def _recorder_main(argv: list[str]) -> int:
    """Child of :func:`graph_speed_split`: record until ``PATH.stop`` exists; print CPU as JSON."""
    import rclpy
    from rclpy.context import Context
    from rclpy.experimental import EventsExecutor
    from rclpy.task import Future

    from hasel_sysid.recording import recorder_factory

    path, domain = argv[0], int(argv[1])
    stop = Path(path + ".stop")
    ctx = Context()
    rclpy.init(args=["--ros-args", "--log-level", "warn"], context=ctx, domain_id=domain)
    node = recorder_factory(path, list(_LOOP_TOPICS))(ctx)
    ex = EventsExecutor(context=ctx)
    ex.add_node(node)
    c0 = time.process_time()
    try:
        end = time.monotonic() + 900.0
        while not stop.exists() and time.monotonic() < end:
            ex.spin_until_future_complete(Future(), timeout_sec=0.1)
        cpu = time.process_time() - c0
    finally:
        ex.shutdown()
        node.destroy_node()  # closes the file
        rclpy.try_shutdown(context=ctx)
    sys.stdout.write(json.dumps({"cpu_s": cpu}) + "\n")
    sys.stdout.flush()
    return 0


if __name__ == "__main__":
    if sys.argv[1:2] == ["recorder"]:
        sys.exit(_recorder_main(sys.argv[2:]))
    sys.exit(f"usage: python -m hasel_bench.graph recorder PATH DOMAIN (got {sys.argv[1:]})")
