"""Shared tools of the generic forms' fits: least squares against the training residual,
scalar searches, bounded refinement, and the clipped polynomial maps.

Every function takes the diagnosis's data through a
:class:`hasel.effects.base.FitContext` (``pipe``): ``pipe.stages`` (the chain's
intermediate signals per record), ``pipe.residuals`` and ``pipe.prep.records`` (with
their ``train`` masks). Moved here unchanged from ``hasel.diagnose.augment`` so that
each family's module can hold its own fit.
"""
from __future__ import annotations

import math
from collections.abc import Callable

import numpy as np
from scipy import optimize

from hasel.effects.base import EffectFit, FitContext
from hasel.effects.heldout import held_out_prefers

__all__ = ["STATIC_DEGREE", "POLY_RIDGE", "sumsq", "sse", "with_fit", "refine", "ls", "poly_ls", "fit_scalar",
           "downstream_nonlinear", "monomial", "monomials", "poly_map", "train_smooth", "train_halves",
           "rate_grid", "fit_log_scalar"]

#: Highest degree of the static and sensor maps' polynomials (offset and linear terms included;
#: 1, 3 or this, chosen by cross-validation within the training samples).
STATIC_DEGREE = 5
#: Ridge of the polynomial maps' least squares, relative to the mean squared column norm.
POLY_RIDGE = 1e-4
# stages whose presence downstream keeps a least-squares basis exact
_LINEAR_STAGES = {"time_delay", "load_mass", "_linear"}
Pipeline = FitContext  # the annotations below name the diagnosis's pipeline

def monomial(z: np.ndarray, j: int, lim: float = 1.0) -> np.ndarray:
    """``z**j`` on ``[-lim, lim]``, held constant outside.

    The maps are normalised so that ``[-1, 1]`` holds the training data (0.5-99.5
    percentiles); a polynomial continued beyond (even along its tangent) would swing
    wildly, so a map's deviation from the nominal stays at its value at the edge of the
    data it was fitted on.
    """
    z = np.asarray(z, float)
    if j == 0:
        return np.ones_like(z)
    return np.clip(z, -lim, lim) ** j


def monomials(z: np.ndarray, n: int, lim: float = 1.0) -> list[np.ndarray]:
    """``[monomial(z, j) for j in range(n)]``, by repeated products."""
    zc = np.clip(np.asarray(z, float), -lim, lim)
    out = [np.ones_like(zc)]
    for _ in range(1, n):
        out.append(out[-1] * zc)
    return out


def poly_map(theta, z: np.ndarray, lim: float = 1.0) -> np.ndarray:
    """``sum_j theta[j] * monomial(z, j)`` (Horner)."""
    zc = np.clip(np.asarray(z, float), -lim, lim)
    acc = np.full_like(zc, float(theta[-1]))
    for c in list(theta)[-2::-1]:
        acc = acc * zc + float(c)
    return acc


def _downstream_nonlinear(effects: dict[str, EffectFit], slot: int) -> bool:
    """Whether a stage after ``slot`` keeps a least-squares basis from being exact (a measured clip
    does not count: it only touches the samples at the measured range's ends)."""
    return any(f.slot > slot and f.name not in _LINEAR_STAGES and not f.variant.startswith("measured")
               for f in effects.values())


def sumsq(x: np.ndarray) -> float:
    """``x @ x`` without BLAS: a threaded dot product of a long vector can stall for
    milliseconds on a busy machine, and the fits call this thousands of times."""
    return float(np.einsum("i,i->", x, x))


def _sse(pipe: Pipeline, effects: dict[str, EffectFit]) -> float:
    return sumsq(pipe.residuals(effects, "train"))


def _with(effects: dict[str, EffectFit], fit: EffectFit) -> dict[str, EffectFit]:
    e = dict(effects)
    e[fit.name] = fit
    return e


def _refine(pipe: Pipeline, effects: dict[str, EffectFit], fit: EffectFit, lo, hi, max_nfev: int = 40,
            x_scale=None) -> EffectFit:
    """Nonlinear least squares on the training residual from ``fit``'s parameters."""
    def fun(th: np.ndarray) -> np.ndarray:
        return pipe.residuals(_with(effects, EffectFit(fit.name, fit.variant, tuple(map(float, th)))), "train")

    x0 = np.clip(np.asarray(fit.theta, float), lo, hi)
    try:
        res = optimize.least_squares(fun, x0, bounds=(lo, hi), method="trf", max_nfev=max_nfev,
                                     x_scale=x_scale if x_scale is not None else "jac", diff_step=1e-3)
    except (ValueError, np.linalg.LinAlgError):
        return fit
    cand = EffectFit(fit.name, fit.variant, tuple(map(float, res.x)))
    return cand if 2.0 * res.cost <= _sse(pipe, _with(effects, fit)) else fit


def _fit_or_none(fitter, pipe: Pipeline, effects: dict[str, EffectFit]) -> EffectFit | None:
    """``fitter(pipe, effects)``, or None where its least squares failed (a singular or ill-posed basis): a
    family's alternative form that cannot be fitted is no candidate, not an error."""
    try:
        return fitter(pipe, effects)
    except (ValueError, np.linalg.LinAlgError):
        return None


def prefer_rival(pipe: Pipeline, effects: dict[str, EffectFit], cur: EffectFit | None,
                 rival: EffectFit | None) -> EffectFit | None:
    """``rival`` (a family's alternative form, same name) in place of ``cur`` when its training sum of squares is
    lower and the held-out blocks prefer it (:func:`hasel.effects.heldout.held_out_prefers`); whichever exists when
    the other is None. Why both: training error alone takes the form that fits noise, held-out alone a form that
    does not explain the training data."""
    if rival is None:
        return cur
    if cur is None:
        return rival
    with_cur, with_rival = _with(effects, cur), _with(effects, rival)
    if _sse(pipe, with_rival) < _sse(pipe, with_cur) and held_out_prefers(pipe, with_cur, with_rival):
        return rival
    return cur


def bic_prefers(n: int, s_simple: float, s_rich: float, extra: int) -> bool:
    """Whether a fit with ``extra`` more parameters (training sum of squares ``s_rich``) has a lower BIC than
    the simpler one (``s_simple``) on ``n`` samples, noise variance unknown: ``n log(s_simple / s_rich) >
    extra log n``; False when either sum is not positive or ``n <= 1``."""
    return n > 1 and s_rich > 0 and s_simple > 0 and n * math.log(s_simple / s_rich) > extra * math.log(n)


def _train_smooth(x: np.ndarray, m: np.ndarray, n: int) -> np.ndarray:
    """Moving average of ``x`` over ``n`` samples using training samples (``m``) only."""
    def box(v: np.ndarray) -> np.ndarray:
        c = np.concatenate([[0.0], np.cumsum(v)])
        i = np.arange(v.size)
        lo = np.clip(i - n // 2, 0, v.size)
        hi = np.clip(i - n // 2 + n, 0, v.size)
        return c[hi] - c[lo]

    return box(np.where(m, x, 0.0)) / np.maximum(box(m.astype(float)), 1.0)


def _ls(pipe: Pipeline, effects: dict[str, EffectFit], basis_fn, nonneg: bool = False,
        smooth: int = 0) -> np.ndarray:
    """Least-squares weights of basis responses (per record) against the current training residual.

    ``smooth > 1`` fits the moving averages (over that many samples, training samples only)
    of the basis and the residual: only their slow parts decide the weights.
    """
    cols, rhs = [], []
    for ri, rec in enumerate(pipe.prep.records):
        m = rec.train
        if not m.any():
            continue
        st = pipe.stages(effects, ri)
        B = basis_fn(ri, st)
        r = rec.y - st["y"]
        if smooth > 1:
            B = [_train_smooth(b, m, smooth) for b in B]
            r = _train_smooth(r, m, smooth)
        cols.append(np.column_stack(B)[m])
        rhs.append(r[m])
    A = np.vstack(cols)
    b = np.concatenate(rhs)
    scale = np.sqrt(np.sum(A * A, axis=0))
    scale[scale == 0] = 1.0
    if nonneg:
        # the same minimiser on the k x k triangle of A's QR (||Ax - b||^2 differs by a constant):
        # an exact active-set solve on a few columns instead of an iterative one on every sample
        q, r_ = np.linalg.qr(A / scale)
        sol = optimize.nnls(r_, q.T @ b)[0]
    else:
        sol = np.linalg.lstsq(A / scale, b, rcond=None)[0]
    return sol / scale


def _fit_scalar(pipe: Pipeline, effects: dict[str, EffectFit], make, grid: np.ndarray,
                maxiter: int = 20) -> EffectFit | None:
    """Best of ``make(v)`` over ``grid`` then a bounded refinement between its neighbours."""
    if grid.size == 0:
        return None
    costs = np.array([_sse(pipe, _with(effects, make(float(v)))) for v in grid])
    i = int(np.argmin(costs))
    lo = grid[max(i - 1, 0)]
    hi = grid[min(i + 1, grid.size - 1)]
    if hi > lo:
        res = optimize.minimize_scalar(lambda v: _sse(pipe, _with(effects, make(float(v)))), bounds=(lo, hi),
                                       method="bounded", options={"xatol": 1e-3 * (hi - lo), "maxiter": maxiter})
        if res.fun <= costs[i]:
            return make(float(res.x))
    return make(float(grid[i]))


def _train_halves(rec) -> tuple[np.ndarray, np.ndarray]:
    """The training samples of a record split in two by alternating its contiguous runs."""
    m = rec.train
    edges = np.flatnonzero(np.diff(np.concatenate([[0], m.astype(int), [0]])))
    a = np.zeros(m.size, bool)
    for i, (s0, s1) in enumerate(zip(edges[::2], edges[1::2])):
        if i % 2 == 0:
            a[s0:s1] = True
    return a, m & ~a


def _poly_ls(pipe: Pipeline, effects: dict[str, EffectFit], basis_fn, degrees=(1, 3, STATIC_DEGREE)) -> np.ndarray:
    """Least-squares polynomial weights with the degree chosen by two-fold cross-validation
    within the training samples (a high degree fitted where the data hold few levels, e.g.
    a single step, would swing wildly in between)."""
    cols, rhs, half = [], [], []
    for ri, rec in enumerate(pipe.prep.records):
        if not rec.train.any():
            continue
        st = pipe.stages(effects, ri)
        B = np.column_stack(basis_fn(ri, st))
        a, b = _train_halves(rec)
        m = rec.train
        cols.append(B[m])
        rhs.append((rec.y - st["y"])[m])
        half.append(a[m])
    A = np.vstack(cols)
    r = np.concatenate(rhs)
    ha = np.concatenate(half)
    scale = np.sqrt(np.sum(A * A, axis=0))
    scale[scale == 0] = 1.0
    An = A / scale
    # the two halves' rows, taken out once (not at each of the six solves below)
    parts = {True: (An[ha], r[ha]), False: (An[~ha], r[~ha]), None: (An, r)}

    def solve(cols_: slice, rows: bool | None) -> np.ndarray:
        # a little ridge on the unit-norm columns: monomials of high degree are nearly
        # collinear, and unregularised they trade huge coefficients of opposite signs
        M = parts[rows][0][:, cols_]
        k = M.shape[1]
        MtM = M.T @ M
        lam = POLY_RIDGE * float(np.trace(MtM)) / k
        return np.linalg.solve(MtM + lam * np.eye(k), M.T @ parts[rows][1])

    # two held levels (a step) cannot tell an affine map from a gain change of the linear
    # part: the map keeps only its offset then (a gain change is the load family's)
    degrees = tuple(d for d in degrees if d <= pipe.max_degree) if pipe.max_degree > 1 else (0,)
    best_d, best_cv = degrees[-1], np.inf
    if ha.any() and (~ha).any():
        for d in degrees:
            c = slice(0, d + 1)
            cv = 0.0
            for tr in (True, False):
                M_te, r_te = parts[not tr]
                e = r_te - M_te[:, c] @ solve(c, tr)
                cv += sumsq(e)
            if cv < best_cv * (1 - 1e-3):
                best_d, best_cv = d, cv
    c = slice(0, best_d + 1)
    return solve(c, None) / scale[c]



# public names (the underscored ones are kept for the diagnosis's older imports)
sse = _sse
with_fit = _with
refine = _refine
ls = _ls
poly_ls = _poly_ls
fit_scalar = _fit_scalar
downstream_nonlinear = _downstream_nonlinear
train_smooth = _train_smooth
train_halves = _train_halves
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


