"""The static map ``h_s(v_s)``: mean output against the operating point (paper eq. 12).

Each operating point gives one point (mean input, mean output) over its data; a
polynomial of low degree is fitted through them, its degree chosen by leave-one-level-out
error (the held-out error of each level's points when the other levels are fitted; points
within :data:`LEVEL_FRACTION` of the span of each other are one level), preferring the
lower degree when two are within 25 %.
"""
from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from hasel.errors import BadInputError

__all__ = ["StaticMap", "fit_static_map"]


@dataclass(frozen=True)
class StaticMap:
    """A fitted static map.

    Attributes
    ----------
    offsets : ndarray
        Mean input of each operating point, input unit.
    means : ndarray
        Mean output of each operating point, output unit.
    degree : int
        Degree of the fitted polynomial.
    coefficients : ndarray
        Polynomial coefficients, descending powers of the input (``numpy.polyval``).
    rmse : float
        RMS residual of the fit at the points, output unit.
    loo_rmse : float
        Leave-one-level-out RMS error of the chosen degree, output unit (``nan`` if too
        few points).
    loo_by_degree : dict of int to float
        Leave-one-level-out RMS error of every degree tried.
    """

    offsets: np.ndarray
    means: np.ndarray
    degree: int
    coefficients: np.ndarray
    rmse: float
    loo_rmse: float
    loo_by_degree: dict[int, float]

    def __call__(self, v: np.ndarray | float) -> np.ndarray:
        """``h_s(v)``: the output for a constant input ``v``."""
        return np.polyval(self.coefficients, np.asarray(v, float))

    def slope(self, v: np.ndarray | float) -> np.ndarray:
        """``dh_s/dv`` at ``v``: the local static gain, output unit per input unit."""
        if self.degree == 0:
            return np.zeros_like(np.asarray(v, float))
        return np.polyval(np.polyder(self.coefficients), np.asarray(v, float))

    def to_json(self) -> dict:
        """JSON-ready dict."""
        return {
            "degree": self.degree,
            "coefficients": [float(c) for c in self.coefficients],
            "offsets": [float(v) for v in self.offsets],
            "means": [float(v) for v in self.means],
            "rmse": float(self.rmse),
            "loo_rmse": None if not np.isfinite(self.loo_rmse) else float(self.loo_rmse),
        }


#: Points whose inputs lie within this fraction of the points' span of their neighbour are one level (set a
#: priori, not tuned): repeats at an offset or a staircase's return to a level, left out together.
LEVEL_FRACTION = 0.02


def _levels(x: np.ndarray) -> np.ndarray:
    """Level index of each point of the sorted inputs ``x``: a new level where the gap exceeds LEVEL_FRACTION."""
    gaps = np.diff(x) > LEVEL_FRACTION * float(np.ptp(x))
    return np.concatenate([[0], np.cumsum(gaps)]).astype(int)


def _loo(x: np.ndarray, y: np.ndarray, deg: int, levels: np.ndarray) -> float:
    """RMS error of the points of each level predicted by the polynomial of degree ``deg`` through the others."""
    err = []
    for k in np.unique(levels):
        m = levels != k
        c = np.polyfit(x[m], y[m], deg)
        err.extend(np.polyval(c, x[~m]) - y[~m])
    return float(np.sqrt(np.mean(np.square(err))))


def fit_static_map(offsets: Sequence[float] | np.ndarray, means: Sequence[float] | np.ndarray, *,
                   max_degree: int = 3) -> StaticMap:
    """Fit ``h_s`` through (operating point, mean output) pairs.

    Parameters
    ----------
    offsets : array_like, shape (n,)
        Mean input of each operating point, input unit.
    means : array_like, shape (n,)
        Mean output of each, output unit.
    max_degree : int
        Highest polynomial degree tried.

    Returns
    -------
    StaticMap
        Degree 0 for one point, 1 for two levels (the line through them), else the
        degree of least leave-one-level-out error up to ``min(max_degree, levels - 2)``,
        the lower one when within 25 %.

    Raises
    ------
    BadInputError
        Without points, with non-finite values, or with repeated offsets only.
    """
    x = np.asarray(offsets, float)
    y = np.asarray(means, float)
    if x.ndim != 1 or x.shape != y.shape or x.size == 0:
        raise BadInputError(f"offsets and means must be non-empty 1-D arrays of one length, got {x.shape}, {y.shape}")
    if not (np.all(np.isfinite(x)) and np.all(np.isfinite(y))):
        raise BadInputError("offsets and means must be finite")
    order = np.argsort(x)
    x, y = x[order], y[order]
    n_distinct = np.unique(np.round(x, 12)).size
    levels = _levels(x) if n_distinct > 1 else np.zeros(x.size, int)
    n_levels = int(levels[-1]) + 1
    loo: dict[int, float] = {}
    if n_distinct <= 1:
        deg = 0
    elif n_levels <= 2:
        deg = 1
    else:
        # repeats at one level say how noisy a mean is, not how the map bends: leave whole levels out (a twin left
        # in lets a curve through it look predictive; three chirps per offset chose a cubic for an LTI log)
        for d in range(0, min(max_degree, n_levels - 2) + 1):
            loo[d] = _loo(x, y, d, levels)
        best = min(loo.values())
        deg = min(d for d, e in loo.items() if e <= 1.25 * best)
    coef = np.polyfit(x, y, deg) if n_distinct > deg else np.array([float(np.mean(y))])
    rmse = float(np.sqrt(np.mean((np.polyval(coef, x) - y) ** 2)))
    return StaticMap(offsets=x, means=y, degree=int(deg), coefficients=np.asarray(coef, float), rmse=rmse,
                     loo_rmse=loo.get(deg, float("nan")), loo_by_degree=loo)
