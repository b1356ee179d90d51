"""A measured closed-loop log against simulated plants: loading, the reference's steps, metrics, NRMSE.

ROS-free half of ``hasel compare`` (the graph runs in :mod:`hasel_sysid.compare`). A
closed-loop log holds the stroke reference (mm), the measured stroke (mm) and the applied
voltage (kV): an MCAP file (``hasel steps --record``, or a rig's with any topics, given
as ``/topic.field``) or a CSV file with a header row.
"""
from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from hasel.errors import BadInputError, DataFileError
from hasel.metrics import StepMetrics, nrmse, steps_from_sequence

__all__ = ["ClosedLoopLog", "load_closed_loop", "reference_steps", "nrmse", "measured_steps", "DEFAULTS"]

#: Default signals: (MCAP field, CSV column) for reference, stroke and voltage.
DEFAULTS = {"reference": ("/reference.stroke_mm", "reference_mm"),
            "stroke": ("/plant/batch.stroke_mm", "stroke_mm"),
            "voltage": ("/plant/batch.voltage_kv", "voltage_kv")}


@dataclass(frozen=True)
class ClosedLoopLog:
    """A measured closed-loop test.

    Attributes
    ----------
    t_s : ndarray
        Sample times of the stroke and voltage, s.
    stroke_mm, voltage_kv : ndarray
        Measured stroke (mm) and applied voltage (kV) at ``t_s``.
    ref_t_s, ref_mm : ndarray
        Times (s) at which the reference took the values ``ref_mm`` (mm).
    source : str
        The file.
    """

    t_s: np.ndarray
    stroke_mm: np.ndarray
    voltage_kv: np.ndarray
    ref_t_s: np.ndarray
    ref_mm: np.ndarray
    source: str


def _finite(path: Path, name: str, t: np.ndarray, v: np.ndarray) -> None:
    if t.size < 2:
        raise DataFileError(f"{path}: {name} has {t.size} samples; at least 2 are needed")
    if not (np.all(np.isfinite(t)) and np.all(np.isfinite(v))):
        raise DataFileError(f"{path}: {name} has NaN/inf values")


def load_closed_loop(path: str | Path, *, time: str | None = None, reference: str | None = None,
                     stroke: str | None = None, voltage: str | None = None) -> ClosedLoopLog:
    """Read a closed-loop log (``.mcap`` or ``.csv``); selectors as in ``hasel identify`` (:data:`DEFAULTS`)."""
    p = Path(path)
    if not p.is_file():
        raise DataFileError(f"no such file: {p}")
    if p.suffix.lower() == ".mcap":
        from hasel.io.loader import load_signals_and_markers

        specs = [reference or DEFAULTS["reference"][0], stroke or DEFAULTS["stroke"][0],
                 voltage or DEFAULTS["voltage"][0]]
        sigs, _ = load_signals_and_markers(p, specs)
        r, y, v = (sigs[s] for s in specs)
        for s, spec in zip((r, y, v), specs):
            _finite(p, spec, s.t_s, s.values)
        t = y.t_s
        u = v.values if np.array_equal(v.t_s, t) else np.interp(t, v.t_s, v.values)
        return ClosedLoopLog(t, y.values, u, r.t_s, r.values, str(p))
    if p.suffix.lower() in (".csv", ".txt", ".tsv"):
        from hasel.io.csvload import read_csv_table

        cols = [time or "t_s", reference or DEFAULTS["reference"][1], stroke or DEFAULTS["stroke"][1],
                voltage or DEFAULTS["voltage"][1]]
        table = read_csv_table(p, cols)
        t, r, y, v = (table.column(c)[1].astype(float) for c in cols)
        _finite(p, "the log", t, np.column_stack([r, y, v]))
        if np.any(np.diff(t) <= 0):
            raise DataFileError(f"{p}: time is not strictly increasing")
        return ClosedLoopLog(t, y, v, t, r, str(p))
    raise BadInputError(f"{p}: unsupported file type {p.suffix or '(none)'}: expected .mcap or .csv")


def reference_steps(log: ClosedLoopLog, tol_s: float = 2e-3) -> tuple[list[float], float | list[float], float]:
    """``(sequence_mm, hold_s, t0_s)``: the reference's values, how long each is held (s) and its start (s).

    When the reference changes at evenly spaced times (as ``hasel steps`` makes it; within
    ``tol_s``) ``hold_s`` is that one hold and the last value is held as long as the
    others; otherwise (a rig's test) it is one hold per value, the last one running to
    the end of the log but no longer than the longest of the others.
    """
    t, r = np.asarray(log.ref_t_s, float), np.asarray(log.ref_mm, float)
    keep = np.concatenate([[True], np.diff(r) != 0])
    times, values = t[keep], r[keep]
    if values.size < 2:
        raise BadInputError(f"{log.source}: the reference never changes ({values.size} value); nothing to compare")
    holds = np.diff(times)
    tail = float(log.t_s[-1]) - float(times[-1])
    hold = float(np.median(holds))
    even = np.max(np.abs(holds - hold)) <= tol_s
    need = hold if even else float(np.min(holds))
    if tail < 0.5 * need:
        raise BadInputError(f"{log.source}: the log ends {tail:.3f} s after the last reference change; "
                            f"it needs about {need:.3f} s to show that step")
    if even:
        return [float(v) for v in values], hold, float(times[0])
    return [float(v) for v in values], [float(h) for h in holds] + [min(tail, float(np.max(holds)))], float(times[0])


def measured_steps(log: ClosedLoopLog, sequence: list[float], hold_s: float | list[float],
                   t0_s: float) -> list[StepMetrics]:
    """Per-step rise, settling and overshoot of the measured stroke (times from each step; holds
    in s as :func:`reference_steps` gives them)."""
    return steps_from_sequence(log.t_s - t0_s, log.stroke_mm, sequence, hold_s)


def on_log_times(log: ClosedLoopLog, t0_s: float, duration_s: float, t_sim: np.ndarray,
                 y_sim: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``(measured, simulated)`` over the replayed span, the simulation interpolated onto the log's times."""
    tl = log.t_s - t0_s
    sel = (tl >= max(0.0, float(t_sim[0]))) & (tl <= min(duration_s, float(t_sim[-1])))
    return sel, np.interp(tl[sel], t_sim, y_sim)
