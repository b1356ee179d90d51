"""``hasel demo``: the toolkit's story end to end, on the simulator.

1. Calibrate the strain sensor against the laser (paper: 2-7 mm in 1 mm steps).
2. Closed-loop steps 2 -> 4 -> 6 -> 4 -> 2 mm with laser and with strain-sensor
   feedback through the node graph, beside the paper's Table II.
3. (when available) the chirp identification and the sim-to-real gap diagnosis.

Everything is written under ``--out`` (default ``out/demo``).
"""
from __future__ import annotations

import argparse
import json
from pathlib import Path

__all__ = ["run"]


def _section(title: str) -> None:
    print(f"\n== {title} " + "=" * max(0, 70 - len(title)))


def run(args: argparse.Namespace) -> int:
    """Run the demo; returns the exit code."""
    from hasel_sysid.calibrate import calibrate
    from hasel_sysid.steps import format_table, plot_steps, run_steps

    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    hold = 0.5 if args.quick else 1.0

    _section("1. strain-sensor calibration against the laser (2-7 mm)")
    fit = calibrate([2, 3, 4, 5, 6, 7], hold, quiet=True)
    cal_path = out / "calibration.yaml"
    fit.calibration.to_yaml(cal_path, {"max_error_pct": fit.max_error_pct})
    c = fit.calibration.coeffs
    print(f"stroke_mm = {c[0]:.5f} * elapsed_us {c[1]:+.4f}; largest error {fit.max_error_pct:.3f} % -> {cal_path}")

    summary = {"calibration": {"coeffs": list(c), "max_error_pct": fit.max_error_pct}}
    for fb in ("laser", "strain"):
        _section(f"2. closed-loop steps, {fb} feedback (node graph, simulated time)")
        res = run_steps(fb, [2.0, 4.0, 6.0, 4.0, 2.0], hold, calibration_file=str(cal_path) if fb == "strain" else "",
                        quiet=True)
        print(format_table(res["steps"], fb))
        print(f"applied voltage {res['min_applied_kv']:.2f} .. {res['max_applied_kv']:.2f} kV (ceiling 9 kV)")
        (out / f"steps_{fb}.json").write_text(json.dumps({k: v for k, v in res.items() if k != "_signals"}, indent=2))
        plot_steps(res, str(out / f"steps_{fb}.png"))
        summary[f"steps_{fb}"] = res["steps"]
    (out / "summary.json").write_text(json.dumps(summary, indent=2))
    _section("done")
    print(f"files in {out}/: calibration.yaml, steps_laser.{{json,png}}, steps_strain.{{json,png}}, summary.json")
    return 0
