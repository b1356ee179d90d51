"""``hasel identify DATA --json MODEL.json [--plot FILE.png] [--report DIR]``.

Loads an input/output log (``.mcap`` or ``.csv``, through :func:`hasel.io.load_io`),
identifies it (:func:`hasel.ident.identify`) and writes MODEL.json, a Bode plot and
a markdown report. Progress goes to stderr, a short summary to stdout.
"""
from __future__ import annotations

import argparse
import json
import sys
import time
from typing import Any

from hasel.errors import BadInputError

__all__ = ["add_arguments", "run"]


def _pair(kind: type, name: str):
    def parse(text: str):
        parts = [p for p in text.replace(" ", "").split(",") if p]
        try:
            vals = tuple(kind(p) for p in parts)
        except ValueError as err:
            raise argparse.ArgumentTypeError(f"{name} must be two numbers A,B, got {text!r}") from err
        if len(vals) != 2:
            raise argparse.ArgumentTypeError(f"{name} must be two numbers A,B, got {text!r}")
        return vals
    return parse


def add_arguments(p: argparse.ArgumentParser) -> None:
    """Options of ``hasel identify``."""
    p.add_argument("data", metavar="DATA", help="the log: .mcap (ROS 2), .csv (header row) or .mat")
    p.add_argument("--json", metavar="MODEL.json", help="write the model: {\"num\", \"den\"} (descending powers "
                   "of s) plus static map, zeros/poles/gain, fit quality, band, dependence verdict")
    p.add_argument("--plot", metavar="FILE.png", help="write a Bode plot of data and fit")
    p.add_argument("--report", metavar="DIR", help="write report.md and figures into DIR")
    p.add_argument("--time", metavar="COL", default=None, help="CSV/MAT time column, s (default t_s)")
    p.add_argument("--input", metavar="COL|/topic.field", default=None,
                   help="input signal: CSV column (default voltage_kv) or MCAP /topic.field "
                   "(default /plant/batch.voltage_kv)")
    p.add_argument("--output", metavar="COL|/topic.field", default=None,
                   help="output signal: CSV column (default stroke_mm) or MCAP /topic.field "
                   "(default /plant/batch.stroke_mm)")
    p.add_argument("--band", metavar="LO,HI", type=_pair(float, "--band"), default=None,
                   help="frequency band analysed and fitted, Hz (default: where the input has power)")
    p.add_argument("--order", metavar="NZ,NP", type=_pair(int, "--order"), default=None,
                   help="fix the numerator and denominator degrees (default: chosen on held-out frequencies)")
    p.add_argument("--max-poles", type=int, default=8, help="highest denominator degree tried (default 8)")
    p.add_argument("--delay", action="store_true", help="also fit an input delay")
    p.add_argument("--holdout", type=float, default=1.0 / 3.0, metavar="FRACTION",
                   help="last part of each operating point held out for validation (default 1/3)")
    p.add_argument("--settle", type=float, default=None, metavar="S",
                   help="time skipped at the start of each operating point, s (default 5 %% of it)")
    p.add_argument("--no-markers", action="store_true",
                   help="ignore the log's segment markers and find the operating points from the input")
    p.add_argument("--paper", action="store_true", help="draw the paper's P(s) in the Bode plot whatever the units")
    p.add_argument("--input-hold", choices=("zoh", "centred"), default="zoh",
                   help="sampling convention of the input: held until the next sample (default) or an "
                        "instantaneous reading")
    p.add_argument("--max-timing-samples", type=float, default=1.5, metavar="N",
                   help="largest timing offset between the input and output samples estimated, raw samples "
                        "(default 1.5; 0 when the loggers' convention is known: no offset is estimated)")


def _write_json(path: str, obj: dict[str, Any]) -> None:
    from hasel.outputs import write_text  # atomic, mode from the umask like every output

    write_text(path, json.dumps(obj, indent=2, allow_nan=False) + "\n")


def _markers(data: Any) -> list[tuple[float, float, float]]:
    """The excitation segments marked in the log (all marked segments if they carry no labels)."""
    ms = list(getattr(data, "marker_segments", ()) or ())
    if ms and any(getattr(m, "label", "") for m in ms):
        return [(m.t_start_s, m.t_end_s, m.offset_kv) for m in ms if m.label == "excitation"]
    return [tuple(s) for s in (getattr(data, "segments", ()) or ())]


def run(args: argparse.Namespace) -> int:
    """Run ``hasel identify``; return the exit code (errors raise :class:`BadInputError`)."""
    from hasel.ident.identify import identify
    from hasel.io import load_io

    t0 = time.perf_counter()

    def say(msg: str) -> None:
        sys.stderr.write(f"hasel identify: {msg} ({time.perf_counter() - t0:.1f} s)\n")
        sys.stderr.flush()

    say(f"loading {args.data}")
    data = load_io(args.data, time=args.time, input=args.input, output=args.output)
    markers = [] if args.no_markers else _markers(data)
    if markers:
        say(f"{len(markers)} marked operating point(s)")
    if args.max_poles < 1:
        raise BadInputError(f"--max-poles must be >= 1, got {args.max_poles}")
    result = identify(data.t_s, data.u, data.y, segments=markers or None, input_name=data.input_name,
                      output_name=data.output_name, progress=say, band_hz=args.band, order=args.order,
                      max_poles=args.max_poles, delay=args.delay, holdout_fraction=args.holdout,
                      settle_s=args.settle, input_hold=args.input_hold,
                      max_timing_samples=args.max_timing_samples)
    result.notes[:0] = list(getattr(data, "notes", ()) or ())
    if args.json:
        _write_json(args.json, result.to_model_json())
        say(f"wrote {args.json}")
    if args.plot:
        from hasel.ident.report import plot_bode

        plot_bode(result, args.plot, paper=True if args.paper else None)
        say(f"wrote {args.plot}")
    if args.report:
        from hasel.ident.report import write_report

        path = write_report(result, args.report)
        say(f"wrote {path}")
    for line in result.summary_lines():
        print(line)
    if not result.usable:
        # the JSON is written (with "usable": false and the reasons); the exit code says not to rely on it
        sys.stderr.write(f"hasel identify: {result.check.one_line()}\n")
        return 1
    return 0
