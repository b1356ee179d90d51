"""``hasel steps``: the paper's closed-loop step test through the node graph (simulated time).

Builds the graph (plant, driver, filter, controller, amplifier, reference), runs the
reference sequence in lockstep, and reports per step the 10-90 % rise time, the 5 %
settling time and the overshoot on the true stroke, beside the paper's Table II.
Writes the JSON of ``shared/interfaces.md`` and a PNG plot on request.
"""
from __future__ import annotations

import argparse
import json
import math
import sys
from pathlib import Path

import numpy as np

from hasel import paper
from hasel.errors import BadInputError
from hasel.metrics import reference_starts, steps_from_sequence
from hasel.outputs import replacing, write_text
from hasel.tune import PAPER_GAINS, read_gains

__all__ = ["run", "run_steps", "format_table"]


def run_steps(feedback: str, sequence: list[float], hold_s: float | list[float], *, seed: int = 0,
              plant: str = "nominal",
              calibration_file: str = "", record: str | None = None, quiet: bool = False,
              actuator=None, gains: dict[str, float] | None = None) -> dict:
    """Run the step test; return the JSON dict plus the signals under ``"_signals"``.

    ``hold_s``: how long each reference value is held, s: one for all, or a list with one
    per value (a rig's uneven test, as ``hasel compare`` replays it).

    ``gains``: controller gain parameters (``kp_plus`` ... ``kd_minus``, as
    :func:`hasel.tune.read_gains` returns them); the paper's by default.
    """
    from hasel_sysid.graph import GraphConfig, NodeGraph
    from hasel_sysid.progress import Progress

    duration = float(reference_starts(len(sequence), hold_s)[-1])
    uneven = np.ndim(hold_s) > 0
    cfg = GraphConfig(feedback=feedback, sequence_mm=sequence, hold_s=1.0 if uneven else hold_s,
                      holds_s=[float(h) for h in hold_s] if uneven else None, seed=seed, variant=plant,
                      calibration_file=calibration_file, actuator=actuator, controller_params=dict(gains or {}))
    extra = []
    if record:
        from hasel_sysid.recording import recorder_factory

        extra.append(recorder_factory(record))
    with NodeGraph(cfg, extra_nodes=extra) as g:
        prog = None if quiet else Progress(duration, f"steps ({feedback} feedback)")
        g.run(duration, progress=prog)
        if prog is not None:
            prog.done()
        s = g.collector.samples()
        applied = np.array(g.collector.applied).reshape(-1, 4)
        filtered = np.array(g.collector.filtered).reshape(-1, 2)
    steps = steps_from_sequence(s["t_s"], s["true_stroke_mm"], sequence, hold_s)
    kv = np.concatenate([s["voltage_kv"], applied[:, 2]]) if applied.size else s["voltage_kv"]
    kv = kv[np.isfinite(kv)]
    return {
        "steps": [m.to_json() for m in steps],
        "max_applied_kv": float(kv.max()) if kv.size else 0.0,
        "min_applied_kv": float(kv.min()) if kv.size else 0.0,
        "feedback": feedback, "sequence_mm": sequence, "hold_s": hold_s, "plant": plant, "seed": seed,
        "gains": {**PAPER_GAINS, **(gains or {})},
        "units": {"rise_s": "s", "settling_s": "s", "overshoot_pct": "%", "applied": "kV"},
        "_signals": {**s, "applied_tick": applied, "filtered": filtered},
    }


def format_table(steps: list[dict], feedback: str) -> str:
    """Per-step metrics side by side with the paper's Table II for that feedback."""
    def f(x, fmt="{:.3f}"):
        return "  -  " if x is None or (isinstance(x, float) and math.isnan(x)) else fmt.format(x)

    lines = [f"{'step (mm)':<12}{'mode':<12}{'rise (s)':>10}{'paper':>8}{'settle (s)':>12}{'paper':>8}"
             f"{'overshoot (%)':>15}{'paper':>8}"]
    for s in steps:
        ref = paper.TABLE_II.get((s["mode"], feedback), (None, None, None))
        lines.append(f"{s['from_mm']:g} -> {s['to_mm']:g}".ljust(12) + f"{s['mode']:<12}"
                     f"{f(s['rise_s']):>10}{f(ref[0]):>8}{f(s['settling_s']):>12}{f(ref[1]):>8}"
                     f"{f(s['overshoot_pct'], '{:.1f}'):>15}{f(ref[2], '{:.1f}'):>8}")
    return "\n".join(lines)


def plot_steps(result: dict, path: str) -> None:
    """PNG: reference, true stroke, measured stroke (mm) and applied voltage (kV) against time."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    s = result["_signals"]
    seq, hold = result["sequence_mm"], result["hold_s"]
    t = s["t_s"]
    starts = reference_starts(len(seq), hold)
    ref = np.asarray(seq, float)[np.clip(np.searchsorted(starts, t, side="right") - 1, 0, len(seq) - 1)]
    fig, (ax1, ax2) = plt.subplots(2, 1, sharex=True, figsize=(9, 6), height_ratios=[2, 1])
    ax1.plot(t, ref, "k--", lw=1, label="reference")
    ax1.plot(t, s["true_stroke_mm"], lw=1.5, label="true stroke")
    if result["feedback"] == "laser":
        ax1.plot(t, s["stroke_mm"], lw=0.6, alpha=0.7, label="laser (measured)")
    elif s["filtered"].size:
        ax1.step(s["filtered"][:, 0], s["filtered"][:, 1], where="post", lw=0.8, alpha=0.8,
                 label="strain sensor, 40 Hz filtered (measured)")
    ax1.set_ylabel("stroke (mm)")
    ax1.legend(loc="upper right", fontsize=8)
    ax1.set_title(f"Closed-loop steps, {result['feedback']} feedback ({result['plant']} plant)")
    ax2.plot(t, s["voltage_kv"], color="tab:red", lw=1)
    ax2.axhline(9.0, color="k", lw=0.8, ls=":")
    ax2.set_ylabel("applied (kV)")
    ax2.set_xlabel("time (s)")
    ax2.set_ylim(min(-0.2, s["voltage_kv"].min() - 0.2), 9.5)
    fig.tight_layout()
    with replacing(path) as tmp:
        fig.savefig(tmp, dpi=110)
    plt.close(fig)


def reach_mm(actuator, settle_s: float = 3.0) -> float:
    """Stroke (mm) the actuator model holds after ``settle_s`` s at the 9 kV ceiling."""
    actuator.reset(0.0)
    out = actuator.run(np.full(int(settle_s * actuator.rate_hz), paper.V_MAX_KV))
    actuator.reset(0.0)
    return float(out.stroke_mm[-1])


def run(args: argparse.Namespace) -> int:
    """CLI: ``hasel steps``."""
    try:
        seq = [float(x) for x in str(args.sequence).split(",")]
    except ValueError as err:
        raise BadInputError(f"--sequence must be comma-separated numbers in mm, got {args.sequence!r}") from err
    if len(seq) < 2 or not all(math.isfinite(x) for x in seq):
        raise BadInputError(f"--sequence needs at least two finite values (mm), got {args.sequence!r}")
    if not (math.isfinite(args.hold) and 0.05 <= args.hold <= 3600):
        raise BadInputError(f"--hold must be between 0.05 and 3600 s, got {args.hold}")
    if args.calibration and not Path(args.calibration).is_file():
        raise BadInputError(f"--calibration file not found: {args.calibration}")
    gains = read_gains(args.gains) if getattr(args, "gains", None) else None
    from sim_plant.plant_node import make_actuator

    from hasel.plantfile import looks_like_path

    if looks_like_path(args.plant):  # a plant-model file: the nodes get its absolute path
        args.plant = str(Path(args.plant).resolve())
    reach = reach_mm(make_actuator(args.plant))  # unknown variant or bad file: a clear error before any ROS work
    low = min(seq)
    if low < 0:
        raise BadInputError(f"--sequence: {low:g} mm is below 0 mm, the stroke at 0 kV (the amplifier's floor)")
    high = max(seq)
    if high > reach:
        sys.stderr.write(f"hasel steps: warning: {high:g} mm is beyond the {reach:.1f} mm the {args.plant} plant "
                         f"reaches at the {paper.V_MAX_KV:g} kV ceiling; the loop will saturate at "
                         f"{paper.V_MAX_KV:g} kV there\n")
    res = run_steps(args.feedback, seq, args.hold, seed=args.seed, plant=args.plant,
                    calibration_file=args.calibration or "", record=args.record, gains=gains)
    print(format_table(res["steps"], args.feedback))
    print(f"applied voltage: {res['min_applied_kv']:.3f} .. {res['max_applied_kv']:.3f} kV (ceiling 9 kV)")
    if args.json:
        write_text(args.json, json.dumps({k: v for k, v in res.items() if k != "_signals"}, indent=2))
        print(f"wrote {args.json}")
    if args.plot:
        plot_steps(res, args.plot)
        print(f"wrote {args.plot}")
    if args.record:
        print(f"recorded {args.record}")
    return 0

