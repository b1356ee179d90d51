"""How well a response does: step metrics as in the paper's Table II (10-90 % rise, 5 %
settling, overshoot) and the normalised error of a simulation against a measurement."""
from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import asdict, dataclass

import numpy as np

from hasel.errors import BadInputError

__all__ = ["StepMetrics", "step_metrics", "steps_from_sequence", "reference_starts", "nrmse", "robust_sd"]

#: the median absolute deviation of a normal variable times this is its standard deviation
MAD_TO_SD = 1.4826


def robust_sd(x: np.ndarray) -> float:
    """Standard deviation of ``x`` (its unit) from the median absolute deviation about the median:
    ``1.4826 * median(|x - median(x)|)``, which outliers (steps, switches, spikes) barely move."""
    x = np.asarray(x, dtype=float)
    return float(MAD_TO_SD * np.median(np.abs(x - np.median(x))))


def nrmse(y: np.ndarray, y_hat: np.ndarray, *, bias_free: bool = False) -> float:
    """Normalised root-mean-square error ``||y - y_hat|| / ||y - mean(y)||`` (0 is perfect).

    The one definition of the toolkit (identification, diagnosis, closed-loop
    comparison): the error is normalised by the measured signal's spread about its
    mean (its standard deviation times sqrt(n)), never by its range; 1 is as good as
    predicting the mean, and MATLAB's ``compare`` fit is ``100 (1 - NRMSE)`` %.

    Parameters
    ----------
    y, y_hat : ndarray, shape (n,)
        Measured and simulated signal, same unit.
    bias_free : bool
        Remove the error's mean first: the error the simulation would have with the
        best constant offset added (a model judged on its dynamics, not its level).

    Returns
    -------
    float
        ``inf`` for a constant ``y`` (nothing to normalise by).

    Raises
    ------
    BadInputError
        If the two are not non-empty 1-D arrays of one length.
    """
    y = np.asarray(y, float)
    y_hat = np.asarray(y_hat, float)
    if y.shape != y_hat.shape or y.ndim != 1 or y.size == 0:
        raise BadInputError(f"y and y_hat must be non-empty 1-D arrays of one length, got {y.shape}, {y_hat.shape}")
    d0, d1 = y - y.mean(), y - y_hat
    if bias_free:
        d1 = d1 - d1.mean()
    # einsum, not dot/norm: no BLAS threads to wake for a long 1-D product
    den = float(np.sqrt(np.einsum("i,i->", d0, d0)))
    return float(np.sqrt(np.einsum("i,i->", d1, d1))) / den if den > 0 else math.inf


@dataclass(frozen=True)
class StepMetrics:
    """Metrics of one reference step. Times in seconds from the step's time; NaN if not reached."""

    from_mm: float
    to_mm: float
    mode: str  # "activation" (increasing) or "relaxation"
    rise_s: float
    settling_s: float
    overshoot_pct: float

    def to_json(self) -> dict:
        """JSON-ready dict (NaN becomes None)."""
        return {k: (None if isinstance(v, float) and not math.isfinite(v) else v) for k, v in asdict(self).items()}


def step_metrics(t_s: np.ndarray, y: np.ndarray, t_step_s: float, t_end_s: float,
                 from_mm: float, to_mm: float, band: float = 0.05) -> StepMetrics:
    """Metrics of the response ``y`` (mm) to a step from ``from_mm`` to ``to_mm`` at ``t_step_s``.

    Rise: time from the first crossing of 10 % to the first crossing of 90 % of the
    step. Settling: time after the step when ``y`` last left the band of
    ``band * |step|`` around ``to_mm`` (NaN if it never stays inside before
    ``t_end_s``). Overshoot: largest excursion beyond ``to_mm``, % of the step.
    """
    t, y = np.asarray(t_s, float), np.asarray(y, float)
    sel = (t >= t_step_s) & (t < t_end_s)
    tt, yy = t[sel] - t_step_s, y[sel]
    delta = to_mm - from_mm
    mode = "activation" if delta > 0 else "relaxation"
    if delta == 0 or tt.size == 0:
        return StepMetrics(from_mm, to_mm, mode, math.nan, math.nan, math.nan)
    progress = (yy - from_mm) / delta  # 0 at start, 1 at target, in either direction

    def first_cross(level: float) -> float:
        idx = np.flatnonzero(progress >= level)
        if idx.size == 0:
            return math.nan
        i = int(idx[0])
        if i == 0:
            return float(tt[0])
        # linear interpolation between the samples around the crossing
        p0, p1 = progress[i - 1], progress[i]
        return float(tt[i - 1] + (level - p0) / (p1 - p0) * (tt[i] - tt[i - 1]))

    rise = first_cross(0.9) - first_cross(0.1)
    outside = np.flatnonzero(np.abs(yy - to_mm) > band * abs(delta))
    if outside.size == 0:
        settling = 0.0
    elif outside[-1] == tt.size - 1:
        settling = math.nan
    else:
        settling = float(tt[outside[-1] + 1])
    overshoot = max(0.0, float(np.max(progress) - 1.0)) * 100.0
    return StepMetrics(from_mm, to_mm, mode, rise, settling, overshoot)


def reference_starts(n: int, hold_s: float | Sequence[float]) -> np.ndarray:
    """Times (s, from the first reference) at which each of ``n`` references starts, and the end.

    ``hold_s`` is one hold for every value (s) or one per value (``n`` of them, each
    positive and finite): a rig's test need not hold its steps evenly. Returns ``n + 1``
    times, the first 0.
    """
    holds = np.full(n, float(hold_s)) if np.ndim(hold_s) == 0 else np.asarray(hold_s, float)
    if holds.shape != (n,):
        raise BadInputError(f"{n} references need {n} holds, got {holds.size}")
    if not np.all(np.isfinite(holds) & (holds > 0)):
        raise BadInputError(f"every hold must be a positive finite time in s, got {holds.tolist()}")
    return np.concatenate([[0.0], np.cumsum(holds)])


def steps_from_sequence(t_s: np.ndarray, y: np.ndarray, sequence_mm: list[float],
                        hold_s: float | Sequence[float]) -> list[StepMetrics]:
    """Metrics of each step of a reference holding its values ``hold_s`` (s; one for all or one
    per value, see :func:`reference_starts`); the first value is the start, times from it."""
    starts = reference_starts(len(sequence_mm), hold_s)
    return [step_metrics(t_s, y, starts[i], starts[i + 1], sequence_mm[i - 1], sequence_mm[i])
            for i in range(1, len(sequence_mm))]
