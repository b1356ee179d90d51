"""``hasel demo``: the toolkit's story end to end, on the simulator.

1. Calibrate the strain sensor against the laser (paper: 2-7 mm in 1 mm steps).
2. Closed-loop steps 2 -> 4 -> 6 -> 4 -> 2 mm with laser and with strain-sensor
   feedback through the node graph, beside the paper's Table II.
3. The paper's identification experiment (chirps on six DC offsets, recorded to
   MCAP) and the transfer-function fit from that log, against the paper's P(s).
4. (when available) the sim-to-real gap diagnosis.

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
    _section("3. identification: the paper's chirp protocol, recorded, then identified from the log")
    summary["identification"] = _identify_stage(out, args.quick)

    (out / "summary.json").write_text(json.dumps(summary, indent=2))
    _section("done")
    print(f"files in {out}/: calibration.yaml, steps_*.{{json,png}}, chirp.mcap, model.json, bode.png, "
          "identify/report.md, summary.json")
    return 0


def _identify_stage(out: Path, quick: bool) -> dict:
    """Chirp campaign through the graph (recorded), then ``identify`` on the MCAP."""
    import numpy as np

    from hasel import paper
    from hasel.errors import HaselError
    from hasel.lti import tf_freqresp
    from hasel.signals import protocol_schedule
    from hasel_sysid.chirp import run_chirp

    offsets = [3.0, 5.0] if quick else list(paper.CHIRP_PROTOCOL["offsets_kv"])
    sched = protocol_schedule(offsets)
    log = out / "chirp.mcap"
    res = run_chirp(sched, str(log), quiet=True)
    print(f"recorded {len(offsets)} operating points x 3 chirps (paper formula), {res['simulated_s']:.0f} s "
          f"simulated at 10 kHz in {res['wall_s'] or 0:.1f} s -> {log}")
    from hasel.cli import main as hasel_main

    print(f"$ hasel identify {log} --json {out / 'model.json'} --plot {out / 'bode.png'} --report {out / 'identify'}")
    if hasel_main(["identify", str(log), "--json", str(out / "model.json"), "--plot", str(out / "bode.png"),
                   "--report", str(out / "identify")]) != 0:
        raise HaselError("identification of the demo's own log failed")
    model = json.loads((out / "model.json").read_text())
    f = np.geomspace(0.1, 15.0, 200)
    ratio = tf_freqresp(model["num"], model["den"], f) / tf_freqresp(*paper.plant_tf(), f)
    db, deg = float(np.max(np.abs(20 * np.log10(np.abs(ratio))))), float(np.max(np.abs(np.angle(ratio, deg=True))))
    print(f"against the paper's P(s), 0.1-15 Hz: worst {db:.3f} dB, {deg:.2f} deg (target 1 dB, 5 deg)")
    return {"num": model["num"], "den": model["den"], "worst_db": db, "worst_deg": deg}
