"""ROS-free measurements for ``hasel bench``: the core closed loop, and identification from MCAP.

- :func:`core_vs_lsim`: :func:`hasel.loop.run_closed_loop` (sensors, driver map,
  filter, dual-mode PID, limits and the 10 kHz plant, tick by tick) in simulated
  seconds per wall second, against ``scipy.signal.lsim`` of the same loop's plant
  (amplifier filter times P(s), zero-order hold at 10 kHz) on the same applied input.
  The two outputs are compared as a check that both computed the same thing.
- :func:`write_campaign`: the paper's identification campaign for one actuator (Table
  I: six offsets 2-7 kV, three 20 s chirps each, -1 kV before each, 10 kHz) written
  straight to MCAP as the recorder would hold it (``/plant/batch`` at 200 Hz with 50
  samples each, ``/markers``), without the ROS graph.
- :func:`ident_vs_load`: ``load_io`` + ``identify`` (what ``hasel identify`` does, minus
  writing files) against ``load_io`` alone, CPU time.
"""
from __future__ import annotations

import os
import time
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from hasel import paper
from hasel.timeconv import ns_to_stamp, s_to_ns

__all__ = ["core_vs_lsim", "write_campaign", "ident_vs_load", "CAMPAIGN_GAINS"]

#: Gain of each of the three actuators relative to P(s) (three different actuators).
CAMPAIGN_GAINS = (0.9, 1.0, 1.1)


def core_vs_lsim(duration_s: float, seed: int = 0) -> dict[str, Any]:
    """Offline closed loop against lsim of its plant; simulated s per wall s of each.

    Returns
    -------
    dict
        ``core_speed``, ``lsim_speed``, ``ratio`` (core / lsim), ``core_wall_s``,
        ``lsim_wall_s``, ``max_abs_diff_mm`` (lsim output against the loop's true stroke).
    """
    import scipy.signal

    from hasel.loop import LoopConfig, run_closed_loop, step_reference
    from hasel.plant import NominalConfig, amplifier_filter_tf
    from hasel.simulator import PlantSimulator

    seq = [2.0, 4.0, 6.0, 4.0, 2.0]
    sim = PlantSimulator(seed=seed)
    w0 = time.perf_counter()
    res = run_closed_loop(sim, step_reference(seq, duration_s / len(seq)), duration_s, LoopConfig())
    core = time.perf_counter() - w0
    cfg = NominalConfig()
    an, ad = amplifier_filter_tf(cfg.amp_filter_hz)
    num, den = np.polymul(an, cfg.num), np.polymul(ad, cfg.den)
    per = int(round(paper.PLANT_RATE_HZ * paper.LOOP_PERIOD_S))
    u = np.repeat(res.command_kv, per)
    t = np.arange(u.size) / paper.PLANT_RATE_HZ
    w0 = time.perf_counter()
    _, y, _ = scipy.signal.lsim((num, den), u, t, interp=False)
    lsim_s = time.perf_counter() - w0
    # the plant reports each sample at the end of its hold, lsim at its start
    diff = float(np.max(np.abs(y[1:] - res.true_stroke_mm[:-1])))
    return {"sim_s": float(duration_s), "core_wall_s": core, "lsim_wall_s": lsim_s,
            "core_speed": duration_s / core, "lsim_speed": duration_s / lsim_s, "ratio": lsim_s / core,
            "max_abs_diff_mm": diff}


def write_campaign(path: str | os.PathLike[str], gain: float = 1.0, seed: int = 0, *,
                   duration_s: float = paper.CHIRP_PROTOCOL["duration_s"],
                   f0_hz: float = paper.CHIRP_PROTOCOL["f0_hz"]) -> dict[str, Any]:
    """Write one actuator's campaign (Table I) to an MCAP file, fast and without ROS.

    Parameters
    ----------
    path : path-like
        The MCAP file to write.
    gain : float
        Gain of this actuator relative to the paper's P(s).
    seed : int
        Seed of the laser noise.
    duration_s, f0_hz : float
        Chirp length (s) and start frequency (Hz); the paper's by default.

    Returns
    -------
    dict
        ``samples``, ``simulated_s``, ``write_s`` and ``file_mib``.
    """
    from hasel.io import Ros2McapWriter
    from hasel_bench.iospeed import encode, encode_sample_batch
    from hasel.plant import NominalActuator, NominalConfig
    from hasel.sensors import LaserConfig, LaserSensor
    from hasel.signals import protocol_schedule

    t0 = time.perf_counter()
    sched = protocol_schedule(duration_s=duration_s, f0_hz=f0_hz)
    base = NominalConfig()
    act = NominalActuator(NominalConfig(num=tuple(gain * np.asarray(base.num)), den=base.den))
    act.reset(0.0)
    out = act.run(sched.command_kv)
    laser = LaserSensor(LaserConfig(), np.random.default_rng(seed)).measure(out.stroke_mm)
    per = int(round(paper.PLANT_RATE_HZ * paper.LOOP_PERIOD_S))
    n = sched.command_kv.size // per
    v = out.applied_kv[:n * per].reshape(n, per)
    y = laser[:n * per].reshape(n, per)
    z = out.stroke_mm[:n * per].reshape(n, per)
    period_ns = s_to_ns(paper.LOOP_PERIOD_S)
    dt_ns = s_to_ns(1.0 / paper.PLANT_RATE_HZ)
    with Ros2McapWriter(path, fsync_interval_s=None) as w:
        mk = w.add_topic("/markers", "hasel_msgs/msg/ExperimentMarker")
        for r in sched.records:
            for start, t in ((True, r.start_s), (False, r.end_s)):
                tn = s_to_ns(t)
                w.write(mk, encode("hasel_msgs/msg/ExperimentMarker", {
                    "header": {"stamp": dict(zip(("sec", "nanosec"), ns_to_stamp(tn)))}, "label": r.kind,
                    "signal": r.excitation or "constant", "offset_kv": float(r.offset),
                    "amplitude_kv": 1.0 if r.kind == "excitation" else 0.0, "f0_hz": float(f0_hz), "f1_hz": 20.0,
                    "duration_s": float(duration_s), "start": start}), tn, tn)
        b = w.add_topic("/plant/batch", "hasel_msgs/msg/SampleBatch")
        for i in range(n):
            stamp = i * period_ns + dt_ns  # first sample: end of its 0.1 ms hold, as the plant node stamps
            w.write(b, encode_sample_batch(stamp, 1.0 / paper.PLANT_RATE_HZ, v[i], y[i], z[i]),
                    stamp + period_ns, stamp + period_ns, i)
    size = Path(path).stat().st_size
    return {"samples": int(n * per), "simulated_s": n * per / paper.PLANT_RATE_HZ,
            "write_s": time.perf_counter() - t0, "file_mib": size / 2**20}


def _excitation_segments(data: Any) -> list[tuple[float, float, float]]:
    """``(t_start_s, t_end_s, offset_kv)`` of the log's marked excitations (as ``hasel identify`` uses them)."""
    return [(m.t_start_s, m.t_end_s, m.offset_kv) for m in data.marker_segments if m.label == "excitation"]


def ident_vs_load(paths: Sequence[str | os.PathLike[str]], repeats: int = 2) -> dict[str, Any]:
    """Identification from MCAP against loading the same files, CPU time summed over ``paths``.

    Loading is ``load_io``; identification is ``load_io`` then ``identify`` with the
    log's markers, as ``hasel identify`` runs them; each the best of ``repeats``.

    Returns
    -------
    dict
        ``load_cpu_s``, ``identify_cpu_s`` (load included), ``ratio``, the wall times,
        ``samples`` and per file the operating points used and the held-out fit.
    """
    from hasel.ident import identify
    from hasel.io import load_io

    load_cpu = load_wall = ident_cpu = ident_wall = 0.0
    samples = 0
    models = []
    for p in paths:
        best_c = best_w = float("inf")
        for _ in range(repeats):
            c0, w0 = time.process_time(), time.perf_counter()
            data = load_io(p)
            best_c, best_w = min(best_c, time.process_time() - c0), min(best_w, time.perf_counter() - w0)
            del data
        load_cpu += best_c
        load_wall += best_w
        best_c = best_w = float("inf")
        for _ in range(repeats):
            c0, w0 = time.process_time(), time.perf_counter()
            data = load_io(p)
            res = identify(data.t_s, data.u, data.y, segments=_excitation_segments(data) or None,
                           input_name=data.input_name, output_name=data.output_name)
            best_c, best_w = min(best_c, time.process_time() - c0), min(best_w, time.perf_counter() - w0)
        ident_cpu += best_c
        ident_wall += best_w
        samples += data.n
        models.append({"file": Path(p).name, "operating_points": len(res.points),
                       "summary": res.summary_lines()[:5]})
    return {"files": len(paths), "samples": samples, "load_cpu_s": load_cpu, "load_wall_s": load_wall,
            "identify_cpu_s": ident_cpu, "identify_wall_s": ident_wall, "ratio": ident_cpu / load_cpu,
            "models": models}
