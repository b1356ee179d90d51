"""``hasel diagnose DATA [--heldout DATA2] [--model MODEL.json] --json VERDICT.json [--export-sim FILE.csv] [--report DIR]``.

Loads the log (``.mcap``, ``.csv`` or ``.mat`` through :func:`hasel.io.load_io`, with
the same ``--time/--input/--output`` options as ``hasel identify``), diagnoses the gap
to the nominal model (:func:`hasel.diagnose.diagnose`) and writes VERDICT.json, the
held-out simulations (``--export-sim``: columns ``t_s, measured, nominal,
augmented``) and a report. A summary goes to stdout; progress (with an estimate of the
whole time) to a status line on stderr when it is a terminal, as lines with ``--progress``
(see :class:`Progress`). ``--jobs`` sets the processes of the candidate fits
(:mod:`hasel.diagnose.pool`).
"""
from __future__ import annotations

import argparse
import json
import math
import sys
import time
from typing import Any

import numpy as np

from hasel.errors import BadInputError
from hasel.outputs import json_safe

__all__ = ["add_arguments", "run", "json_safe", "Progress"]


def add_arguments(p: argparse.ArgumentParser) -> None:
    """Options of ``hasel diagnose``."""
    p.add_argument("data", metavar="DATA", help="the log: .mcap (ROS 2), .csv (header row) or .mat")
    p.add_argument("--heldout", metavar="DATA2", help="a second log of the same system for scoring "
                   "(default: every third of 30 interleaved blocks of DATA is held out)")
    p.add_argument("--model", metavar="MODEL.json", help="the nominal model {\"num\", \"den\"[, \"delay_s\"]} "
                   "(default: identify a linear model from DATA first)")
    p.add_argument("--json", metavar="VERDICT.json", help="write the verdict here")
    p.add_argument("--export-sim", metavar="FILE.csv", help="write t_s, measured, nominal, augmented over "
                   "the held-out data (at the working rate)")
    p.add_argument("--report", metavar="DIR", help="write report.md and figures into DIR")
    p.add_argument("--time", metavar="COL", default=None, help="CSV/MAT time column, s (default t_s), or fs=RATE_HZ")
    p.add_argument("--input", metavar="COL|/topic.field", default=None,
                   help="input signal: CSV column (default voltage_kv) or MCAP /topic.field")
    p.add_argument("--output", metavar="COL|/topic.field", default=None,
                   help="output signal: CSV column (default stroke_mm) or MCAP /topic.field")
    p.add_argument("--identify", choices=("auto", "internal", "ident"), default="auto",
                   help="without --model: hasel.ident if it succeeds (auto), always it (ident), or the "
                   "internal output-error fit (internal)")
    p.add_argument("--rate", type=float, default=None, metavar="HZ",
                   help="working rate, Hz (default: about 25 times the input's band)")
    p.add_argument("--max-effects", type=int, default=3, metavar="N", help="most effects named (default 3)")
    p.add_argument("--export-plant", metavar="FILE.json", help="write the augmented model as a plant-model file")
    p.add_argument("--jobs", type=int, default=None, metavar="N",
                   help="processes for the candidate fits (default: the cores available; 1: serial)")
    p.add_argument("--progress", action="store_true",
                   help="progress as lines on stderr even when it is not a terminal (by default a terminal gets "
                        "one status line, cleared at the end, and a script none: a late error stays alone)")


def _write_atomic(path: str, text: str) -> None:
    from hasel.outputs import write_text  # atomic, mode from the umask like every output

    write_text(path, text)


def _load_model(path: str) -> dict:
    try:
        with open(path) as fh:
            model = json.load(fh)
    except FileNotFoundError as err:
        raise BadInputError(f"no such model file: {path}") from err
    except (OSError, json.JSONDecodeError) as err:
        raise BadInputError(f"cannot read the model {path}: {err}") from err
    if not isinstance(model, dict) or "num" not in model or "den" not in model:
        raise BadInputError(f"{path} is not a MODEL.json: it needs \"num\" and \"den\" lists")
    return model


def _units(data: Any) -> tuple[str, str]:
    try:
        from hasel.ident import unit_from_name

        return unit_from_name(data.input_name) or "", unit_from_name(data.output_name) or ""
    except Exception:  # noqa: BLE001 - units are only labels
        return "", ""


def run(args: argparse.Namespace) -> int:
    """Run ``hasel diagnose``; return the exit code (bad input raises :class:`BadInputError`)."""
    from hasel.diagnose.pool import set_jobs

    if getattr(args, "jobs", None) is not None and args.jobs < 1:
        raise BadInputError(f"--jobs must be >= 1, got {args.jobs}")
    set_jobs(getattr(args, "jobs", None))
    say = Progress(sys.stderr, lines=bool(getattr(args, "progress", False)))
    try:
        return _run(args, say)
    finally:
        say.close()  # the status line goes before anything else is written (an error, the summary)
        set_jobs(None)


class Progress:
    """Where ``hasel diagnose`` says what it is doing (a callable taking one message).

    On a terminal: one status line rewritten in place (the command, the step, the seconds
    so far and the estimate of the whole), cleared by :meth:`close`, so that an error found
    late is the only line left on stderr (the promise of exit code 2) and the summary on
    stdout follows a clean line. ``lines=True`` (``--progress``): every message as its own
    line, terminal or not. Otherwise (a script, a pipe): nothing.
    """

    def __init__(self, stream, lines: bool = False) -> None:
        self.stream, self.t0 = stream, time.perf_counter()
        self.lines = lines
        try:
            self.status = not lines and bool(stream.isatty())
        except (AttributeError, ValueError):
            self.status = False
        self.estimate = ""
        self.shown = False

    def __call__(self, msg: str) -> None:
        """Show ``msg`` (with the seconds since the start)."""
        if msg.startswith("estimate:"):
            self.estimate = "; " + msg.split("(")[0].strip()  # kept on the status line from now on
        seconds = f"{time.perf_counter() - self.t0:.1f} s"
        if self.lines:
            self.stream.write(f"hasel diagnose: {msg} ({seconds})\n")
        elif self.status:
            text = f"hasel diagnose: {msg} ({seconds}{'' if msg.startswith('estimate:') else self.estimate})"
            import shutil

            width = max(20, shutil.get_terminal_size((100, 20)).columns - 1)
            text = text if len(text) <= width else text[:width - 3] + "..."
            self.stream.write("\r" + text + "\033[K")
            self.shown = True
        else:
            return
        self.stream.flush()

    def close(self) -> None:
        """Clear the status line (on a terminal)."""
        if self.shown:
            self.stream.write("\r\033[K")
            self.stream.flush()
            self.shown = False


def _run(args: argparse.Namespace, say: Progress) -> int:
    """``hasel diagnose`` proper, telling its progress to ``say``."""
    from hasel.diagnose.core import DiagnoseOptions, DiagnosisFailed, diagnose
    from hasel.io import load_io
    from hasel.validate import excited

    if args.max_effects < 0:
        raise BadInputError(f"--max-effects must be >= 0, got {args.max_effects}")
    if args.rate is not None and not (math.isfinite(args.rate) and args.rate > 0):
        raise BadInputError(f"--rate must be a positive number of Hz, got {args.rate}")
    model = _load_model(args.model) if args.model else None
    say(f"loading {args.data}")
    data = load_io(args.data, time=args.time, input=args.input, output=args.output)
    held = None
    logs = [data]
    if args.heldout:
        say(f"loading {args.heldout}")
        h = load_io(args.heldout, time=args.time, input=args.input, output=args.output)
        held = (h.t_s, h.u, h.y)
        logs.append(h)
    for d in logs:
        # as identify refuses it: a constant input excites nothing, and every "effect" would be a fit to noise
        excited(f"{d.source}: {d.input_name}", d.u, "diagnose")
        for note in d.notes:
            print(f"note ({d.source.name}): {note}")
    units = _units(data)
    opts = DiagnoseOptions(max_effects=args.max_effects, identify=args.identify, target_rate_hz=args.rate,
                           progress=say)
    try:
        v = diagnose(data.t_s, data.u, data.y, model=model, heldout=held, options=opts, units=units)
    except DiagnosisFailed as err:
        # still write what was measured, marked unusable, then fail with one line (exit 1)
        if args.json:
            _write_atomic(args.json, json.dumps(json_safe(err.payload), indent=2, allow_nan=False) + "\n")
        raise
    out = v.to_json()
    out["signals"] = {"input": data.input_name, "output": data.output_name, "units": list(units),
                      "data": str(args.data), "heldout": str(args.heldout) if args.heldout else None}
    if args.json:
        _write_atomic(args.json, json.dumps(json_safe(out), indent=2, allow_nan=False) + "\n")
        say(f"wrote {args.json}")
    if getattr(args, "export_plant", None):
        from hasel.plantfile import from_verdict, write_plant

        plant = from_verdict(v, units)
        path = write_plant(args.export_plant, plant)
        left = plant.extra.get("not_simulated") or []
        say(f"wrote {path}" + "".join(f" ({e['name']} {', '.join(f'{k} {x:.4g}' for k, x in e['params'].items())} "
                                      f"left out: a timing offset, not physics)" for e in left))
    if args.export_sim:
        ex = v.export
        rows = np.column_stack([ex["t_s"], ex["measured"], ex["nominal"], ex["augmented"]])
        lines = ["t_s,measured,nominal,augmented"] + [",".join(f"{x:.9g}" for x in row) for row in rows]
        _write_atomic(args.export_sim, "\n".join(lines) + "\n")
        say(f"wrote {args.export_sim} ({rows.shape[0]} held-out samples)")
    if args.report:
        from hasel.diagnose.report import write_report

        path = write_report(v, args.report, units)
        say(f"wrote {path}")
    from hasel.diagnose.report import verdict_lines

    say.close()
    for line in verdict_lines(v, units):
        print(line)
    return 0
