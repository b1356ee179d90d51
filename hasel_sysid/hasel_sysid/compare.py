"""``hasel compare LOG --plant A [--plant B ...] [--json F] [--plot F.png]``.

Replays the reference of a measured closed-loop log through the node graph in simulated
time, once per plant (``nominal``, ``truth...`` or a plant-model file), and prints per
step the rise, settling and overshoot measured beside each plant's, with the stroke and
applied-voltage NRMSE of each plant against the measurement.
"""
from __future__ import annotations

import argparse
import json
import math
from pathlib import Path


from hasel.compare import (DEFAULTS, ClosedLoopLog, load_closed_loop, measured_steps, nrmse, on_log_times,
                           reference_steps)
from hasel.errors import BadInputError
from hasel.metrics import reference_starts
from hasel.outputs import replacing, write_text
from hasel.tune import PAPER_GAINS, read_gains

__all__ = ["add_arguments", "run", "compare"]


def add_arguments(p: argparse.ArgumentParser) -> None:
    """Options of ``hasel compare``."""
    p.add_argument("log", metavar="LOG", help="measured closed-loop log: .mcap or .csv (header row)")
    p.add_argument("--plant", action="append", required=True, metavar="PLANT",
                   help="nominal | truth | truth:EFFECT(p=v)+... | a plant-model file; repeat for more")
    p.add_argument("--feedback", choices=["laser", "strain"], default="laser", help="feedback sensor (default laser)")
    p.add_argument("--seed", type=int, default=0, help="noise seed of the simulated sensors (default 0)")
    p.add_argument("--gains", default=None, metavar="GAINS.yaml",
                   help="controller gains of the replay (parameter file, hasel tune; default the paper's)")
    p.add_argument("--time", metavar="COL", default=None, help="CSV time column, s (default t_s)")
    p.add_argument("--reference", metavar="COL|/topic.field", default=None,
                   help=f"reference, mm (default {DEFAULTS['reference'][1]} or {DEFAULTS['reference'][0]})")
    p.add_argument("--stroke", metavar="COL|/topic.field", default=None,
                   help=f"measured stroke, mm (default {DEFAULTS['stroke'][1]} or {DEFAULTS['stroke'][0]})")
    p.add_argument("--voltage", metavar="COL|/topic.field", default=None,
                   help=f"applied voltage, kV (default {DEFAULTS['voltage'][1]} or {DEFAULTS['voltage'][0]})")
    p.add_argument("--json", metavar="FILE", default=None, help="write the comparison as JSON")
    p.add_argument("--plot", metavar="FILE.png", default=None, help="write an overlay plot")


def compare(log: ClosedLoopLog, plants: list[str], *, feedback: str = "laser", seed: int = 0,
            quiet: bool = True, gains: dict[str, float] | None = None) -> dict:
    """The comparison of ``log`` with each plant (JSON-ready, plus ``"_signals"`` for plots).

    ``gains``: the controller's gain parameters for the replay (the paper's by default);
    they should be the gains the log was measured with.
    """
    from hasel_sysid.steps import run_steps

    seq, hold, t0 = reference_steps(log)
    duration = float(reference_starts(len(seq), hold)[-1])
    out: dict = {"log": log.source, "sequence_mm": seq, "hold_s": hold, "feedback": feedback, "seed": seed,
                 "gains": {**PAPER_GAINS, **(gains or {})},
                 "measured": {"steps": [m.to_json() for m in measured_steps(log, seq, hold, t0)]},
                 "plants": [], "_signals": {"measured": (log.t_s - t0, log.stroke_mm, log.voltage_kv)}}
    for plant in plants:
        res = run_steps(feedback, seq, hold, seed=seed, plant=plant, quiet=quiet, gains=gains)
        s = res["_signals"]
        sel, y_sim = on_log_times(log, t0, duration, s["t_s"], s["true_stroke_mm"])
        _, v_sim = on_log_times(log, t0, duration, s["t_s"], s["voltage_kv"])
        out["plants"].append({"plant": plant, "stroke_nrmse": nrmse(log.stroke_mm[sel], y_sim),
                              "voltage_nrmse": nrmse(log.voltage_kv[sel], v_sim), "steps": res["steps"],
                              "max_applied_kv": res["max_applied_kv"]})
        out["_signals"][plant] = (s["t_s"], s["true_stroke_mm"], s["voltage_kv"])
    return out


def format_table(result: dict) -> str:
    """Per-step metrics, measured beside each plant ([1], [2], ...), then the NRMSEs."""
    def f(x, fmt: str) -> str:
        return "-" if x is None or (isinstance(x, float) and math.isnan(x)) else fmt.format(x)

    plants = result["plants"]
    lines = [f"[{i + 1}] {p['plant']}" for i, p in enumerate(plants)]
    lines.append(f"{'step (mm)':<12}{'mode':<12}{'':<10}{'measured':>10}"
                 + "".join(f"{f'[{i + 1}]':>10}" for i in range(len(plants))))
    for i, m in enumerate(result["measured"]["steps"]):
        label, mode = f"{m['from_mm']:g} -> {m['to_mm']:g}", m["mode"]
        for key, unit, fmt in (("rise_s", "rise s", "{:.3f}"), ("settling_s", "settle s", "{:.3f}"),
                               ("overshoot_pct", "over %", "{:.1f}")):
            vals = [m[key]] + [p["steps"][i][key] for p in plants]
            lines.append(f"{label:<12}{mode:<12}{unit:<10}" + "".join(f"{f(v, fmt):>10}" for v in vals))
            label = mode = ""
    for i, p in enumerate(plants):
        lines.append(f"[{i + 1}] stroke NRMSE {p['stroke_nrmse']:.4f}, applied-voltage NRMSE {p['voltage_nrmse']:.4f}")
    return "\n".join(lines)


def plot_compare(result: dict, path: str) -> None:
    """PNG: measured and simulated stroke (mm) and applied voltage (kV) against time."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, (ax1, ax2) = plt.subplots(2, 1, sharex=True, figsize=(10, 6))
    sig = result["_signals"]
    t, y, v = sig["measured"]
    ax1.plot(t, y, "k", lw=1.2, label="measured")
    ax2.plot(t, v, "k", lw=1.2, label="measured")
    for p in result["plants"]:
        ts, ys, vs = sig[p["plant"]]
        lab = f"{Path(p['plant']).name} (NRMSE {p['stroke_nrmse']:.3f})"
        ax1.plot(ts, ys, lw=0.9, label=lab)
        ax2.plot(ts, vs, lw=0.9, label=f"{Path(p['plant']).name} (NRMSE {p['voltage_nrmse']:.3f})")
    ax1.set_ylabel("stroke (mm)")
    ax2.set_ylabel("applied (kV)")
    ax2.set_xlabel("time from the first reference (s)")
    ax1.legend(fontsize=8)
    ax2.legend(fontsize=8)
    ax1.set_title(f"Measured closed loop against simulated plants ({result['feedback']} feedback)")
    fig.tight_layout()
    with replacing(path) as tmp:
        fig.savefig(tmp, dpi=110, format="png")
    plt.close(fig)


def run(args: argparse.Namespace) -> int:
    """CLI: ``hasel compare``."""
    from hasel.plantfile import looks_like_path
    from hasel.plantspec import make_actuator

    plants = []
    for plant in args.plant:
        if looks_like_path(plant):
            plant = str(Path(plant).resolve())
        make_actuator(plant)  # a bad plant: one line before any ROS work
        plants.append(plant)
    if not 0 <= args.seed < 2**31:
        raise BadInputError(f"--seed must be within 0 .. 2^31-1, got {args.seed}")
    gains = read_gains(args.gains) if args.gains else None
    log = load_closed_loop(args.log, time=args.time, reference=args.reference, stroke=args.stroke,
                           voltage=args.voltage)
    res = compare(log, plants, feedback=args.feedback, seed=args.seed, gains=gains)
    print(format_table(res))
    if args.json:
        write_text(args.json, json.dumps({k: v for k, v in res.items() if k != "_signals"}, indent=2) + "\n")
        print(f"wrote {args.json}")
    if args.plot:
        plot_compare(res, args.plot)
        print(f"wrote {args.plot}")
    return 0
