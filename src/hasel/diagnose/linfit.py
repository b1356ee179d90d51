"""The diagnosis's linear identifier for logs without a nominal model: a thin use of :mod:`hasel.ident`.

For each order ``n`` (poles) a start comes from ident's least-squares ARX fit
(:func:`hasel.ident.timefit.arx_start`) or from given poles, and is refined by ident's
output-error fit (:func:`hasel.ident.timefit.oe_fit`) on the training samples of every
record, simulated with the diagnosis's sampling point (:attr:`Prepared.sample_offset`).
An output level per record is fitted alongside but left out of the model, which goes
through the origin: a log whose output is not zero at zero input then shows that as a
static map with an offset, which the diagnosis reports. Right-half-plane zeros (a
rational stand-in for a dead time) disqualify an order, so that a delay stays visible
to the diagnosis. The order is the lowest whose training error is within 3 % of the best.
"""
from __future__ import annotations

import numpy as np

from hasel.diagnose.prep import LinearSim, Prepared
from hasel.errors import BadInputError
from hasel.ident.tffit import TFModel
from hasel.ident.timefit import Pieces, arx_start, oe_fit

__all__ = ["fit_linear"]


def _stacked(prep: Prepared) -> tuple[np.ndarray, np.ndarray, Pieces]:
    """Inputs and outputs of all records end to end, each record a piece simulated from rest."""
    us, ys, est, bounds, i = [], [], [], [], 0
    for rec in prep.records:
        us.append(rec.u)
        ys.append(rec.y)
        est.append(rec.train)
        bounds.append((i, i + rec.u.size))
        i += rec.u.size
    e = np.concatenate(est)
    return np.concatenate(us), np.concatenate(ys), Pieces(bounds, e, np.zeros(e.size, bool))


def _start_from_poles(poles: np.ndarray, u: np.ndarray, y: np.ndarray, pieces: Pieces) -> TFModel:
    """A start with the given poles and the static gain of a straight line through the training samples."""
    den = np.real(np.poly(np.asarray(poles, complex)))
    x, z = u[pieces.estimate] - u[pieces.estimate].mean(), y[pieces.estimate] - y[pieces.estimate].mean()
    k0 = float(x @ z / max(float(x @ x), 1e-300))
    return TFModel(num=np.array([k0 * den[-1]]), den=den)


def _rhp_zeros(num: np.ndarray) -> int:
    """Number of zeros of ``num`` in the open right half-plane."""
    nz = np.trim_zeros(np.asarray(num, float), "f")
    if nz.size <= 1:
        return 0
    z = np.roots(nz)
    return int(np.sum(np.real(z) > 1e-6 * np.maximum(np.abs(z), 1e-12)))


def fit_linear(prep: Prepared, max_order: int = 4, orders: tuple[int, ...] | None = None,
               init_poles: np.ndarray | None = None, warm_only: bool = False) -> tuple[np.ndarray, np.ndarray, dict]:
    """Identify a stable, strictly proper continuous model ``num/den`` from the training samples.

    Parameters
    ----------
    prep : Prepared
        Working-rate data (only ``train`` samples are used).
    max_order : int
        Largest number of poles tried.
    orders : tuple of int, optional
        Exactly these numbers of poles (instead of ``1 .. max_order``).
    init_poles : ndarray, optional
        Poles (rad/s) to start from (a quick refinement) for the order of their number.
    warm_only : bool
        Start from ``init_poles`` alone (no ARX start): for many small changes of the
        data, as a profile over a delay makes.

    Returns
    -------
    num, den : ndarray
        Descending powers of s.
    info : dict
        ``{"order", "nrmse_train", "orders": {n: nrmse}, "method"}``.

    Raises
    ------
    BadInputError
        When no order gives a stable, minimum-phase model (one line saying so).
    """
    u, y, pieces = _stacked(prep)
    if not np.any(pieces.estimate):
        raise BadInputError("no training samples to identify a linear model from")
    yt = y[pieces.estimate]
    norm = float(np.linalg.norm(yt - yt.mean())) or 1.0
    fits = {}
    for n in (orders or range(1, max_order + 1)):
        starts = []
        if init_poles is not None and np.asarray(init_poles).size == n:
            starts.append(_start_from_poles(init_poles, u, y, pieces))
        if not starts or not warm_only:
            try:
                arx = arx_start(u, y, prep.rate_hz, n, pieces)
            except (np.linalg.LinAlgError, ValueError):
                arx = None
            if arx is not None:
                starts.append(arx)
        best = None
        for m0 in starts:
            try:
                with np.errstate(all="ignore"):
                    oe = oe_fit(m0, u, y, prep.rate_hz, pieces, block=1, max_nfev=60 if warm_only else 120,
                                offset=prep.sample_offset)
            except (np.linalg.LinAlgError, ValueError):
                continue
            num, den = oe.model.num, oe.model.den
            if not (np.all(np.isfinite(num)) and np.all(np.isfinite(den))) or _rhp_zeros(num) \
                    or np.any(np.real(np.roots(den)) >= 0):
                continue
            # scored on the model itself, with its best output level per record
            sim = LinearSim(num, den, prep.rate_hz, prep.sample_offset)
            e = np.concatenate([(r.y - sim.run(r.u))[r.train] for r in prep.records if r.train.any()])
            e = e - e.mean()
            sse = float(e @ e)
            if np.isfinite(sse) and (best is None or sse < best[2]):
                best = (num, den, sse)
        if best is not None:
            fits[n] = (best[0], best[1], float(np.sqrt(best[2]) / norm))
    if not fits:
        raise BadInputError("no stable, minimum-phase linear model could be fitted to the log (try a longer log "
                            "or a richer excitation, or give a nominal model)")
    e_best = min(f[2] for f in fits.values())
    order = min(n for n, f in fits.items() if f[2] <= 1.03 * e_best + 1e-12)
    num, den, e = fits[order]
    return num, den, {"order": order, "nrmse_train": e, "orders": {n: f[2] for n, f in fits.items()},
                      "method": "internal output-error fit (hasel.ident)"}
