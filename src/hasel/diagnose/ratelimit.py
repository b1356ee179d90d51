"""Rate limits, and a test of whether a fitted static map is a line.

Two signatures that neither a clip, a lag nor a delay has:

- **slew limit** of the input (an amplifier's current limit): the applied input
  cannot change faster than ``S`` (input units per second),
  ``x_k = x_{k-1} + clip(u_k - x_{k-1}, -S dt, S dt)``. The gap appears only where the
  command moves faster than ``S`` (steps, the fast part of a chirp), whatever the
  level; a step becomes a ramp of slope ``S``, a sine of amplitude ``A`` and angular
  frequency ``w`` is untouched while ``A w <= S`` and turns into a triangle beyond.
  Its lag grows with amplitude times frequency, a delay's does not.
- **speed limit** of the output in one direction (e.g. a relaxation limited by the
  flow of the liquid back): ``y_k = max(z_k, y_{k-1} - R dt)`` while falling (``R``
  output units per second), ``y_k = z_k`` while rising (or the mirror image). The gap
  appears only while the output falls (rises) fast; a falling step becomes a ramp.

Both are one-parameter families; :func:`rate_grid` proposes candidate limits from the
speeds the signal actually has, and :func:`fit_log_scalar` searches a cost over them
(a grid, then a bounded refinement in ``log`` between the best's neighbours).

:func:`line_share` measures how far a fitted static map is from a line: a map whose
curve deviates little from its own best line (over the samples it acts on) is a
linear correction of the model (a gain, a changed dynamic), not a static nonlinearity.
"""
from __future__ import annotations

import math
from collections.abc import Callable

import numpy as np
from scipy import optimize

__all__ = ["slew_limit", "speed_limit", "rate_grid", "fit_log_scalar", "line_share", "DIRECTIONS"]

#: Directions a speed limit of the output may act in.
DIRECTIONS = ("falling", "rising")


def _limited(x: np.ndarray, up: float, down: float, y0: float | None) -> np.ndarray:
    """``y_k = y_{k-1} + clip(x_k - y_{k-1}, -down, up)`` (steps per sample, ``inf``: free).

    The limit acts only where the signal moves faster than it (or after it did, until the
    output has caught up): the samples in between are copied, only the active runs looped.
    """
    xs = np.asarray(x, float)
    out = xs.copy()
    if xs.size == 0:
        return out
    y = float(xs[0]) if y0 is None else float(y0)
    d0 = np.diff(xs, prepend=y)
    fast = np.flatnonzero((d0 > up) | (d0 < -down))
    vals = xs.tolist()
    n = xs.size
    j = 0
    while j < fast.size:
        k = int(fast[j])
        y = vals[k - 1] if k > 0 else y
        while k < n:  # active: follow at the limit until the output meets the signal again
            d = vals[k] - y
            if d > up:
                y += up
            elif d < -down:
                y -= down
            else:
                y = vals[k]
                out[k] = y
                k += 1
                break
            out[k] = y
            k += 1
        j = int(np.searchsorted(fast, k, side="left"))  # caught up: copy until the next fast sample
    return out


def _step(rate: float, dt: float) -> float:
    step = float(rate) * float(dt)
    if not step > 0:
        raise ValueError(f"rate limit must be > 0, got {rate}")
    return step


def slew_limit(x: np.ndarray, rate: float, dt: float, x0: float | None = None) -> np.ndarray:
    """``x`` followed at a speed of at most ``rate`` (units of ``x`` per second).

    Parameters
    ----------
    x : ndarray, shape (n,)
        The command, sampled every ``dt`` seconds.
    rate : float
        Slew limit, units of ``x`` per second (> 0; ``inf``: no limit).
    dt : float
        Sample interval, s.
    x0 : float, optional
        State before the first sample (default ``x[0]``: settled).

    Returns
    -------
    ndarray, shape (n,)
        ``y_k = y_{k-1} + clip(x_k - y_{k-1}, -rate dt, rate dt)``.
    """
    step = _step(rate, dt)
    return _limited(x, step, step, x0)


def speed_limit(z: np.ndarray, rate: float, dt: float, direction: str = "falling",
                y0: float | None = None) -> np.ndarray:
    """``z`` followed at once in one direction and at most at ``rate`` in the other.

    Parameters
    ----------
    z : ndarray, shape (n,)
        The unlimited output, sampled every ``dt`` seconds.
    rate : float
        Largest speed in ``direction``, units of ``z`` per second (> 0; ``inf``: no limit).
    dt : float
        Sample interval, s.
    direction : {"falling", "rising"}
        The limited direction.
    y0 : float, optional
        State before the first sample (default ``z[0]``).

    Returns
    -------
    ndarray, shape (n,)
        Falling: ``y_k = z_k`` if ``z_k >= y_{k-1}``, else ``max(z_k, y_{k-1} - rate dt)``.
    """
    if direction not in DIRECTIONS:
        raise ValueError(f"direction must be one of {DIRECTIONS}, got {direction!r}")
    step = _step(rate, dt)
    return _limited(z, math.inf, step, y0) if direction == "falling" else _limited(z, step, math.inf, y0)


def rate_grid(x: np.ndarray, dt: float, n: int = 10, direction: str | None = None,
              lo_quantile: float = 0.5) -> np.ndarray:
    """Candidate rate limits for the signal ``x``: a geometric grid of ``n`` speeds.

    From the ``lo_quantile`` quantile of the signal's moving speeds (a limit below most of
    them would distort the whole log) to just below its fastest speed (a limit above
    that does nothing).

    Parameters
    ----------
    x : ndarray
        The signal the limit would act on.
    dt : float
        Sample interval, s.
    n : int
        Grid size.
    direction : {None, "falling", "rising"}
        Speeds of both directions (``None``) or only of that one.
    lo_quantile : float
        Quantile of the nonzero speeds where the grid starts.

    Returns
    -------
    ndarray
        Increasing speeds (units of ``x`` per second); empty if ``x`` never moves.
    """
    d = np.diff(np.asarray(x, float)) / dt
    if direction == "falling":
        d = -d
    if direction is not None:
        d = d[d > 0]
    else:
        d = np.abs(d)
    scale = float(np.max(np.abs(x))) if np.size(x) else 0.0
    d = d[d > 1e-9 * max(scale, 1e-300) / dt]
    if d.size < 2:
        return np.zeros(0)
    hi = 0.95 * float(d.max())
    lo = min(float(np.quantile(d, lo_quantile)), 0.5 * hi)
    lo = max(lo, 1e-3 * hi)
    if not (hi > lo > 0):
        return np.zeros(0)
    return np.geomspace(lo, hi, n)


def fit_log_scalar(cost: Callable[[float], float], grid: np.ndarray, maxiter: int = 12,
                   max_extend: int = 4) -> tuple[float, float]:
    """Minimise ``cost`` over a positive geometric ``grid``, then between the best's neighbours in ``log``.

    When the best is at an end of the grid, the grid is extended beyond that end by its own
    ratio (at most ``max_extend`` times) until the cost rises again.

    Returns
    -------
    (value, cost) : (float, float)
        The best value and its cost (``(nan, inf)`` for an empty grid).
    """
    vals = [float(v) for v in np.asarray(grid, float)]
    if not vals:
        return float("nan"), float("inf")
    costs = [cost(v) for v in vals]
    if len(vals) > 1:
        ratio = vals[1] / vals[0]
        for _ in range(max_extend):
            i = int(np.argmin(costs))
            if i == 0:
                vals.insert(0, vals[0] / ratio)
                costs.insert(0, cost(vals[0]))
            elif i == len(vals) - 1:
                vals.append(vals[-1] * ratio)
                costs.append(cost(vals[-1]))
            else:
                break
    i = int(np.argmin(costs))
    best, best_c = vals[i], float(costs[i])
    lo, hi = math.log(vals[max(i - 1, 0)]), math.log(vals[min(i + 1, len(vals) - 1)])
    if hi > lo:
        res = optimize.minimize_scalar(lambda v: cost(math.exp(v)), bounds=(lo, hi), method="bounded",
                                       options={"xatol": 1e-3 * (hi - lo), "maxiter": maxiter})
        if float(res.fun) < best_c:
            best, best_c = math.exp(float(res.x)), float(res.fun)
    return best, best_c


def line_share(curve: np.ndarray, at: np.ndarray) -> float:
    """How far a static map's curve is from a line, over the points it acts on.

    Parameters
    ----------
    curve : ndarray, shape (n,)
        The map's deviation from the nominal at the samples ``at`` (its output minus its
        input, any unit).
    at : ndarray, shape (n,)
        The samples the map acts on.

    Returns
    -------
    float
        RMS of ``curve`` minus its least-squares line in ``at``, over the RMS of ``curve``
        minus its mean (0: a line; 1: nothing of it is a line); 0 for a constant curve.
    """
    c = np.asarray(curve, float)
    a = np.asarray(at, float)
    c0 = c - c.mean()
    a0 = a - a.mean()
    tot = float(np.einsum("i,i->", c0, c0))
    if tot <= 0:
        return 0.0
    aa = float(np.einsum("i,i->", a0, a0))
    slope = float(np.einsum("i,i->", a0, c0)) / aa if aa > 0 else 0.0
    e = c0 - slope * a0
    return math.sqrt(float(np.einsum("i,i->", e, e)) / tot)
