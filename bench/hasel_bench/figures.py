"""``hasel bench`` (what ``make bench`` runs): one table of measured figures and ratios, and JSON.

Figures (each measured against its baseline in the same run where one exists):

1. The full graph (plant, driver, filter, controller, amplifier, reference, MCAP
   recorder) in simulated time, lockstep: simulated seconds per wall second, with
   rclpy's ``EventsExecutor``; baseline the same graph with the
   ``SingleThreadedExecutor``. The recording is read back to check that simulated
   time worked with each executor (one output per 5 ms tick on the exact grid).
   Also the executor callbacks per simulated tick (every delivery of every message,
   and the timers on the simulated clock) and the wall time per callback: lockstep
   runs them one after another, so their product sets the speed. And the ceiling
   of any graph of this shape on this machine
   (:func:`~hasel_bench.graph.ring_floor`): five nodes that do nothing but
   pass one message around, one more hop for ``/clock``, and one step of the plant
   simulation; ``period / that`` is the most a lockstep graph of five nodes can
   reach, with and without the plant's own cost. And the ceiling of this graph's
   own message pattern: its publishes and deliveries per tick priced at the empty
   ring's measured cost of a publish and of a delivery, plus the plant step
   (:func:`~hasel_bench.graph.pattern_ceiling`): the speed of the same graph
   if every callback did nothing; a target above it cannot be met with this stack.
   And the other process layout: the recorder in a process of its own, on the other
   core (:func:`~hasel_bench.graph.graph_speed_split`): its speed, and the
   messages it lost (the loop does not wait for a recorder in another process).
2. The offline core closed loop (:func:`hasel.loop.run_closed_loop`): simulated
   seconds per wall second, against ``scipy.signal.lsim`` of the same loop's plant on
   the same input.
3. Real time at 200 Hz (60 s; ``--quick`` 5 s): one loop with strain-sensor feedback
   (plant, driver, filter, controller, amplifier, reference) in one process:
   latency from the sensor stamp to the arrival of the amplifier output carrying it,
   p50/p99/max, and missed periods; baseline the same loop split over two processes
   (plant | the other nodes).
4. Scale: namespaced loops in two worker processes (each hosting half of them in one
   ``EventsExecutor``), counts raised until a count misses 0.1 % of its periods or a
   loop's p99 latency exceeds 2 ms; the CPU used at each count; baseline the largest
   count that held, in one process. A count that fails only on missed periods is
   measured a second time (a stall of the virtual machine misses a period in every
   loop at once); the JSON keeps the first try. And the ceiling: the loops the machine's cores
   could hold if each cost only the CPU of figure 1's empty ring and a plant step.
5. Identification of the paper's campaign (3 actuators x 6 offsets x 60 s at 10 kHz,
   written to MCAP without the graph and cached under ``out/`` for the run only)
   against merely loading the same files; the recorder node's message path against
   a bare ``mcap`` writer writing the same bytes; the MCAP writer alone against the
   bare writer with the same zstd level.
6. The diagnosis blind check (:func:`hasel_bench.blind.run_blind`): top-1
   accuracy, the right pair, false alarms and misses, median held-out shrink, time
   per case ("not available" when that module is absent). Then the same scoring on
   logs of an independent simulator (:func:`hasel_bench.othersim.run_othersim`) whose
   effects have other forms, rates and excitations than the generator the
   diagnosis was developed with.
7. The 200 Hz loop while a busy-loop process loads one core, against figure 3's
   unloaded run of the same length.
8. The log loaders fuzzed (mutated MCAP and CSV files through ``load_io`` and
   ``info``) for a bounded time: cases, hangs, crashes other than
   DataFileError/BadInputError, peak memory. Failing inputs are kept in
   ``bench_fuzz_failures/`` beside the JSON file.
9. Identification and diagnosis on the verification corpus (``bench/verify``, written
   without reading the analysis code; no threshold tuned on it): generated from its
   seed, scored black-box by its own scorer; the issue's figures per corpus.
10. The same on a second verification corpus (``bench/verify2``, session 9: another author
   with its own simulator and effect forms, 103 cases; about 50 min with 2 jobs on 2 cores;
   ``--quick`` scores three of its cases).
11. The same on a third verification corpus (``bench/verify3``, session 10: a third author,
   88 cases, 21 effect forms; ``--quick`` scores three of its cases).

Executors, and why:

- Simulated time (figure 1, and ``hasel steps/calibrate/chirp/demo``):
  ``EventsExecutor``, in one process. Lockstep makes every tick a chain of message
  hops, so the cost per hop sets the speed; it is several times lower there than in
  the ``SingleThreadedExecutor`` (both measured here), and ``/clock`` driven
  timers fire at the right simulated stamps with it (checked on the recording).
  The recorder stays in the loop's process: in a process of its own it gains
  nothing (a message to another process costs its sender more than an in-process
  delivery) and loses what it cannot keep up with (both measured in figure 1).
- Real time (figures 3, 4, 7): ``EventsExecutor`` in each worker process, whole
  loops per process (no loop split across processes: an inter-process hop costs
  more latency than the in-process one, measured as figure 3's baseline); plants'
  timers started at staggered phases; garbage collector frozen after set-up; the
  workers under ``SCHED_FIFO`` (``--rt-priority``, default 50) where the system
  permits it (root, CAP_SYS_NICE or an rtprio limit), as a real-time deployment
  runs, else the normal scheduler; the table says which. On a shared machine the
  normal scheduler lets other processes delay a wake-up by milliseconds. Its
  ``spin()`` is not used (it busy-waits and ignores SIGINT on this rclpy); workers
  spin in bounded stretches.
- Offline figures (2, 5, 6, 8) use no executor.

Every graph runs on a private ROS domain (:func:`hasel.rosenv.private_domain`), so
nothing else on the machine can disturb it. The machine's load average is recorded
with each figure: on a shared machine, real-time figures depend on it.
"""
from __future__ import annotations

import argparse
import json
import math
import os
import shutil
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

from hasel.errors import BadInputError, HaselError
from hasel.outputs import json_safe

__all__ = ["add_arguments", "run", "Row", "format_table", "FIGURES"]

#: Figure numbers and what they measure (``--only`` takes the numbers).
FIGURES = {1: "graph in simulated time", 2: "offline core loop", 3: "real time 200 Hz",
           4: "scale", 5: "identification and recording", 6: "diagnosis blind check",
           7: "200 Hz under load", 8: "loader fuzzing", 9: "verification corpus (untuned)",
           10: "second verification corpus (untuned, another author)",
           11: "third verification corpus (untuned, a third author)"}


@dataclass
class Row:
    """One line of the table. ``ratio`` is value / baseline (None when there is no baseline)."""

    figure: str
    value: str
    baseline: str = "-"
    ratio: float | None = None
    target: str = "-"
    passed: bool | None = None


def format_table(rows: list[Row]) -> str:
    """The rows as a plain-text table (figure | value | baseline | ratio | target | pass)."""
    head = ("figure", "value", "baseline", "ratio", "target", "pass")
    cells = [head] + [(r.figure, r.value, r.baseline, "-" if r.ratio is None or not math.isfinite(r.ratio)
                       else f"{r.ratio:.3g}", r.target,
                       "-" if r.passed is None else ("yes" if r.passed else "NO")) for r in rows]
    widths = [max(len(c[i]) for c in cells) for i in range(len(head))]
    line = "-+-".join("-" * w for w in widths)
    out = [" | ".join(c.ljust(w) for c, w in zip(cells[0], widths)), line]
    out += [" | ".join(c.ljust(w) for c, w in zip(row, widths)) for row in cells[1:]]
    return "\n".join(out)


def add_arguments(p: argparse.ArgumentParser) -> None:
    """Options of ``hasel bench``."""
    p.add_argument("--quick", action="store_true", help="a smoke version (short runs, seconds per figure)")
    p.add_argument("--json", metavar="FILE", default="out/bench.json", help="JSON output (default out/bench.json)")
    p.add_argument("--only", metavar="N,N", default="",
                   help="run only these figures: " + "; ".join(f"{k} {v}" for k, v in FIGURES.items()))
    p.add_argument("--rt-priority", type=int, default=50, metavar="N",
                   help="SCHED_FIFO priority of the real-time workers where the system permits it "
                   "(default 50; 0: the normal scheduler)")
    p.add_argument("--cache", metavar="DIR", default="out/bench_cache",
                   help="where the campaign MCAP files live during the run (default out/bench_cache; removed after)")


def _period_s() -> float:
    """The loop period, s."""
    from hasel import paper

    return paper.LOOP_PERIOD_S


def _load() -> float:
    try:
        return os.getloadavg()[0]
    except OSError:
        return math.nan


class _Bench:
    """State of one run: options, progress, rows and JSON results."""

    def __init__(self, args: argparse.Namespace) -> None:
        self.quick = bool(args.quick)
        self.t0 = time.monotonic()
        self.rows: list[Row] = []
        self.reports: list[str] = []  # printed after the table (e.g. confusion matrices)
        self.results: dict[str, Any] = {}
        self.cache = Path(args.cache)
        self.out_dir = Path(args.json).parent
        self.rt_priority = int(getattr(args, "rt_priority", 50))
        from hasel.rosenv import private_domain

        self.domain = private_domain()

    def say(self, msg: str) -> None:
        sys.stderr.write(f"hasel bench: {msg} ({time.monotonic() - self.t0:.0f} s)\n")
        sys.stderr.flush()

    def row(self, *a, **kw) -> None:
        self.rows.append(Row(*a, **kw))


# -- figures -------------------------------------------------------------------------------

def _fig1(b: _Bench) -> None:
    from hasel_bench.graph import graph_speed

    dur, base_dur = (2.0, 0.5) if b.quick else (20.0, 2.0)
    with tempfile.TemporaryDirectory(prefix="hasel-bench-") as tmp:
        b.say(f"1: graph in simulated time, EventsExecutor, {dur:g} s simulated")
        ev = graph_speed("events", dur, b.domain, tmp)
        b.say(f"1: same graph, SingleThreadedExecutor, {base_dur:g} s simulated")
        st = graph_speed("single", base_dur, b.domain, tmp)
    b.results["1_graph_sim_time"] = {"events": ev, "single": st, "load_avg": _load(),
                                     "msgs_per_tick": sum(ev["recorded"].values()) / max(ev["ticks"], 1)}
    b.row("1 graph+recorder, sim time (sim s / wall s)", f"{ev['speed']:.1f}x (EventsExecutor)",
          f"{st['speed']:.1f}x (SingleThreaded)", ev["speed"] / st["speed"], ">= 40x", ev["speed"] >= 40.0)
    need = 1e6 * _period_s() / 40.0 / ev["us_per_callback"]
    b.row("1 executor callbacks per simulated tick", f"{ev['callbacks_per_tick']:.0f} x {ev['us_per_callback']:.1f} us",
          "-", None, f"40x needs <= {need:.0f} at this cost", None)
    from hasel_bench.graph import graph_speed_split

    b.say(f"1: same graph, recorder in a process of its own, {base_dur * 5:g} s simulated")
    with tempfile.TemporaryDirectory(prefix="hasel-bench-") as tmp:
        sp = graph_speed_split(base_dur * 5, b.domain, tmp)
    b.results["1_graph_sim_time"]["split"] = sp
    b.row("1 same graph, recorder in a 2nd process", f"{sp['speed']:.1f}x, lost {sp['lost']} of "
          f"{sp['published']} messages", f"loop process {sp['cpu_us_per_tick']:.0f} us CPU/tick",
          sp["speed"] / ev["speed"], "nothing lost", sp["lost"] == 0)
    ok = ev["sim_time_ok"] and st["sim_time_ok"]
    b.row("1 simulated time works (5 ms grid, all samples)", "yes" if ok else "NO", "-", None,
          "both executors", ok)
    fl = _ring_floor(b)
    bare = 1e6 * _period_s() / (fl["round_us"] + fl["hop_us"])
    b.row("1 ceiling: empty 5-node ring + /clock hop, + plant step", f"{fl['speed_ceiling']:.1f}x",
          f"{bare:.1f}x (no plant step)", ev["speed"] / fl["speed_ceiling"], ">= 40x", None)
    from hasel_bench.graph import pattern_ceiling

    pat = pattern_ceiling(fl, ev["publishes_per_tick"], ev["deliveries_per_tick"], ev["timers_per_tick"])
    ev["pattern_ceiling"] = pat
    b.row("1 ceiling of this graph's messages, callbacks empty",
          f"{pat:.1f}x ({ev['publishes_per_tick']:.0f} publishes x {fl['publish_us']:.1f} us, "
          f"{ev['deliveries_per_tick']:.0f} deliveries x {fl['delivery_us']:.1f} us)",
          f"+ plant step {fl['sim_step_us']:.0f} us", ev["speed"] / pat, ">= 40x", pat >= 40.0)


def _ring_floor(b: _Bench) -> dict[str, Any]:
    """The empty-ring floor of a tick (measured once per run, shared by figures 1 and 4)."""
    fl = b.results.get("floor")
    if fl is None:
        from hasel_bench.graph import ring_floor

        b.say("1/4: floor of a tick: an empty 5-node ring and one plant step")
        fl = b.results["floor"] = ring_floor(5, 1000 if b.quick else 5000, b.domain)
        fl["load_avg"] = _load()
    return fl


def _fig2(b: _Bench) -> None:
    from hasel_bench.offline import core_vs_lsim

    dur = 2.0 if b.quick else 20.0
    b.say(f"2: offline core loop and lsim, {dur:g} s simulated")
    r = core_vs_lsim(dur)
    r["load_avg"] = _load()
    b.results["2_core_loop"] = r
    b.row("2 offline core closed loop (sim s / wall s)", f"{r['core_speed']:.0f}x",
          f"{r['lsim_speed']:.0f}x (lsim of plant)", r["ratio"], ">= 1 (vs lsim)", r["ratio"] >= 1.0)


def _rt_single(b: _Bench, duration_s: float, roles: str = "all") -> dict[str, Any]:
    from hasel_bench.realtime import WorkerSpec, latency_summary, run_layout

    warm = 1.0 if b.quick else 2.0
    kw = {"duration_s": duration_s, "warmup_s": warm, "domain_id": b.domain, "rt_priority": b.rt_priority}
    if roles == "all":
        specs = [WorkerSpec((0,), **kw)]
    else:
        specs = [WorkerSpec((0,), roles="plant", **kw), WorkerSpec((0,), roles="ctrl", **kw)]
    res = run_layout(specs)
    s = latency_summary([lp for r in res for lp in r["loops"]])
    s["cpu_cores"] = sum(r["cpu_s"] for r in res) / max(res[0]["wall_s"], 1e-9)
    s["duration_s"] = duration_s
    s["load_avg"] = _load()
    s["scheduler"] = res[0]["scheduler"]
    s["gc_pauses"] = [p for r in res for p in r["gc_pauses"]]  # (start, generation, ms): a cause of bursts?
    return s


def _sched(s: dict) -> str:
    """Short name of the scheduler a real-time run used."""
    return str(s.get("scheduler", "?")).split(" (")[0]


def _lat(s: dict) -> str:
    return f"{s['p50_us']:.0f}/{s['p99_us']:.0f}/{s['max_us']:.0f} us"


def _bursts_text(s: dict) -> str:
    """' (in 1 burst at 23.4 s)' when the misses of a run came in bursts, else ''."""
    bursts = s.get("miss_bursts") or []
    if not bursts:
        return ""
    at = ", ".join(f"{a:.1f} s" for a, _, _ in bursts[:3]) + (", ..." if len(bursts) > 3 else "")
    return f" (in {len(bursts)} burst{'s' if len(bursts) > 1 else ''} at {at})"


def _fig3(b: _Bench) -> None:
    dur, base = (5.0, 2.0) if b.quick else (60.0, 10.0)
    b.say(f"3: one loop at 200 Hz in real time, one process, {dur:g} s")
    one = _rt_single(b, dur)
    b.say(f"3: the same loop split over two processes, {base:g} s")
    split = _rt_single(b, base, roles="split")
    b.results["3_realtime"] = {"one_process": one, "two_processes": split}
    ratio = one["p99_us"] / split["p99_us"] if split["p99_us"] > 0 else math.nan
    b.row(f"3 200 Hz latency p50/p99/max (1 process, {_sched(one)})", _lat(one), _lat(split) + " (2 proc)", ratio,
          "p99 < 1000 us", one["p99_us"] < 1000.0)
    b.row("3 200 Hz missed periods (1 process)", f"{one['missed']} of {one['expected_ticks']}{_bursts_text(one)}",
          f"{split['missed']} of {split['expected_ticks']} (2 proc)", None, "0", one["missed"] == 0)


def _scale_point(b: _Bench, n: int, workers: int, duration_s: float) -> dict[str, Any]:
    from hasel_bench.realtime import WorkerSpec, latency_summary, run_layout

    w = max(1, min(workers, n))
    specs = [WorkerSpec(tuple(range(i, n, w)), duration_s=duration_s, warmup_s=1.0, slot=i, slots=w,
                        domain_id=b.domain, rt_priority=b.rt_priority) for i in range(w)]
    res = run_layout(specs)
    s = latency_summary([lp for r in res for lp in r["loops"]])
    wall = max(r["wall_s"] for r in res)
    s.update(n=n, workers=w, cpu_cores=sum(r["cpu_s"] for r in res) / wall,
             cpu_per_worker=[r["cpu_s"] / r["wall_s"] for r in res], load_avg=_load(),
             scheduler=res[0]["scheduler"], gc_pauses=[p for r in res for p in r["gc_pauses"]])
    s["held"] = bool(s["missed_fraction"] < 1e-3 and s["worst_loop_p99_us"] < 2000.0)
    return s


def _fig4(b: _Bench) -> None:
    counts = [1, 2, 4] if b.quick else [1, 2, 4, 8, 12, 16, 20, 24, 28, 32, 40, 48]
    dur = 2.0 if b.quick else 8.0
    curve = []
    best = 0
    for n in counts:
        b.say(f"4: {n} loop(s) at 200 Hz in 2 worker processes, {dur:g} s")
        s = _scale_point(b, n, 2, dur)
        if not s["held"] and s["worst_loop_p99_us"] < 2000.0:
            # only periods missed: one stall of the (virtual) machine misses a period in
            # every loop at once, so a count is measured a second time before it counts
            # as not held; both measurements are in the JSON
            b.say(f"4:   {n} loops missed {100 * s['missed_fraction']:.2f} % of periods{_bursts_text(s)}; "
                  "measuring once more")
            again = _scale_point(b, n, 2, dur)
            again["first_try"] = {k: s[k] for k in ("missed", "missed_fraction", "p99_us", "worst_loop_p99_us",
                                                    "miss_bursts")}
            s = again
        curve.append(s)
        b.say(f"4:   p99 {s['p99_us']:.0f} us (worst loop {s['worst_loop_p99_us']:.0f}), missed "
              f"{100 * s['missed_fraction']:.2f} %, CPU {s['cpu_cores']:.2f} cores -> "
              f"{'held' if s['held'] else 'not held'}")
        if not s["held"]:
            break
        best = n
    one = None
    one_failed = ""
    if best >= 2:
        b.say(f"4: {best} loops in one process (baseline layout), {dur:g} s")
        try:
            one = _scale_point(b, best, 1, dur)
        except HaselError as err:  # one core cannot carry them: that is the baseline's result
            one_failed = str(err)
            b.say(f"4: {best} loops in one process: {err}")
    for s in curve + ([one] if one else []):
        s.pop("cpu_per_worker", None)
    b.results["4_scale"] = {"curve": curve, "one_process_at_best": one, "one_process_failed": one_failed,
                            "max_loops": best,
                            "criteria": "missed < 0.1 % and every loop's p99 < 2 ms"}
    if one_failed:
        base = f"{best} in 1 proc: not held ({one_failed})"
    else:
        base = "-" if one is None else (f"{best} in 1 proc: {'held' if one['held'] else 'not held'}, "
                                        f"p99 {one['worst_loop_p99_us']:.0f} us")
    b.row(f"4 loops holding 200 Hz (2 processes, {_sched(curve[0])})", str(best), base, None, ">= 32", best >= 32)
    cpu = " ".join(f"{s['n']}:{s['cpu_cores']:.2f}" for s in curve)
    per = [s["cpu_cores"] / s["n"] for s in curve if s["held"]]
    b.row("4 CPU cores used by n loops (n:cores)", cpu, "-", None,
          f"{100 * (sum(per) / len(per)):.1f} % core/loop" if per else "-", None)
    fl = _ring_floor(b)
    cores = os.cpu_count() or 1
    ceiling = cores * 1e6 * _period_s() / fl["cpu_per_loop_floor_us"]
    b.row("4 ceiling: loops if each cost only its empty ring + plant step", f"{ceiling:.0f}",
          f"{fl['cpu_per_loop_floor_us']:.0f} us CPU per tick, {cores} cores", None, ">= 32", None)


def _fig5(b: _Bench) -> None:
    from hasel_bench.iospeed import writer_overhead

    from hasel_bench.graph import recorder_vs_bare
    from hasel_bench.offline import CAMPAIGN_GAINS, ident_vs_load, write_campaign

    b.cache.mkdir(parents=True, exist_ok=True)
    paths = []
    kw = {"duration_s": 2.0, "f0_hz": 0.5} if b.quick else {}
    gen = []
    try:
        for k, gain in enumerate(CAMPAIGN_GAINS):
            p = b.cache / f"campaign_actuator{k + 1}.mcap"
            b.say(f"5: writing the campaign of actuator {k + 1} to {p}")
            gen.append(write_campaign(p, gain, seed=k, **kw))
            paths.append(p)
        b.say("5: identification vs loading")
        r = ident_vs_load(paths)
    finally:
        for p in paths:
            p.unlink(missing_ok=True)
        try:
            b.cache.rmdir()
        except OSError:
            pass
    b.say("5: recorder node vs bare mcap writer")
    rec = recorder_vs_bare(4000 if b.quick else 20000, 3, b.domain)
    b.say("5: MCAP writer vs bare mcap writer (zstd)")
    wo = writer_overhead(4000 if b.quick else 20000, repeats=3)
    b.results["5_ident_recording"] = {"campaign": gen, "identify_vs_load": r, "recorder_vs_bare": rec,
                                      "writer_vs_bare": wo, "load_avg": _load()}
    b.row("5 identify campaign from MCAP (CPU s)", f"{r['identify_cpu_s']:.2f} s",
          f"{r['load_cpu_s']:.2f} s (load only)", r["ratio"], "< 2x", r["ratio"] < 2.0)
    b.row("5 recorder node per message (no compression)", f"{rec['recorder_us']:.2f} us",
          f"{rec['bare_us']:.2f} us (bare mcap)", rec["ratio"], "< 1.3x", rec["ratio"] < 1.3)
    b.row("5 MCAP writer per message (zstd 3)", f"{wo['ours_us']:.2f} us", f"{wo['bare_us']:.2f} us (bare mcap)",
          wo["ratio"], "< 1.3x", wo["ratio"] < 1.3)


def _fig6(b: _Bench) -> None:
    try:
        from hasel_bench.blind import run_blind
    except ImportError as err:
        b.results["6_blind"] = {"available": False, "reason": str(err)}
        b.row("6 diagnosis blind check", "not available", "-", None, "-", None)
        return
    n, quick = (4, True) if b.quick else (30, False)
    b.say(f"6: diagnosis blind check, {n} cases, 2 workers")
    s = run_blind(n, seed=0, workers=2, quick=quick, progress=lambda m: b.say("6: " + m.strip()))
    from hasel_bench.blind import format_report

    b.reports.append(format_report(s))  # the labels revealed: confusion matrix, wrong cases
    cases = s.pop("cases", [])
    s["wrong"] = [{"case": c["case"], "truth": c["truth"], "named": c["named"]} for c in cases if not c["correct"]]
    s["load_avg"] = _load()
    s["quick_cases"] = quick
    b.results["6_blind"] = s

    def pct(x):
        return "n/a" if x is None else f"{100 * x:.0f} %"

    top1 = s.get("top1_accuracy")
    b.row("6 blind: top-1 (single/none)", f"{pct(top1)} of {s.get('n_single_or_none')}", "-", None, ">= 90 %",
          None if top1 is None else top1 >= 0.9)
    pair = s.get("pair_accuracy")
    b.row("6 blind: right pair (two effects)", f"{pct(pair)} of {s.get('n_pairs')}", "-", None, "most (> 50 %)",
          None if pair is None else pair > 0.5)
    fa, n_none = s.get("false_alarms", 0), s.get("n_none", 0)
    mi, n_eff = s.get("misses", 0), s.get("n_effect_cases", 0)
    b.row("6 blind: false alarms / misses", f"{fa} of {n_none} / {mi} of {n_eff}", "-", None, "<= 1 in 20 each",
          (n_none == 0 or fa / n_none <= 0.05) and (n_eff == 0 or mi / n_eff <= 0.05))
    sh = s.get("median_shrink")
    b.row("6 blind: median held-out shrink", pct(sh), "-", None, ">= 70 %", None if sh is None else sh >= 0.7)
    spc = s.get("seconds_per_case")
    b.row("6 blind: time per case", "n/a" if spc is None else f"{spc:.1f} s", "-", None, "-", None)
    _fig6_foreign(b, pct)


def _fig6_foreign(b: _Bench, pct: Callable[[float | None], str]) -> None:
    """The same blind scoring on logs of an independent simulator (:mod:`hasel_bench.othersim`).

    Its effects have other forms (slew limits, Prandtl-Ishlinskii and Duhem hysteresis,
    Pade delays, power-law maps, springy loads...), other rates (500 Hz, 1 kHz) and
    excitations: the diagnosis cannot have been tuned to its parameters.
    """
    from hasel_bench.othersim import run_othersim

    n = 3 if b.quick else 10
    b.say(f"6: the diagnosis on an independent simulator's logs, {n} cases")
    s = run_othersim(n, seed=2, progress=lambda m: b.say("6: " + m.strip()), short=b.quick)
    from hasel_bench.othersim import format_report

    b.reports.append(format_report(s))
    cases = s.pop("cases", [])
    s["wrong"] = [{"case": c["case"], "truth": c["truth"], "named": c["named"]} for c in cases if not c["correct"]]
    s.pop("no_model", None)
    s["load_avg"] = _load()
    b.results["6_othersim"] = s
    b.row("6 other simulator: top-1 (single/none)", f"{pct(s.get('top1_accuracy'))} of {s.get('n_single_or_none')}",
          f"{pct(b.results['6_blind'].get('top1_accuracy'))} (own generator)", None, "-", None)
    b.row("6 other simulator: both of a pair named", f"{pct(s.get('pair_both_named'))} of {s.get('n_pairs')}",
          "-", None, "-", None)
    b.row("6 other simulator: false alarms / misses", f"{s.get('false_alarms')} of {s.get('n_none')} / "
          f"{s.get('misses')} of {s.get('n_effect_cases')}", "-", None, "-", None)
    b.row("6 other simulator: median shrink, time per case", f"{pct(s.get('median_shrink'))}, "
          f"{s.get('seconds_per_case') or math.nan:.1f} s", "-", None, "-", None)


def _fig9(b: _Bench) -> None:
    """Identification and diagnosis on the verification corpus (``bench/verify``), on which no threshold
    was tuned: generated from its seed, then scored black-box by its own scorer (exit codes and JSON only).
    """
    here = Path(__file__).resolve().parents[1] / "verify"  # bench/verify, beside this package
    if not (here / "score.py").is_file():
        raise FileNotFoundError(f"the verification corpus's scripts are not at {here} (an editable install of bench/ "
                                "keeps them beside this package)")
    hasel = Path(sys.executable).with_name("hasel")  # the venv's command, as a user runs it
    quick = ["--quick"] if b.quick else []
    with tempfile.TemporaryDirectory(prefix="hasel-verify-") as tmp:
        b.say(f"9: generating the verification corpus{' (quick subset)' if b.quick else ''}")
        subprocess.run([sys.executable, str(here / "gen.py"), "--out", tmp, *quick], check=True,
                       stdout=subprocess.DEVNULL)
        b.say("9: scoring it black-box (hasel identify / diagnose in subprocesses, 2 jobs)")
        subprocess.run([sys.executable, str(here / "score.py"), "--corpus", tmp, "--jobs", "2", *quick,
                        "--hasel", str(hasel)], check=True, stdout=subprocess.DEVNULL)
        s = json.loads(Path(tmp, "score.json").read_text())
        b.reports.append("verification corpus (untuned):\n" + Path(tmp, "score.md").read_text())
    b.results["9_verify"] = s

    d, i = s.get("diagnose", {}), s.get("ident", {})
    if d:
        sg, m, ef, nf, sh = d["single"], d["multi"], d["effect_free"], d["near_floor"], d["shrink"]
        b.row("9 verify: single effects top-1", _frac(sg["top1"], sg["n"]), "-", None, ">= 95 %",
              None if not sg["n"] else sg["top1"] >= 0.95 * sg["n"])
        for cat in ("pair", "triple"):
            mc = m[cat]
            ok = None if mc["recall"] is None or mc["precision"] is None else (
                mc["recall"] >= 0.85 and mc["precision"] >= 0.90)
            b.row(f"9 verify: {cat}s recall / precision", f"{_f2(mc['recall'])} / {_f2(mc['precision'])}",
                  "-", None, ">= 0.85 / 0.90", ok)
        b.row("9 verify: effect-free logs with no effect named", _frac(ef["n"] - ef["false_alarms"], ef["n"]),
              "-", None, ">= 95 %", None if not ef["n"] else ef["false_alarms"] <= 0.05 * ef["n"])
        b.row("9 verify: near-floor false attributions", _frac(nf["false_attributions"], nf["n"]), "-", None, "-", None)
        w = d["worse_than_nominal"]
        b.row("9 verify: held-out shrink median / worst; worse, unflagged",
              f"{_f2(sh['median'])} / {_f2(sh['worst'])}; {w['n'] - w['flagged']}", "-", None, ">= 0.80; 0",
              None if sh["median"] is None else sh["median"] >= 0.80 and w["n"] == w["flagged"])
        b.row("9 verify: seconds per diagnosis, median / max",
              f"{d['seconds']['median']:.1f} / {d['seconds']['max']:.1f}", "-", None, "-", None)
    if i:
        ot = i.get("offset_test", {})
        b.row("9 verify: identify within 1 dB / 5 deg (0.1-15 Hz)", _frac(i["within_1db_5deg"], i["n"]), "-", None,
              "all", i["within_1db_5deg"] == i["n"])
        if ot.get("n"):
            b.row("9 verify: offset test false rejections at p = 0.05", _frac(ot["rejected_at_0.05"], ot["n"]),
                  "-", None, "<= 5 %", ot["rejected_at_0.05"] <= 0.05 * ot["n"])


def _quick_cases(labels: Path) -> str:
    """A smoke subset of the second corpus: one effect-free log, one single effect, one identification log."""
    ids = sorted(f.stem for f in labels.glob("*.json"))
    pick = [next(i for i in ids if i.startswith(p)) for p in ("free_", "single_", "id_")]
    return ",".join(pick)


def _fig10(b: _Bench) -> None:
    """Identification and diagnosis on the second verification corpus (``bench/verify2``: another author,
    its own simulator and effect forms, seed 2), on which no threshold was tuned; scored black-box by its
    own scorer. ``--quick`` scores three of its cases."""
    here = Path(__file__).resolve().parents[1] / "verify2"
    if not (here / "score.py").is_file():
        raise FileNotFoundError(f"the second verification corpus's scripts are not at {here}")
    hasel = Path(sys.executable).with_name("hasel")
    with tempfile.TemporaryDirectory(prefix="hasel-verify2-") as tmp:
        b.say("10: generating the second verification corpus (about 4 min, 240 MB)")
        subprocess.run([sys.executable, str(here / "gen.py"), "--out", tmp], check=True, stdout=subprocess.DEVNULL)
        only = ["--cases", _quick_cases(Path(tmp, "labels"))] if b.quick else []
        b.say(f"10: scoring it black-box (2 jobs{', a 3-case subset' if b.quick else ''})")
        out = Path(tmp, "score", "score.json")
        out.parent.mkdir()
        subprocess.run([sys.executable, str(here / "score.py"), "--corpus", tmp, "--hasel", str(hasel),
                        "--jobs", "2", "--json", str(out), *only], check=True, stdout=subprocess.DEVNULL)
        s = json.loads(out.read_text())["summary"]
        b.reports.append("second verification corpus (untuned):\n" + out.with_suffix(".md").read_text())
    b.results["10_verify2"] = s

    if "singles" in s:
        sg, ef, nf, sh, w = s["singles"], s["effect_free"], s["near_floor"], s["shrink_effect_cases"], s["worse_unflagged"]
        b.row("10 verify2: single effects top-1", _frac(sg["top1"], sg["n"]), "-", None, ">= 95 %",
              None if not sg["n"] else sg["top1"] >= 0.95 * sg["n"])
        for cat in ("pairs", "triples"):
            c = s[cat]
            ok = None if c["recall"] is None or c["precision"] is None else c["recall"] >= 0.85 and c["precision"] >= 0.90
            b.row(f"10 verify2: {cat} recall / precision", f"{_f2(c['recall'])} / {_f2(c['precision'])}", "-", None,
                  ">= 0.85 / 0.90", ok)
        b.row("10 verify2: effect-free logs with no effect named", _frac(ef["no_effect_named"], ef["n"]), "-", None,
              ">= 95 %", None if not ef["n"] else ef["no_effect_named"] >= 0.95 * ef["n"])
        b.row("10 verify2: near-floor false attributions", _frac(nf["false_attributions"], nf["n"]), "-", None, "0",
              None if not nf["n"] else nf["false_attributions"] == 0)
        b.row("10 verify2: held-out shrink median / worst; worse, unflagged",
              f"{_f2(sh.get('median'))} / {_f2(sh.get('min'))}; {w['n']}", "-", None, ">= 0.80; 0",
              None if sh.get("median") is None else sh["median"] >= 0.80 and w["n"] == 0)
        ds = s["diagnose_seconds"]
        b.row("10 verify2: seconds per diagnosis, median / max", f"{ds['median']:.1f} / {ds['max']:.1f}", "-", None,
              "-", None)
    if "ident" in s:
        i = s["ident"]
        b.row("10 verify2: identify exit 0 and within 1 dB / 5 deg (0.1-15 Hz)", _frac(i["exit0_within_tol"], i["n"]),
              "-", None, "all", i["exit0_within_tol"] == i["n"])
        b.row("10 verify2: offset test false rejections", _frac(len(i["dependence_false_rejections"]),
                                                                 i["dependence_tested"]), "-", None, "<= 5 %",
              None if not i["dependence_tested"] else
              len(i["dependence_false_rejections"]) <= 0.05 * i["dependence_tested"])


def _fig11(b: _Bench) -> None:
    """Identification and diagnosis on the third verification corpus (``bench/verify3``, session 10:
    a third author, its own simulator and 21 effect forms, seed 3), on which no threshold was tuned;
    scored black-box by its own scorer. ``--quick`` scores its own three-case subset."""
    here = Path(__file__).resolve().parents[1] / "verify3"
    if not (here / "score.py").is_file():
        raise FileNotFoundError(f"the third verification corpus's scripts are not at {here}")
    hasel = Path(sys.executable).with_name("hasel")
    with tempfile.TemporaryDirectory(prefix="hasel-verify3-") as tmp:
        b.say("11: generating the third verification corpus (about 3 min, 130 MB)")
        subprocess.run([sys.executable, str(here / "gen.py"), "--out", tmp, "--seed", "3"], check=True,
                       stdout=subprocess.DEVNULL)
        b.say(f"11: scoring it black-box (2 jobs{', a 3-case subset' if b.quick else ''})")
        out = Path(tmp, "score.json")
        p = subprocess.run([sys.executable, str(here / "score.py"), "--corpus", tmp, "--hasel", str(hasel),
                            "--jobs", "2", "--json", str(out), "--work", str(Path(tmp, "runs")),
                            *(["--quick"] if b.quick else [])], check=True, stdout=subprocess.PIPE, text=True)
        s = json.loads(out.read_text())["summary"]
        b.reports.append("third verification corpus (untuned):\n" + p.stdout)
    b.results["11_verify3"] = s

    sg, ef, nf, sh = s["singles"], s["effect_free"], s["near_floor"], s["shrink"]
    if sg["n"]:
        b.row("11 verify3: single effects top-1", _frac(sg["top1"], sg["n"]), "-", None, ">= 95 %",
              sg["top1"] >= 0.95 * sg["n"])
    for cat in ("pairs", "triples"):
        c = s[cat]
        if c["n"]:
            ok = None if c["recall"] is None or c["precision"] is None else c["recall"] >= 0.85 and c["precision"] >= 0.90
            b.row(f"11 verify3: {cat} recall / precision", f"{_f2(c['recall'])} / {_f2(c['precision'])}", "-", None,
                  ">= 0.85 / 0.90", ok)
    if ef["n"]:
        b.row("11 verify3: effect-free logs with no effect named", _frac(ef["clean"], ef["n"]), "-", None, ">= 95 %",
              ef["clean"] >= 0.95 * ef["n"])
    if nf["n"]:
        b.row("11 verify3: near-floor false attributions", _frac(nf["false_attribution"], nf["n"]), "-", None, "0",
              nf["false_attribution"] == 0)
    if sh["n"]:
        b.row("11 verify3: held-out shrink median / worst; worse, unflagged",
              f"{_f2(sh['median'])} / {_f2(sh['worst'])}; {len(sh['worse_unflagged'])}", "-", None, ">= 0.80; 0",
              sh["median"] >= 0.80 and not sh["worse_unflagged"])
    i, ot = s["identify"], s["offset_test"]
    if i["n"]:
        b.row("11 verify3: identify exit 0 and within 1 dB / 5 deg (0.1-15 Hz)", _frac(i["passed"], i["n"]), "-",
              None, "all", i["passed"] == i["n"])
    if ot["reported"]:
        b.row("11 verify3: offset test false rejections", _frac(ot["rejected"], ot["reported"]), "-", None,
              "<= 5 %", ot["rejected"] <= 0.05 * ot["reported"])
    b.row("11 verify3: seconds per case, median / max",
          f"{s['seconds']['median']:.1f} / {s['seconds']['max']:.1f}", "-", None, "-", None)


def _frac(a: int, n: int) -> str:
    """``a/n`` as counted, "-" when there is nothing to count."""
    return f"{a}/{n}" if n else "-"


def _f2(x: float | None) -> str:
    """A share or ratio with two decimals, "-" when there is none."""
    return "-" if x is None else f"{x:.2f}"


def _fig7(b: _Bench) -> None:
    from hasel_bench.realtime import busy_loop_process

    dur = 5.0 if b.quick else 60.0
    unloaded = b.results.get("3_realtime", {}).get("one_process")
    if unloaded is None or unloaded.get("duration_s") != dur:
        b.say(f"7: one loop at 200 Hz without load, {dur:g} s")
        unloaded = _rt_single(b, dur)
    b.say(f"7: one loop at 200 Hz while a busy-loop process loads a core, {dur:g} s")
    hog = busy_loop_process()
    try:
        loaded = _rt_single(b, dur)
    finally:
        hog.kill()
        hog.wait()
    b.results["7_under_load"] = {"loaded": loaded, "unloaded": unloaded, "load": "one busy-loop process"}
    ratio = loaded["p99_us"] / unloaded["p99_us"] if unloaded["p99_us"] > 0 else math.nan
    b.row(f"7 200 Hz + busy core: p50/p99/max ({_sched(loaded)})", _lat(loaded), _lat(unloaded) + " (no load)", ratio,
          "p99 < 1000 us", loaded["p99_us"] < 1000.0)
    b.row("7 200 Hz + busy core: missed periods", f"{loaded['missed']} of {loaded['expected_ticks']}"
          f"{_bursts_text(loaded)}",
          f"{unloaded['missed']} of {unloaded['expected_ticks']} (no load)", None, "0", loaded["missed"] == 0)


def _fig8(b: _Bench) -> None:
    from hasel_bench.fuzz import run_fuzz

    budget, timeout = (3.0, 5.0) if b.quick else (20.0, 10.0)
    fail_dir = b.out_dir / "bench_fuzz_failures"
    shutil.rmtree(fail_dir, ignore_errors=True)
    b.say(f"8: fuzzing the loaders for {budget:g} s (per-case timeout {timeout:g} s)")
    r = run_fuzz(budget, case_timeout_s=timeout, failures_dir=fail_dir, progress=b.say)
    b.results["8_fuzz"] = r
    kinds = ", ".join(f"{k} x{v}" for k, v in r["crashes_by_type"].items())
    b.row("8 loader fuzzing: cases (ok/rejected)", f"{r['cases']} ({r['ok']}/{r['rejected']})", "-", None,
          "no hang", not r["hangs"])
    b.row("8 loader fuzzing: other exceptions", f"{r['crashed']}" + (f" ({kinds})" if kinds else ""), "-", None,
          "0 (only DataFileError/BadInputError)", r["crashed"] == 0)
    b.row("8 loader fuzzing: peak memory", f"{r['peak_rss_mib']:.0f} MiB (+{r['rss_growth_mib']:.0f})", "-", None,
          f"< {r['mem_limit_mib']} MiB limit", 0 < r["peak_rss_mib"] < r["mem_limit_mib"])
    from hasel_bench.fuzz import run_cli_fuzz  # every subcommand and node (issue 17)

    c = b.results["8_cli_fuzz"] = run_cli_fuzz(1.0 if b.quick else 4.0, progress=b.say)
    b.row("8 CLI fuzzing: cases tried", f"{c['cases']} ({c['wall_s']:.0f} s)", "-", None,
          "exit 0/1/2, no traceback, no overwrite", c["passed"])


_RUNNERS: dict[int, Callable[[_Bench], None]] = {1: _fig1, 2: _fig2, 3: _fig3, 4: _fig4, 5: _fig5, 6: _fig6,
                                                  7: _fig7, 8: _fig8, 9: _fig9, 10: _fig10,
                                                  11: _fig11}


def _parse_only(text: str) -> list[int]:
    if not text.strip():
        return sorted(_RUNNERS)
    try:
        want = sorted({int(x) for x in text.split(",") if x.strip()})
    except ValueError as err:
        raise BadInputError(f"--only takes figure numbers like 1,3,5, got {text!r}") from err
    bad = [n for n in want if n not in _RUNNERS]
    if bad or not want:
        raise BadInputError(f"--only: figures are {', '.join(map(str, _RUNNERS))}, got {text!r}")
    return want


def run(args: argparse.Namespace) -> int:
    """Run the benchmarks; print the table; write the JSON. Exit 1 if a figure could not be measured."""
    figures = _parse_only(args.only)
    prio = getattr(args, "rt_priority", 50)
    if not 0 <= prio <= 99:
        raise BadInputError(f"--rt-priority must be 0 (off) or a SCHED_FIFO priority 1-99, got {prio}")
    out = Path(args.json)
    try:
        out.parent.mkdir(parents=True, exist_ok=True)
    except OSError as err:
        raise BadInputError(f"cannot write {out}: {err.strerror or err}") from err
    os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
    b = _Bench(args)
    b.say(f"figures {','.join(map(str, figures))}{' (quick)' if b.quick else ''}, ROS domain {b.domain}, "
          f"{os.cpu_count()} CPUs, load average {_load():.2f}")
    errors = {}
    seconds = {}
    for n in figures:
        t_fig = time.monotonic()
        try:
            _RUNNERS[n](b)
        except Exception as err:  # noqa: BLE001 - one figure failing must not hide the others
            import traceback

            errors[n] = f"{type(err).__name__}: {err}\n{traceback.format_exc()}"
            b.row(f"{n} {FIGURES[n]}", "FAILED", "-", None, "-", False)
            b.say(f"{n}: failed: {type(err).__name__}: {err}")
        seconds[str(n)] = time.monotonic() - t_fig
    table = format_table(b.rows)
    print(table)
    for rep in b.reports:
        print()
        print(rep)
    if b.quick:
        print("(--quick: short runs to check that every figure works; the targets apply to the full run)")
    doc = {"quick": b.quick, "figures": figures, "rt_priority": b.rt_priority, "wall_s": time.monotonic() - b.t0,
           "seconds_per_figure": seconds, "cpus": os.cpu_count(), "domain_id": b.domain, "table": [asdict(r) for r in b.rows],
           "results": b.results, "errors": errors}
    with open(out, "w") as fh:
        json.dump(json_safe(doc), fh, indent=1, allow_nan=False)
        fh.write("\n")
    b.say(f"wrote {out}")
    return 1 if errors else 0
