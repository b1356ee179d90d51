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

The kernels live with their families (:func:`hasel.effects.saturation.slew_limit`,
:func:`hasel.effects.asymmetric.speed_limit`, both on
:func:`hasel.effects.operators.rate_limited`); this module keeps their old names.

Both are one-parameter families; :func:`rate_grid` proposes candidate limits from the
speeds the signal actually has, and :func:`fit_log_scalar` searches a cost over them
(a grid, then a bounded refinement in ``log`` between the best's neighbours).

:func:`line_share` measures how far a fitted static map is from a line: a map whose
curve deviates little from its own best line (over the samples it acts on) is a
linear correction of the model (a gain, a changed dynamic), not a static nonlinearity.
"""
from __future__ import annotations

import math

import numpy as np

from hasel.effects.asymmetric import DIRECTIONS, speed_limit
from hasel.effects.fitkit import fit_log_scalar, rate_grid
from hasel.effects.operators import rate_limited as _limited  # noqa: F401 - the old private name
from hasel.effects.saturation import slew_limit

__all__ = ["slew_limit", "speed_limit", "rate_grid", "fit_log_scalar", "line_share", "DIRECTIONS"]


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
