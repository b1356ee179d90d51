"""Split a log into operating points (DC offsets of the input).

A campaign log holds several operating points one after another, often with
pre-conditioning holds between them (the paper's -1 kV charge reversal). The input's
local level is followed with block means, changes of level are found where the
means of two adjacent windows differ by more than a threshold, and the pieces
between changes are kept if they carry excitation and are long enough. The start
of each kept piece (``settle_s``) is skipped: it holds the transient of the step to
the new offset. Explicit markers ``(t_start_s, t_end_s, offset)``, e.g. from MCAP
annotations, replace the detection.
"""
from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from scipy import signal

from hasel.errors import BadInputError
from hasel.metrics import robust_sd
from hasel.validate import finite

__all__ = ["Segment", "SkippedPart", "SegmentSearch", "find_segments", "segments_from_markers",
           "DEFAULT_SETTLE_FRACTION"]

#: Default part of each segment skipped at its start (step transient), as a fraction of its length.
DEFAULT_SETTLE_FRACTION = 0.05


@dataclass(frozen=True)
class Segment:
    """One operating point: samples ``i0 <= i < i1`` of the log.

    Attributes
    ----------
    i0, i1 : int
        Sample range used (after skipping the settling part).
    start_s, end_s : float
        Times of samples ``i0`` and ``i1 - 1``, s.
    offset : float
        The operating point's DC input level (the marker's value, or the detected
        median level), input unit.
    source : str
        ``"marker"`` or ``"detected"``.
    settle_s : float
        Time skipped at the start of the piece, s.
    """

    i0: int
    i1: int
    start_s: float
    end_s: float
    offset: float
    source: str
    settle_s: float

    @property
    def duration_s(self) -> float:
        """Length of the used part, s."""
        return self.end_s - self.start_s


@dataclass(frozen=True)
class SkippedPart:
    """A piece of the log that is not an operating point, and why."""

    start_s: float
    end_s: float
    level: float
    reason: str


@dataclass(frozen=True)
class SegmentSearch:
    """Result of :func:`find_segments`: kept segments, skipped pieces and the detection settings."""

    segments: list[Segment]
    skipped: list[SkippedPart]
    window_s: float
    min_step: float


def _settle(duration_s: float, settle_s: float | None) -> float:
    if settle_s is None:
        return DEFAULT_SETTLE_FRACTION * duration_s
    s = finite("settle_s", settle_s)
    if s < 0:
        raise BadInputError(f"settle_s must be >= 0, got {s}")
    return s


def _rate(t_s: np.ndarray) -> float:
    dt = np.diff(t_s)
    return 1.0 / float(np.median(dt))


def segments_from_markers(t_s: np.ndarray, markers: Sequence[tuple[float, float, float]], *,
                          settle_s: float | None = None) -> list[Segment]:
    """Segments from explicit markers ``(t_start_s, t_end_s, offset)``.

    Parameters
    ----------
    t_s : ndarray, shape (n,)
        Sample times of the log, s, increasing.
    markers : sequence of (float, float, float)
        Start and end times (s) and nominal offset (input unit) of each operating point.
    settle_s : float, optional
        Time skipped at the start of each marker, s (default 5 % of its length).

    Returns
    -------
    list of Segment
        In the order of the markers.

    Raises
    ------
    BadInputError
        If a marker is malformed or holds fewer than two samples of the log.
    """
    t = np.asarray(t_s, float)
    out: list[Segment] = []
    for j, mk in enumerate(markers):
        try:
            t0, t1, off = (float(v) for v in mk)
        except (TypeError, ValueError) as err:
            raise BadInputError(f"segment marker {j} must be (t_start_s, t_end_s, offset), got {mk!r}") from err
        if not (np.isfinite(t0) and np.isfinite(t1) and np.isfinite(off)) or t1 <= t0:
            raise BadInputError(f"segment marker {j} must have finite values and t_end_s > t_start_s, got {mk!r}")
        skip = _settle(t1 - t0, settle_s)
        i0 = int(np.searchsorted(t, t0 + skip, side="left"))
        i1 = int(np.searchsorted(t, t1, side="left"))
        if i1 - i0 < 2:
            raise BadInputError(f"segment marker {j} ({t0:g}-{t1:g} s) holds fewer than two samples of the log "
                                f"(which spans {t[0]:g}-{t[-1]:g} s)")
        out.append(Segment(i0, i1, float(t[i0]), float(t[i1 - 1]), off, "marker", skip))
    return out


def find_segments(t_s: np.ndarray, u: np.ndarray, *, window_s: float | None = None,
                  min_step: float | None = None, min_duration_s: float | None = None,
                  settle_s: float | None = None, rel_excitation: float = 0.1) -> SegmentSearch:
    """Find the operating points of a log from the level of its input.

    Parameters
    ----------
    t_s : ndarray, shape (n,)
        Sample times, s, increasing and (nearly) equally spaced.
    u : ndarray, shape (n,)
        Input samples (any unit).
    window_s : float, optional
        Length of the two windows compared for a change of level, s (default
        ``min(2, duration / 40)``). It should be longer than the slowest
        oscillation of the excitation.
    min_step : float, optional
        Smallest change of level that separates operating points, input unit
        (default: the larger of 6 robust standard deviations of the window
        difference and 5 % of the largest change).
    min_duration_s : float, optional
        Shortest operating point kept, s (default ``4 * window_s``).
    settle_s : float, optional
        Time skipped at the start of each operating point, s (default 5 % of it).
    rel_excitation : float
        A piece whose input RMS about its level is below this fraction of the
        largest one is a hold without excitation (pre-conditioning) and is skipped.

    Returns
    -------
    SegmentSearch
    """
    t = np.asarray(t_s, float)
    x = np.asarray(u, float)
    n = x.size
    if n < 16:
        raise BadInputError(f"need at least 16 samples to find operating points, got {n}")
    rate = _rate(t)
    duration = float(t[-1] - t[0])
    window_s = min(2.0, duration / 40.0) if window_s is None else finite("window_s", window_s)
    # blocks: a few thousand over the log, at least one sample
    B = max(1, n // 8000)
    nb = n // B
    xb = x[: nb * B].reshape(nb, B)
    m = xb.mean(axis=1)
    m2 = (xb * xb).mean(axis=1)
    block_s = B / rate
    W = max(1, int(round(window_s / block_s)))
    if 2 * W >= nb:
        W = max(1, nb // 4)
    c = np.concatenate([[0.0], np.cumsum(m)])
    b = np.arange(W, nb - W + 1)
    d = (c[b + W] - c[b]) / W - (c[b] - c[b - W]) / W if b.size else np.zeros(0)
    if d.size == 0:
        change_blocks: list[int] = []
        min_step_v = float("inf") if min_step is None else float(min_step)
    else:
        ad = np.abs(d)
        sig = robust_sd(d)
        min_step_v = (max(6.0 * sig, 0.05 * float(ad.max())) if min_step is None
                      else finite("min_step", min_step))
        # every peak of |d| above the threshold: two steps closer than two windows (a short
        # hold between operating points) give two peaks
        peaks, _ = signal.find_peaks(np.concatenate([[0.0], ad, [0.0]]), height=min_step_v,
                                     distance=max(1, W // 2))
        change_blocks = [int(b[p - 1]) for p in peaks]
    bounds = [0] + change_blocks + [nb]

    def stats(b0: int, b1: int) -> tuple[float, float]:
        inner = slice(b0 + min(W, (b1 - b0) // 4), b1 - min(W, (b1 - b0) // 4))
        level = float(np.median(m[inner])) if inner.stop > inner.start else float(np.mean(m[b0:b1]))
        mean = float(np.mean(m[inner])) if inner.stop > inner.start else float(np.mean(m[b0:b1]))
        msq = float(np.mean(m2[inner])) if inner.stop > inner.start else float(np.mean(m2[b0:b1]))
        return level, float(np.sqrt(max(msq - mean * mean, 0.0)))

    pieces = [(bounds[i], bounds[i + 1]) for i in range(len(bounds) - 1) if bounds[i + 1] > bounds[i]]
    # merge neighbours at the same level (spurious changes inside an excitation)
    merged = True
    while merged and len(pieces) > 1:
        merged = False
        levels = [stats(p0, p1)[0] for p0, p1 in pieces]
        for i in range(len(pieces) - 1):
            if abs(levels[i + 1] - levels[i]) < min_step_v:
                pieces[i:i + 2] = [(pieces[i][0], pieces[i + 1][1])]
                merged = True
                break
    min_dur = 4.0 * window_s if min_duration_s is None else finite("min_duration_s", min_duration_s)
    # a short piece next to a long excited one, within that one's swing, is its slow start or
    # end (a sweep from a very low frequency), not an operating point of its own
    merged = True
    while merged and len(pieces) > 1:
        merged = False
        info = [stats(p0, p1) for p0, p1 in pieces]
        long_ = [(p1 - p0) * block_s >= min_dur for p0, p1 in pieces]
        for i in range(len(pieces)):
            if long_[i]:
                continue
            for j in (i + 1, i - 1):
                if 0 <= j < len(pieces) and long_[j] and info[j][1] > 0 and \
                        abs(info[i][0] - info[j][0]) <= 2.0 * info[j][1] and info[i][1] > 0.1 * info[j][1]:
                    a, b = sorted((i, j))
                    pieces[a:b + 1] = [(pieces[a][0], pieces[b][1])]
                    merged = True
                    break
            if merged:
                break
    info = [stats(p0, p1) for p0, p1 in pieces]
    rms_max = max((r for _, r in info), default=0.0)
    margin = 2 if len(pieces) > 1 else 0
    segments: list[Segment] = []
    skipped: list[SkippedPart] = []
    for (p0, p1), (level, rms) in zip(pieces, info):
        i0 = p0 * B + (margin * B if p0 > 0 else 0)
        i1 = (p1 * B - (margin * B if p1 < nb else 0)) if p1 < nb else n
        t0, t1 = float(t[i0]), float(t[max(i1 - 1, i0)])
        if rms <= rel_excitation * rms_max or rms_max <= 0.0:
            skipped.append(SkippedPart(t0, t1, level, "no excitation (a hold)"))
            continue
        if t1 - t0 < min_dur:
            skipped.append(SkippedPart(t0, t1, level, f"shorter than {min_dur:g} s"))
            continue
        skip = _settle(t1 - t0, settle_s)
        j0 = int(np.searchsorted(t, t0 + skip, side="left"))
        if i1 - j0 < 16:
            skipped.append(SkippedPart(t0, t1, level, "nothing left after the settling time"))
            continue
        segments.append(Segment(j0, i1, float(t[j0]), float(t[i1 - 1]), level, "detected", skip))
    return SegmentSearch(segments=segments, skipped=skipped, window_s=window_s, min_step=min_step_v)
