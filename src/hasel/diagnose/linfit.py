"""A small continuous-time output-error fit, for logs diagnosed without a nominal model.

For each order ``n`` (poles) the fit starts from the poles of an ARX model, mapped to
continuous time, and refines them on the simulation (output) error; for given poles
the numerator enters linearly and is solved by least squares inside the loop
(variable projection), so only the poles are searched. The model goes through the
origin (no offset): a log whose output is not zero at zero input then shows that as
a static map with an offset, which the diagnosis reports. The order is the lowest
whose training error is within 3 % of the best.
"""
from __future__ import annotations

import numpy as np
from scipy import optimize

from hasel.diagnose.prep import LinearSim, Prepared

__all__ = ["fit_linear"]


def _poles_from_theta(th: np.ndarray, n_real: int) -> np.ndarray:
    real = -np.exp(th[:n_real])
    pairs = []
    for i in range(n_real, th.size, 2):
        wn, zeta = np.exp(th[i]), 1.0 / (1.0 + np.exp(-th[i + 1]))
        re, im = -zeta * wn, wn * np.sqrt(max(1.0 - zeta * zeta, 0.0))
        pairs += [re + 1j * im, re - 1j * im]
    return np.concatenate([real.astype(complex), np.asarray(pairs, complex)])


def _theta_from_poles(p: np.ndarray) -> tuple[np.ndarray, int]:
    real = np.sort(np.real(p[np.abs(p.imag) < 1e-9 * np.maximum(1, np.abs(p))]))
    cplx = p[p.imag >= 1e-9 * np.maximum(1, np.abs(p))]
    th = list(np.log(np.maximum(-real, 1e-9)))
    for c in cplx:
        wn = abs(c)
        zeta = float(np.clip(-c.real / wn, 0.02, 0.98))
        th += [np.log(wn), np.log(zeta / (1 - zeta))]
    return np.asarray(th, float), real.size


def _arx_poles(prep: Prepared, n: int) -> np.ndarray:
    rows, rhs = [], []
    for rec in prep.records:
        if rec.train.sum() <= 3 * n:
            continue
        y, u = rec.y - rec.y.mean(), rec.u - rec.u.mean()
        k = np.arange(n, y.size)
        k = k[rec.train[n:]]
        cols = [-y[k - i] for i in range(1, n + 1)] + [u[k - i] for i in range(1, n + 1)]
        rows.append(np.column_stack(cols))
        rhs.append(y[k])
    A, b = np.vstack(rows), np.concatenate(rhs)
    sol = np.linalg.lstsq(A, b, rcond=None)[0]
    z = np.roots(np.concatenate([[1.0], sol[:n]]))
    z = np.where(np.abs(z) >= 0.999, 0.999 * z / np.abs(z), z)
    s = np.log(z.astype(complex)) * prep.rate_hz
    # negative real z have no continuous counterpart: take them as fast real poles
    s = np.where((np.abs(z.imag) < 1e-12) & (z.real <= 0), -0.5 * np.pi * prep.rate_hz + 0j, s)
    s = np.where(s.real > -1e-6, -1e-3 * prep.rate_hz + 1j * s.imag, s)
    # keep conjugate pairs consistent
    return np.concatenate([s[np.abs(s.imag) < 1e-9], s[s.imag >= 1e-9], np.conj(s[s.imag >= 1e-9])])


def _solve_num(prep: Prepared, den: np.ndarray) -> tuple[np.ndarray, float, list[np.ndarray]]:
    n = den.size - 1
    cols_all, ys, sims = [], [], []
    for j in range(n):
        num = np.zeros(j + 1)
        num[0] = 1.0
        sims.append(LinearSim(num, den, prep.rate_hz))
    for rec in prep.records:
        if not rec.train.any():
            continue
        B = np.column_stack([s.run(rec.u) for s in sims])
        cols_all.append(B[rec.train])
        ys.append(rec.y[rec.train])
    A, b = np.vstack(cols_all), np.concatenate(ys)
    scale = np.sqrt((A * A).sum(axis=0))
    scale[scale == 0] = 1.0
    c = np.linalg.lstsq(A / scale, b, rcond=None)[0] / scale
    r = b - A @ c
    # numerator: sum_j c_j s^j  (descending powers)
    num = c[::-1]
    return num, float(r @ r), [b]


def _fit_order(prep: Prepared, n: int) -> tuple[np.ndarray, np.ndarray, float]:
    try:
        p0 = _arx_poles(prep, n)
    except (np.linalg.LinAlgError, ValueError):
        p0 = -np.geomspace(0.1, 0.1 * prep.rate_hz, n) + 0j
    th0, n_real = _theta_from_poles(p0)
    lo = np.log(1e-4 / (prep.records[0].t_s[-1] - prep.records[0].t_s[0] + 1e-9))
    hi = np.log(0.45 * np.pi * prep.rate_hz)

    def cost(th: np.ndarray) -> float:
        t2 = th.copy()
        t2[:n_real] = np.clip(t2[:n_real], lo, hi)
        t2[n_real::2] = np.clip(t2[n_real::2], lo, hi)
        den = np.real(np.poly(_poles_from_theta(t2, n_real)))
        try:
            return _solve_num(prep, den)[1]
        except (np.linalg.LinAlgError, ValueError):
            return np.inf

    res = optimize.minimize(cost, th0, method="Nelder-Mead",
                            options={"maxiter": 120 * th0.size, "xatol": 1e-3, "fatol": 1e-9})
    th = res.x if res.fun <= cost(th0) else th0
    th[:n_real] = np.clip(th[:n_real], lo, hi)
    th[n_real::2] = np.clip(th[n_real::2], lo, hi)
    den = np.real(np.poly(_poles_from_theta(th, n_real)))
    num, sse, _ = _solve_num(prep, den)
    return num, den, sse


def fit_linear(prep: Prepared, max_order: int = 4) -> tuple[np.ndarray, np.ndarray, dict]:
    """Identify a stable, strictly proper continuous model ``num/den`` from the training samples.

    Parameters
    ----------
    prep : Prepared
        Working-rate data (only ``train`` samples are used).
    max_order : int
        Largest number of poles tried.

    Returns
    -------
    num, den : ndarray
        Descending powers of s.
    info : dict
        ``{"order", "nrmse_train", "orders": {n: nrmse}}``.
    """
    y = np.concatenate([r.y[r.train] for r in prep.records])
    fits = {}
    for n in range(1, max_order + 1):
        try:
            num, den, sse = _fit_order(prep, n)
        except (np.linalg.LinAlgError, ValueError):
            continue
        fits[n] = (num, den, float(np.sqrt(sse) / np.linalg.norm(y - y.mean())))
    if not fits:
        raise ValueError("no linear model could be fitted")
    best = min(f[2] for f in fits.values())
    order = min(n for n, f in fits.items() if f[2] <= 1.03 * best + 1e-12)
    num, den, e = fits[order]
    return num, den, {"order": order, "nrmse_train": e, "orders": {n: f[2] for n, f in fits.items()},
                      "method": "internal output-error fit"}

