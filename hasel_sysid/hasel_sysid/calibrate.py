"""``hasel calibrate``: the paper's strain-sensor calibration against the laser.

The loop (on laser feedback, the ground truth) holds the actuator at 2, 3, ... 7 mm;
at each hold the mean 555 elapsed time and the mean laser stroke are taken over the
settled second half; a line of best fit (or a low-order polynomial) maps one to the
other. Prints the residual at each point and writes the YAML the driver node loads.
"""
from __future__ import annotations

import argparse
import math
from pathlib import Path

import numpy as np

from hasel.calibration import CalibrationFit, fit_calibration
from hasel.errors import BadInputError
from hasel.outputs import replacing

__all__ = ["run", "calibrate"]


def calibrate(points_mm: list[float], hold_s: float, *, degree: int = 1, seed: int = 0, plant: str = "nominal",
              actuator=None, quiet: bool = False) -> CalibrationFit:
    """Hold each point (mm) for ``hold_s`` s under laser feedback; fit elapsed time -> laser stroke."""
    from hasel_sysid.graph import GraphConfig, NodeGraph
    from hasel_sysid.progress import Progress

    cfg = GraphConfig(feedback="laser", sequence_mm=points_mm, hold_s=hold_s, seed=seed, variant=plant,
                      actuator=actuator)
    with NodeGraph(cfg) as g:
        prog = None if quiet else Progress(hold_s * len(points_mm), "calibrate")
        g.run(hold_s * len(points_mm), progress=prog)
        if prog is not None:
            prog.done()
        s = g.collector.samples()
    elapsed, laser = [], []
    for i in range(len(points_mm)):
        sel = (s["t_s"] >= (i + 0.5) * hold_s) & (s["t_s"] < (i + 1) * hold_s)
        elapsed.append(float(np.mean(s["elapsed_us"][sel])))
        laser.append(float(np.mean(s["stroke_mm"][sel])))
    return fit_calibration(np.array(elapsed), np.array(laser), degree)


def run(args: argparse.Namespace) -> int:
    """CLI: ``hasel calibrate``."""
    try:
        points = [float(x) for x in str(args.points).split(",")]
    except ValueError as err:
        raise BadInputError(f"--points must be comma-separated strokes in mm, got {args.points!r}") from err
    if len(points) < args.degree + 1 or not all(math.isfinite(p) and 0 < p < 12 for p in points):
        raise BadInputError(f"--points needs at least {args.degree + 1} strokes in (0, 12) mm, got {args.points!r}")
    if not 0.2 <= args.hold <= 600:
        raise BadInputError(f"--hold must be between 0.2 and 600 s, got {args.hold}")
    fit = calibrate(points, args.hold, degree=args.degree, seed=args.seed, plant=args.plant)
    cal = fit.calibration
    print(f"{'target (mm)':>12}{'elapsed (us)':>14}{'laser (mm)':>12}{'fit (mm)':>10}{'residual (mm)':>15}{'error (%)':>11}")
    for p, x, y, r in zip(points, fit.elapsed_us, fit.laser_mm, fit.residual_mm):
        print(f"{p:>12.2f}{x:>14.4f}{y:>12.4f}{y - r:>10.4f}{r:>15.4f}{100 * abs(r) / abs(y):>11.2f}")
    if len(cal.coeffs) == 2:
        print(f"line of best fit: stroke_mm = {cal.coeffs[0]:.6f} * elapsed_us {cal.coeffs[1]:+.4f}")
    else:
        print(f"polynomial (descending powers of elapsed_us): {list(cal.coeffs)}")
    print(f"largest error: {fit.max_error_pct:.2f} % (paper: < 5 %)")
    out = Path(args.out)
    with replacing(out) as tmp:
        cal.to_yaml(tmp, {"points_mm": points, "elapsed_us": fit.elapsed_us.tolist(),
                          "laser_mm": fit.laser_mm.tolist(), "residual_mm": fit.residual_mm.tolist(),
                          "max_error_pct": fit.max_error_pct, "hold_s": args.hold, "plant": args.plant})
    print(f"wrote {out} (load it with: hasel steps --feedback strain --calibration {out})")
    return 0
