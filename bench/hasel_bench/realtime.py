"""Real-time measurements of the 200 Hz loop for ``hasel bench``: latency, missed periods, scale, load.

One *loop* is the node chain of one actuator on the wall clock: ``sim_plant``
(``clock_mode=wall``: a steady 200 Hz timer steps the plant with the latest command),
``strain_driver``, ``lowpass_filter``, ``pid_controller`` (strain-sensor feedback, so
every tick crosses the whole chain plant -> driver -> filter -> controller -> amplifier
-> plant), ``hv_amplifier`` and ``reference_generator``, all under their own
namespace (``/rt0``, ``/rt1``...), no ``/clock``. The plant is measured from outside
its stepping (:class:`hasel_bench.probe.MeasuredPlant`): the latency from a tick's
sensor stamp to the arrival of the amplifier output carrying that stamp, the periods
whose output had not arrived by the next tick, and its ticks.

Executor: rclpy's ``EventsExecutor`` in every worker process (a message hop costs
about 14 us there against about 175 us with the ``SingleThreadedExecutor``; at 200 Hz
with six nodes per loop the latter would spend a large part of a core per loop).
Its ``spin()`` is never used: on this rclpy it busy-waits and ignores SIGINT;
workers spin with ``spin_until_future_complete`` in bounded stretches instead.

Layouts (``roles`` of a worker): ``all`` hosts whole loops; ``plant`` only the
plants and ``ctrl`` only the other nodes (to compare with the loop split across two
processes, as separate executables would run it).

Timing choices that are part of the layout: the plants' 200 Hz timers are started at
staggered phases (loop k of n at k/n of the period, interleaved across workers), as a
real-time scheduler spreads periodic tasks, so the loops do not all wake at once;
Python's garbage collector is frozen after set-up (``gc.freeze``) so a collection
does not scan the long-lived nodes inside a period.

Missed periods are the measured plant's count (no output by the next tick) plus ticks
the timer skipped because the process woke more than a period late (counted from the
gaps between its wake-ups; ``expected - ticks`` would also count the
phase of a loop's first tick against the window as a miss).

Workers run as ``python -m hasel_bench.realtime WORKER_JSON`` and print one line
(``ready``) when their nodes are matched, wait for ``go EPOCH`` on stdin, print the
result as one JSON line, and tear their nodes down only on ``end`` (sent once every
worker has measured: one worker's teardown must not load the others' window).
"""
from __future__ import annotations

import gc
import json
import math
import os
import subprocess
import sys
import threading
import time
from collections.abc import Callable, Sequence
from dataclasses import asdict, dataclass
from typing import Any

import numpy as np

from hasel import paper
from hasel.errors import HaselError
from hasel.timeconv import ns_to_s

__all__ = ["WorkerSpec", "run_worker", "run_layout", "latency_summary", "busy_loop_process", "PERIOD_S"]

PERIOD_S = paper.LOOP_PERIOD_S
_REFERENCE_CYCLE_MM = (2.0, 4.0, 6.0, 4.0)


@dataclass(frozen=True)
class WorkerSpec:
    """One worker process: which loops it hosts and for how long it measures.

    Attributes
    ----------
    loops : sequence of int
        Indices of the loops (namespace ``/rt<index>``).
    roles : str
        ``"all"``, ``"plant"`` or ``"ctrl"``.
    duration_s : float
        Measured wall time, s.
    warmup_s : float
        Wall time run before measuring (discovery, first transients), s.
    slot : int
        This worker's index among ``slots`` workers (phase interleaving).
    slots : int
        Number of workers hosting plants.
    feedback : str
        ``"strain"`` (whole chain) or ``"laser"``.
    freeze_gc : bool
        ``gc.freeze()`` after set-up.
    domain_id : int
        ROS domain of the run.
    rt_priority : int
        If > 0, run the worker (and the DDS threads it starts) under ``SCHED_FIFO`` at
        this priority, when the system permits it (root, CAP_SYS_NICE or an
        ``rtprio`` limit); otherwise the normal scheduler. The result says which.
    """

    loops: tuple[int, ...]
    roles: str = "all"
    duration_s: float = 10.0
    warmup_s: float = 1.0
    slot: int = 0
    slots: int = 1
    feedback: str = "strain"
    freeze_gc: bool = True
    domain_id: int = 0
    rt_priority: int = 0


def _set_scheduler(priority: int) -> str:
    """SCHED_FIFO at ``priority`` for this thread and the threads it starts, if permitted."""
    if priority <= 0:
        return "SCHED_OTHER"
    try:
        os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(priority))
    except (OSError, AttributeError) as err:
        return f"SCHED_OTHER (SCHED_FIFO refused: {err})"
    return f"SCHED_FIFO {priority}"


def _build(ctx, spec: WorkerSpec, total_s: float) -> tuple[list, list]:
    """The nodes of the worker's loops; returns (all nodes, plants)."""
    from rclpy.parameter import Parameter

    from hasel_control.amplifier_node import HvAmplifierNode
    from hasel_control.controller_node import PidControllerNode
    from hasel_control.reference_node import ReferenceNode
    from hasel_driver.driver_node import StrainDriverNode
    from hasel_driver.filter_node import LowPassNode
    from hasel_bench.probe import MeasuredPlant

    nodes, plants = [], []
    n_refs = min(900, int(math.ceil(total_s)) + 2)
    seq = [_REFERENCE_CYCLE_MM[i % len(_REFERENCE_CYCLE_MM)] for i in range(n_refs)]
    for k in spec.loops:
        kw = {"context": ctx, "namespace": f"/rt{k}"}
        if spec.roles in ("all", "plant"):
            p = MeasuredPlant(None, **kw, parameter_overrides=[Parameter("clock_mode", value="wall"),
                                                           Parameter("seed", value=k)])
            plants.append(p)
            nodes.append(p)
        if spec.roles in ("all", "ctrl"):
            nodes += [StrainDriverNode(**kw), LowPassNode(**kw),
                      PidControllerNode(**kw, parameter_overrides=[Parameter("feedback", value=spec.feedback)]),
                      HvAmplifierNode(**kw),
                      ReferenceNode(**kw, parameter_overrides=[Parameter("sequence_mm", value=seq),
                                                               Parameter("hold_s", value=1.0)])]
    return nodes, plants


def _matched(nodes: list, spec: WorkerSpec) -> bool:
    """Every link this worker publishes or receives has its peer."""
    for n in nodes:
        name = n.get_name()
        if name == "sim_plant":
            fb = n.timing_pub if spec.feedback == "strain" else n.laser_pub
            subs = {s.topic_name: s for s in n.subscriptions}
            applied = next(s for t, s in subs.items() if t.endswith("/amp/applied"))
            if fb.get_subscription_count() < 1 or applied.get_publisher_count() < 1:
                return False
        elif name == "hv_amplifier" and n.applied_pub.get_subscription_count() < 1:
            return False
        elif name == "pid_controller" and n.cmd_pub.get_subscription_count() < 1:
            return False
        elif name == "strain_driver" and n.pub.get_subscription_count() < 1:
            return False
        elif name == "lowpass_filter" and spec.feedback == "strain" and n.pub.get_subscription_count() < 1:
            return False
    return True


def _wall_timer(plant):
    return next(t for t in plant.timers if t.callback == plant.on_wall_tick)


def _stagger(plants: list, spec: WorkerSpec, epoch: float) -> None:
    """Restart plant k's 200 Hz timer at phase (k * slots + slot) / (n * slots) of the period."""
    n = len(plants) * spec.slots
    for i, p in enumerate(plants):
        phase = PERIOD_S * (i * spec.slots + spec.slot) / max(n, 1)
        now = time.monotonic()
        target = epoch + phase + PERIOD_S * math.ceil((now + 0.001 - epoch - phase) / PERIOD_S)
        while time.monotonic() < target - 0.0003:
            time.sleep(0.0002)
        while time.monotonic() < target:
            pass
        _wall_timer(p).reset()


def _spin_for(ex, seconds: float) -> None:
    """Spin ``ex`` for ``seconds`` of wall time, in one call (each new call can stall the loops)."""
    from rclpy.task import Future

    end = time.monotonic() + seconds
    while True:
        left = end - time.monotonic()
        if left <= 0:
            return
        ex.spin_until_future_complete(Future(), timeout_sec=left)


def run_worker(spec: WorkerSpec, go: Callable[[], float] | None = None,
               ready: Callable[[], None] | None = None,
               measured: Callable[[dict[str, Any]], None] | None = None) -> dict[str, Any]:
    """Build the worker's loops, wait for ``go()`` (the phase epoch), warm up, measure.

    ``measured(result)`` is called after the measurement and before the nodes are torn
    down, so that a worker can hold its teardown until every other worker has
    finished measuring (destroying a hundred nodes loads a core and floods DDS
    discovery: it would be counted against the workers still measuring).

    Returns
    -------
    dict
        ``loops`` (per loop: ``latencies_us`` list, ``missed``, ``ticks``, ``expected``,
        ``skipped``, ``missed_at_s``),
        ``cpu_s`` and ``wall_s`` of the measured window, ``setup_s``.
    """
    import rclpy
    from rclpy.context import Context
    from rclpy.experimental import EventsExecutor

    t_setup = time.monotonic()
    sched = _set_scheduler(spec.rt_priority)
    ctx = Context()
    rclpy.init(args=["--ros-args", "--log-level", "warn"], context=ctx, domain_id=spec.domain_id)
    nodes: list = []
    ex = None
    try:
        total = spec.warmup_s + spec.duration_s + 5.0
        nodes, plants = _build(ctx, spec, total)
        ex = EventsExecutor(context=ctx)
        for n in nodes:
            ex.add_node(n)
        deadline = time.monotonic() + 60.0
        while not _matched(nodes, spec):
            if time.monotonic() > deadline:
                raise HaselError("real-time bench: the loops did not connect within 60 s")
            ex.spin_until_future_complete(_done_future(), timeout_sec=0.02)
        setup_s = time.monotonic() - t_setup
        if ready is not None:
            ready()
        epoch = go() if go is not None else time.monotonic()
        if plants:
            _stagger(plants, spec, epoch)
        _spin_for(ex, spec.warmup_s)
        if spec.freeze_gc:
            gc.collect()
            gc.freeze()
            # the collection stalls every loop for tens of ms: let them catch up (1 s: 0.25 s
            # still left periods skipped in the first 0.15 s of the window) before
            # counting, or the stall of the set-up is counted as missed periods
            _spin_for(ex, 1.0)
        for p in plants:
            p.reset_wall_stats()
        pauses: list[tuple[float, int, float]] = []  # (start s, generation, ms): to explain missed periods
        gc_watch = _gc_watch(pauses)
        gc.callbacks.append(gc_watch)
        c0, w0 = time.process_time(), time.monotonic()
        _spin_for(ex, spec.duration_s)
        cpu, wall = time.process_time() - c0, time.monotonic() - w0
        gc.callbacks.remove(gc_watch)
        loops = []
        for p in plants:
            expected = int(round(wall / PERIOD_S))
            loops.append({"ns": p.get_namespace(), "latencies_us": [x / 1e3 for x in p.latencies_ns],
                          "missed": int(p.missed_periods), "ticks": int(p.ticks), "expected": expected,
                          "skipped": int(p.skipped_periods),
                          "missed_at_s": [ns_to_s(x) - w0 for x in p.missed_at_ns],
                          "skipped_at_s": [ns_to_s(x) - w0 for x in p.skipped_at_ns]})
        result = {"loops": loops, "cpu_s": cpu, "wall_s": wall, "setup_s": setup_s, "nodes": len(nodes),
                  "scheduler": sched, "t_start": w0,
                  # collections of 1 ms or more: (s from the window's start, generation, ms)
                  "gc_pauses": [(round(a - w0, 3), g, round(ms, 2)) for a, g, ms in pauses if ms >= 1.0]}
        if measured is not None:
            measured(result)
        return result
    finally:
        if spec.freeze_gc:
            gc.unfreeze()
        if ex is not None:
            ex.shutdown()
        for n in nodes:
            n.destroy_node()
        rclpy.try_shutdown(context=ctx)


def _gc_watch(out: list) -> Callable[[str, dict], None]:
    """A ``gc.callbacks`` hook appending (start time s, generation, duration ms) of each collection."""
    start = [0.0]

    def hook(phase: str, info: dict) -> None:
        if phase == "start":
            start[0] = time.monotonic()
        else:
            out.append((start[0], int(info["generation"]), 1e3 * (time.monotonic() - start[0])))
    return hook


def _done_future():
    from rclpy.task import Future

    return Future()


def latency_summary(loops: Sequence[dict]) -> dict[str, Any]:
    """Pooled latency percentiles (us) and missed periods over ``loops`` (from :func:`run_worker`).

    ``missed`` counts both outputs that came after the next tick and ticks the timer
    skipped; ``worst_loop_p99_us`` is the largest per-loop p99; ``miss_bursts`` groups
    the misses in time (s from the start of the window; see :func:`_bursts`).
    """
    lat = np.concatenate([np.asarray(l["latencies_us"], float) for l in loops]) if loops else np.empty(0)
    expected = sum(l["expected"] for l in loops)
    skipped = sum(l["skipped"] for l in loops)
    late = sum(l["missed"] for l in loops)
    per_p99 = [float(np.percentile(l["latencies_us"], 99)) for l in loops if len(l["latencies_us"])]
    events = sorted(t for l in loops for t in l.get("missed_at_s", []) + l.get("skipped_at_s", []))
    out = {"loops": len(loops), "samples": int(lat.size), "expected_ticks": int(expected),
           "ticks": int(sum(l["ticks"] for l in loops)), "late_outputs": int(late), "skipped_ticks": int(skipped),
           "missed": int(late + skipped), "missed_fraction": (late + skipped) / expected if expected else math.nan,
           "unanswered": int(sum(l["ticks"] for l in loops) - lat.size),
           "miss_bursts": _bursts(events)}
    if lat.size:
        out.update(p50_us=float(np.percentile(lat, 50)), p99_us=float(np.percentile(lat, 99)),
                   max_us=float(lat.max()), worst_loop_p99_us=max(per_p99))
    else:
        out.update(p50_us=math.nan, p99_us=math.nan, max_us=math.nan, worst_loop_p99_us=math.nan)
    return out


def _bursts(times_s: Sequence[float], gap_s: float = 0.1) -> list[list[float]]:
    """Misses grouped in time: [[start s, end s, events], ...] (events closer than ``gap_s``).

    A stall of the machine or of a process misses periods in every loop at once, in one
    burst; scattered single misses point at the loops' own load instead.
    """
    out: list[list[float]] = []
    for t in times_s:
        if out and t - out[-1][1] <= gap_s:
            out[-1][1] = t
            out[-1][2] += 1
        else:
            out.append([t, t, 1])
    return [[round(a, 3), round(b, 3), n] for a, b, n in out]


# -- processes ---------------------------------------------------------------------------

def _worker_main(argv: Sequence[str]) -> int:
    spec_d = json.loads(argv[0])
    spec_d["loops"] = tuple(spec_d["loops"])
    spec = WorkerSpec(**spec_d)
    box: list[float] = []
    got = threading.Event()

    end = threading.Event()

    def reader() -> None:
        for line in sys.stdin:
            if line.startswith("go"):
                box.append(float(line.split()[1]))
                got.set()
            elif line.startswith("end"):
                break
        got.set()  # stdin closed: the parent is gone
        end.set()

    def go() -> float:
        threading.Thread(target=reader, daemon=True).start()
        if not got.wait(120.0) or not box:
            raise HaselError("no go from the parent")
        return box[0]

    def ready() -> None:
        sys.stdout.write("ready\n")
        sys.stdout.flush()

    def measured(res: dict[str, Any]) -> None:
        sys.stdout.write(json.dumps(res) + "\n")
        sys.stdout.flush()
        end.wait(120.0)  # tear down only when every worker has measured

    run_worker(spec, go, ready, measured)
    return 0


def run_layout(specs: Sequence[WorkerSpec], in_process: bool = False,
               timeout_s: float | None = None) -> list[dict[str, Any]]:
    """Run workers (each its own process unless ``in_process`` and a single spec) and collect results.

    Every worker builds and matches its nodes and says ``ready``; then all get the same
    phase epoch, warm up and measure together.
    """
    if in_process:
        if len(specs) != 1:
            raise HaselError("in_process runs one worker")
        return [run_worker(specs[0])]
    limit = timeout_s if timeout_s is not None else 120.0 + max(s.warmup_s + s.duration_s for s in specs)
    procs = []
    env = dict(os.environ)
    env.setdefault("OPENBLAS_NUM_THREADS", "1")
    try:
        for s in specs:
            d = asdict(s)
            d["loops"] = list(s.loops)
            procs.append(subprocess.Popen([sys.executable, "-m", "hasel_bench.realtime", json.dumps(d)],
                                          stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True, env=env))
        deadline = time.monotonic() + limit
        for p in procs:
            line = _readline(p, deadline)
            if line.strip() != "ready":
                raise HaselError(f"real-time worker failed to start (exit {p.poll()}): {line.strip()[:200]}")
        epoch = time.monotonic() + 0.05
        for p in procs:
            p.stdin.write(f"go {epoch!r}\n")
            p.stdin.flush()
        out = []
        for p in procs:
            line = _readline(p, deadline)
            if not line:
                raise HaselError(f"real-time worker ended without a result (exit {p.wait(5)})")
            out.append(json.loads(line))
        for p in procs:  # all have measured: now they may tear down
            p.stdin.write("end\n")
            p.stdin.flush()
        for p in procs:
            p.wait(timeout=max(1.0, deadline - time.monotonic()))
        return out
    finally:
        for p in procs:
            if p.poll() is None:
                p.kill()
                p.wait()


def _readline(p: subprocess.Popen, deadline: float) -> str:
    """One line of a worker's stdout, or kill it at the deadline."""
    result: list[str] = []
    t = threading.Thread(target=lambda: result.append(p.stdout.readline()), daemon=True)
    t.start()
    t.join(max(0.0, deadline - time.monotonic()))
    if t.is_alive():
        p.kill()
        raise HaselError("a real-time worker timed out")
    return result[0]


def busy_loop_process() -> subprocess.Popen:
    """A process that keeps one core busy until killed (the load of issue 7, item 4)."""
    return subprocess.Popen([sys.executable, "-c", "while True:\n    pass\n"])


if __name__ == "__main__":
    sys.exit(_worker_main(sys.argv[1:]))
