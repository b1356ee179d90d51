"""One input/output record for identification, from an MCAP log, a CSV or a MATLAB file.

:func:`load_io` returns an :class:`IOData`: input ``u`` and output ``y`` on one common
time base ``t_s`` (float seconds), checked (finite, strictly increasing time, enough
samples, no gap in the time stamps longer than :data:`MAX_FILL_SAMPLES` samples), plus the experiment's segments when the log has ``ExperimentMarker``
messages. The format is chosen by the file's suffix.

- ``.mcap``: ``input``/``output`` are ``/topic.field`` (default the plant's batched
  10 kHz topic: ``/plant/batch.voltage_kv`` -> ``/plant/batch.stroke_mm``). If the two
  come with different times, the input is interpolated onto the output's times (within
  the span both cover) and a note says so.
- ``.csv``: columns by header name or 0-based index (``time`` default ``t_s``,
  ``input`` ``voltage_kv``, ``output`` ``stroke_mm``).
- ``.mat``: MATLAB v5 variables by name.

For files without a time column, ``time`` may be ``"fs=RATE_HZ"`` or ``"dt=PERIOD_S"``
(uniform sampling from 0 s); a CSV with a ``Ts`` column holding the sample period on
its first row (the nonlinearbenchmark.org layout) gets that automatically when the
default time column is absent.
"""
from __future__ import annotations

import os
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from hasel.errors import BadInputError, DataFileError
from hasel.io.csvload import Table, first_value, read_csv_table, read_mat_table
from hasel.io.loader import MarkerSegment, Segment, load_signals_and_markers, marker_segments

__all__ = ["IOData", "load_io", "DEFAULT_MCAP_INPUT", "DEFAULT_MCAP_OUTPUT", "DEFAULT_TIME", "DEFAULT_INPUT",
           "DEFAULT_OUTPUT", "MIN_SAMPLES", "MAX_FILL_SAMPLES"]

DEFAULT_MCAP_INPUT = "/plant/batch.voltage_kv"
DEFAULT_MCAP_OUTPUT = "/plant/batch.stroke_mm"
DEFAULT_TIME = "t_s"
DEFAULT_INPUT = "voltage_kv"
DEFAULT_OUTPUT = "stroke_mm"
MIN_SAMPLES = 10
#: Longest run of missing samples (a gap in the time stamps) filled by interpolation; longer ones are refused.
MAX_FILL_SAMPLES = 5
_TABLE_SUFFIXES = {".csv", ".txt", ".tsv", ".dat"}


@dataclass(frozen=True)
class IOData:
    """Input and output samples on one time base.

    Attributes
    ----------
    t_s : ndarray, shape (n,)
        Sample times, float seconds, strictly increasing.
    u, y : ndarray, shape (n,)
        Input and output (units of the source: kV and mm for the project's logs).
    input_name, output_name : str
        Where ``u`` and ``y`` came from (``/topic.field``, column or variable name).
    segments : list of Segment
        ``(t_start_s, t_end_s, offset_kv)`` of each marked segment (empty without markers).
    source : Path
        The file.
    notes : tuple of str
        What was done to the data on the way (resampling, a derived time base...).
    marker_segments : tuple of MarkerSegment
        The segments with everything their markers said (label, signal, amplitude...).
    """

    t_s: np.ndarray
    u: np.ndarray
    y: np.ndarray
    input_name: str
    output_name: str
    segments: list[Segment]
    source: Path
    notes: tuple[str, ...] = ()
    marker_segments: tuple[MarkerSegment, ...] = field(default_factory=tuple)

    @property
    def n(self) -> int:
        """Number of samples."""
        return int(self.t_s.size)

    @property
    def sample_rate_hz(self) -> float:
        """Median sample rate, Hz."""
        return float(1.0 / np.median(np.diff(self.t_s)))

    @property
    def duration_s(self) -> float:
        """Time from the first to the last sample, s."""
        return float(self.t_s[-1] - self.t_s[0])


def _uniform_time(spec: str, n: int) -> np.ndarray | None:
    key, eq, value = spec.partition("=")
    if not eq or key.strip().lower() not in ("fs", "dt"):
        return None
    try:
        x = float(value)
    except ValueError:
        raise BadInputError(f"bad time {spec!r}: expected fs=RATE_HZ or dt=PERIOD_S") from None
    if not np.isfinite(x) or x <= 0:
        raise BadInputError(f"bad time {spec!r}: the rate or period must be > 0")
    dt = 1.0 / x if key.strip().lower() == "fs" else x
    return np.arange(n) * dt


def _validate(t: np.ndarray, u: np.ndarray, y: np.ndarray, names: tuple[str, str, str], source: Path,
              min_samples: int, row_offset: int = 0) -> None:
    if u.size != t.size or y.size != t.size:
        raise DataFileError(f"{source}: time, input and output lengths differ ({t.size}, {u.size}, {y.size})")
    if t.size < min_samples:
        raise DataFileError(f"{source}: only {t.size} samples; at least {min_samples} are needed")
    for arr, name in ((t, names[0]), (u, names[1]), (y, names[2])):
        bad = ~np.isfinite(arr)
        if bad.any():
            i = int(np.argmax(bad))
            where = f"sample {i}" + (f" (line {i + row_offset})" if row_offset else "")
            raise DataFileError(f"{source}: {name} has {int(bad.sum())} NaN/inf values, the first at {where}")
    dt = np.diff(t)
    if np.any(dt <= 0):
        i = int(np.argmax(dt <= 0)) + 1
        where = f"sample {i}" + (f" (line {i + row_offset})" if row_offset else "")
        raise DataFileError(f"{source}: time {names[0]} is not strictly increasing at {where}: "
                            f"{t[i - 1]:.9g} then {t[i]:.9g} s")


def _gaps(t: np.ndarray, source: Path) -> str | None:
    """A note on the short gaps in ``t`` (s) that the analyses fill; a long one is refused.

    A gap is a step over 1.5 median steps. Up to :data:`MAX_FILL_SAMPLES` missing samples
    are filled later by linear interpolation onto the uniform grid (a dropped sample or
    two changes no estimate); a longer gap would be a ramp the system never saw, fitted
    as if it had, so it stops the analysis with where it is and what to do.
    """
    dt = np.diff(t)
    step = float(np.median(dt))
    missing = np.rint(dt / step).astype(np.int64) - 1
    gap = dt > 1.5 * step
    if not gap.any():
        return None
    worst = int(np.argmax(np.where(gap, missing, -1)))
    if missing[worst] > MAX_FILL_SAMPLES:
        raise DataFileError(f"{source}: {int(gap.sum())} gap(s) in the time stamps, the longest {dt[worst]:.6g} s "
                            f"({int(missing[worst])} samples of {step:.6g} s missing) after t = {t[worst]:.9g} s; "
                            f"the analyses need continuous samples: split the log at the gap and analyse the parts "
                            f"(one may be --heldout)")
    return (f"{int(gap.sum())} short gap(s) in the time stamps (at most {int(missing[worst])} missing sample(s) of "
            f"{step:.6g} s, {int(missing[gap].sum())} in all) filled by linear interpolation")


def _distinct(in_name: str, out_name: str, source: object) -> None:
    """Refuse an input and an output that are the same signal (a fit of a signal to itself means nothing)."""
    if in_name == out_name:
        raise BadInputError(f"{source}: input and output are the same signal {in_name!r}; "
                            "choose different --input and --output")


def _from_table(table: Table, time: str | None, input: str | None, output: str | None,
                min_samples: int, row_offset: int) -> IOData:
    in_name, u = table.column(input or DEFAULT_INPUT, None if table.label != "column" else "input column")
    out_name, y = table.column(output or DEFAULT_OUTPUT, None if table.label != "column" else "output column")
    _distinct(in_name, out_name, table.source)
    notes: list[str] = []
    tspec = time or DEFAULT_TIME
    t = _uniform_time(tspec, u.size)
    if t is not None:
        t_name = tspec
        notes.append(f"time base {tspec} (uniform sampling from 0 s)")
    elif table.resolve(tspec) is not None:
        t_name, t = table.column(tspec)
    elif time is None and table.label == "column" and (ts_col := table.resolve("Ts") or table.resolve("dt")):
        ts = first_value(table.source, ts_col)
        if ts is None or not np.isfinite(ts) or ts <= 0:
            raise BadInputError(f"{table.source}: no time column {tspec!r}, and {ts_col!r} holds no sample period; "
                                f"{table.describe()}; give --time COL, or --time fs=RATE_HZ / dt=PERIOD_S")
        t = np.arange(u.size) * ts
        t_name = f"dt={ts:g}"
        notes.append(f"no {tspec!r} column: time from the sample period {ts_col} = {ts:g} s on its first row")
    else:
        raise BadInputError(f"{table.source}: no time {table.label} {tspec!r}; {table.describe()}; "
                            "give --time NAME, or --time fs=RATE_HZ / dt=PERIOD_S for uniform sampling")
    _validate(t, u, y, (t_name, in_name, out_name), table.source, min_samples, row_offset)
    notes += [n for n in (_gaps(t, table.source),) if n]
    return IOData(t.astype(float), u.astype(float), y.astype(float), in_name, out_name, [], table.source,
                  tuple(notes))


def _from_mcap(path: Path, time: str | None, input: str | None, output: str | None, min_samples: int) -> IOData:
    in_spec = input or DEFAULT_MCAP_INPUT
    out_spec = output or DEFAULT_MCAP_OUTPUT
    _distinct(in_spec, out_spec, path)
    notes: list[str] = []
    if time is not None:
        notes.append(f"time {time!r} ignored: MCAP times come from header.stamp (or the log time)")
    sigs, markers = load_signals_and_markers(path, [in_spec, out_spec])
    si, so = sigs[in_spec], sigs[out_spec]
    for s, spec in ((si, in_spec), (so, out_spec)):
        if len(s) < min_samples:
            raise DataFileError(f"{path}: {spec} has {len(s)} samples; at least {min_samples} are needed")
        bad = ~np.isfinite(s.values)
        if bad.any():
            i = int(np.argmax(bad))
            raise DataFileError(f"{path}: {spec} has {int(bad.sum())} NaN/inf values, the first at "
                                f"t = {s.t_s[i]:.6f} s")
        dt = np.diff(s.t_s)
        if np.any(dt <= 0):
            i = int(np.argmax(dt <= 0)) + 1
            raise DataFileError(f"{path}: times of {spec} are not strictly increasing at sample {i} "
                                f"(t = {s.t_s[i - 1]:.9f} then {s.t_s[i]:.9f} s)")
    t, y = so.t_s, so.values
    if si.t_s.size == so.t_s.size and np.array_equal(si.t_s, so.t_s):
        u = si.values
    else:
        keep = (t >= si.t_s[0]) & (t <= si.t_s[-1])
        if keep.sum() < min_samples:
            raise DataFileError(f"{path}: {in_spec} ({si.t_s[0]:.3f}-{si.t_s[-1]:.3f} s) and {out_spec} "
                                f"({t[0]:.3f}-{t[-1]:.3f} s) overlap in fewer than {min_samples} samples")
        t, y = t[keep], y[keep]
        u = np.interp(t, si.t_s, si.values)
        rate_in = (len(si) - 1) / max(si.t_s[-1] - si.t_s[0], 1e-300)
        notes.append(f"{in_spec} ({len(si)} samples, {rate_in:.4g} Hz) linearly interpolated onto the "
                     f"{t.size} sample times of {out_spec}")
    _validate(t, u, y, ("time", in_spec, out_spec), path, min_samples)
    notes += [n for n in (_gaps(t, path),) if n]
    msegs = tuple(marker_segments(markers, float(so.t_s[-1]) if so.t_s.size else None))
    return IOData(t, u, y, in_spec, out_spec, [m.as_segment() for m in msegs], path, tuple(notes), msegs)


def load_io(path: str | os.PathLike[str], *, time: str | None = None, input: str | None = None,
            output: str | None = None, min_samples: int = MIN_SAMPLES) -> IOData:
    """Load an input/output record from ``.mcap``, ``.csv`` or ``.mat``.

    Parameters
    ----------
    path : path-like
        The data file; a rosbag2 directory holding exactly one ``.mcap`` also works.
    time : str, optional
        CSV column / MAT variable of the time (s), or ``fs=RATE_HZ`` / ``dt=PERIOD_S``;
        default ``t_s``. Not used for MCAP (times come from the messages).
    input, output : str, optional
        CSV column / MAT variable, or ``/topic.field`` for MCAP; defaults
        ``voltage_kv`` / ``stroke_mm`` and ``/plant/batch.voltage_kv`` /
        ``/plant/batch.stroke_mm``.
    min_samples : int
        Fewest samples accepted.

    Returns
    -------
    IOData

    Raises
    ------
    BadInputError
        Unknown column, variable, topic or field (the message lists what exists).
    DataFileError
        Unreadable or damaged file; NaN/inf values; time not strictly increasing; a gap of more than
        MAX_FILL_SAMPLES missing samples; too
        few samples.
    """
    p = Path(path)
    if p.is_dir():
        found = sorted(p.glob("*.mcap"))
        if len(found) != 1:
            raise DataFileError(f"{p} is a directory with {len(found)} .mcap files; give the file itself")
        p = found[0]
    if not p.exists():
        raise DataFileError(f"no such file: {p}")
    suffix = p.suffix.lower()
    if suffix == ".mcap":
        return _from_mcap(p, time, input, output, min_samples)
    columns = [c for c in (time or DEFAULT_TIME, input or DEFAULT_INPUT, output or DEFAULT_OUTPUT)]
    if suffix in _TABLE_SUFFIXES:
        table = read_csv_table(p, columns)
        return _from_table(table, time, input, output, min_samples, 1 + int(table.has_header))
    if suffix == ".mat":
        return _from_table(read_mat_table(p), time, input, output, min_samples, 0)
    raise BadInputError(f"{p}: unsupported file type {suffix or '(none)'}: expected .mcap, .csv or .mat")
