"""A small continuous-time output-error fit, for logs diagnosed without a nominal model.

For each order ``n`` (poles) the fit starts from the poles of an ARX model, mapped to
continuous time, and refines them on the simulation (output) error; for given poles
the output is a combination of the modal (partial-fraction) responses, each an exact
closed-form ZOH recursion, so the numerator is solved by least squares inside the
loop (variable projection) and only the poles are searched. An output offset is
fitted alongside but left out of the model, which goes through the origin: a log
whose output is not zero at zero input then shows that as a static map with an
offset, which the diagnosis reports. The order is the lowest
whose training error is within 3 % of the best.
"""
from __future__ import annotations

import numpy as np
from scipy import optimize, signal

from hasel.diagnose.prep import LinearSim, Prepared, at_offset
from hasel.errors import BadInputError

__all__ = ["fit_linear"]


def _poles_from_theta(th: np.ndarray, n_real: int, w_lo: float, w_hi: float) -> np.ndarray:
    """Poles from free parameters: magnitudes ``w_lo + exp(theta)`` (at most ``w_hi``), damping logistic."""
    mag = np.minimum(w_lo + np.exp(np.minimum(th, 50.0)), w_hi)
    real = -mag[:n_real]
    pairs = []
    for i in range(n_real, th.size, 2):
        wn, zeta = mag[i], 1.0 / (1.0 + np.exp(-th[i + 1]))
        re, im = -zeta * wn, wn * np.sqrt(max(1.0 - zeta * zeta, 0.0))
        pairs += [re + 1j * im, re - 1j * im]
    return np.concatenate([real.astype(complex), np.asarray(pairs, complex)])


def _theta_from_poles(p: np.ndarray, w_lo: float) -> tuple[np.ndarray, int]:
    real = np.sort(np.real(p[np.abs(p.imag) < 1e-9 * np.maximum(1, np.abs(p))]))
    cplx = p[p.imag >= 1e-9 * np.maximum(1, np.abs(p))]
    th = list(np.log(np.maximum(-real - w_lo, 1e-3 * w_lo + 1e-12)))
    for c in cplx:
        wn = abs(c)
        zeta = float(np.clip(-c.real / wn, 0.02, 0.98))
        th += [np.log(max(wn - w_lo, 1e-3 * w_lo + 1e-12)), np.log(zeta / (1 - zeta))]
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


def _modal_columns(poles: np.ndarray, u: np.ndarray, rate_hz: float, offset: float = 0.0,
                   rows: np.ndarray | None = None) -> list[np.ndarray]:
    """Responses to ``u`` of ``1/(s - p)`` (real poles) and of the real and imaginary parts of
    ``1/(s - p)`` (one of each conjugate pair): exact ZOH recursions in closed form, started at
    rest with ``u[0]``, output ``offset`` samples into each interval (as :class:`LinearSim`);
    only the samples ``rows`` (a boolean mask) when given."""
    T = 1.0 / rate_hz
    cols = []
    for p in poles:
        real = np.imag(p) == 0
        # a real pole in real arithmetic: the same numbers as the complex recursion, half the work
        pp = float(np.real(p)) if real else complex(p)
        a = np.exp(pp * T)
        bb = (a - 1.0) / pp
        x0 = -u[0] / pp
        y = signal.lfilter([bb], [1.0, -a], u, zi=[a * x0])[0]
        x = np.concatenate([[x0], y])
        mid = x[:-1] if offset == 0.0 else at_offset(x, offset)
        if rows is not None:
            mid = mid[rows]
        if real:
            cols.append(mid)
        else:
            cols += [mid.real, mid.imag]
    return cols


def _modal_poles(poles: np.ndarray) -> np.ndarray:
    """Real poles, then one pole (positive imaginary part) of each conjugate pair."""
    tol = 1e-9 * np.maximum(1.0, np.abs(poles))
    return np.concatenate([np.real(poles[np.abs(poles.imag) <= tol]).astype(complex), poles[poles.imag > tol]])


def _solve_num(prep: Prepared, poles: np.ndarray) -> tuple[np.ndarray, float, np.ndarray]:
    """Best numerator for the given poles (least squares on the training samples).

    The output is a combination of the modal responses (partial fractions), so for given
    poles the numerator is linear and found by least squares; an output offset is
    fitted alongside and dropped from the model (the dynamics and the incremental gain come
    out right, and an offset is left for the diagnosis to name).

    Returns the numerator, the training SSE and the denominator.
    """
    poles = np.asarray(poles, complex)
    if not np.all(np.isfinite(poles)):
        raise ValueError("non-finite poles")
    mp = _modal_poles(poles)
    cols_all, ys = [], []
    for rec in prep.records:
        if not rec.train.any():
            continue
        cols = _modal_columns(mp, rec.u, prep.rate_hz, prep.sample_offset, rows=rec.train)
        B = np.empty((cols[0].size, len(cols) + 1))
        for j, c in enumerate(cols):
            B[:, j] = c
        B[:, -1] = 1.0
        cols_all.append(B)
        ys.append(rec.y[rec.train])
    A, b = (cols_all[0], ys[0]) if len(cols_all) == 1 else (np.vstack(cols_all), np.concatenate(ys))
    scale = np.sqrt(np.einsum("ij,ij->j", A, A))
    scale[scale == 0] = 1.0
    c = np.linalg.lstsq(A / scale, b, rcond=None)[0] / scale
    r = b - A @ c
    full = np.concatenate([mp, np.conj(mp[mp.imag > 0])])
    den = np.real(np.poly(full))
    n = den.size - 1
    num = np.zeros(n, complex)
    i = 0
    for k, p in enumerate(mp):
        others = np.delete(full, k) if p.imag == 0 else np.delete(full, [k, mp.size + int(np.sum(mp[:k].imag > 0))])
        rest = np.poly(others) if others.size else np.array([1.0])
        if p.imag == 0:
            term = c[i] * rest
            i += 1
        else:
            term = np.polymul([c[i], -c[i] * p.real + c[i + 1] * p.imag], rest)
            i += 2
        num[n - term.size:] += term
    return np.real(num), float(np.einsum('i,i->', r, r)), den


def _rhp_zeros(num: np.ndarray) -> int:
    """Number of zeros of ``num`` in the open right half-plane."""
    nz = np.trim_zeros(np.asarray(num, float), "f")
    if nz.size <= 1:
        return 0
    z = np.roots(nz)
    return int(np.sum(np.real(z) > 1e-6 * np.maximum(np.abs(z), 1e-12)))


def _minimum_phase(num: np.ndarray) -> bool:
    """No zero in the right half-plane (zeros on the imaginary axis allowed).

    Right half-plane zeros are how a rational model imitates a dead time (Pade); the fit
    is kept minimum-phase so that a delay stays visible to the diagnosis.
    """
    nz = np.trim_zeros(np.asarray(num, float), "f")
    if nz.size <= 1:
        return True
    z = np.roots(nz)
    return bool(np.all(np.real(z) <= 1e-6 * np.maximum(np.abs(z), 1e-12)))


def _fit_order(prep: Prepared, n: int, init: np.ndarray | None = None,
               warm_only: bool = False) -> tuple[np.ndarray, np.ndarray, float]:
    # modes slower than a twentieth of the log are offsets or drifts, not dynamics it can identify
    w_lo = 20.0 / (prep.records[0].t_s[-1] - prep.records[0].t_s[0] + 1e-9)
    w_hi = 0.45 * np.pi * prep.rate_hz
    starts = []
    n_train = sum(int(r.train.sum()) for r in prep.records)
    if init is not None and np.asarray(init).size == n:
        starts.append(np.asarray(init, complex))  # a warm start (alone on long logs, to save time)
    if not starts or (n_train < 5000 and not warm_only):
        try:
            starts.append(_arx_poles(prep, n))
        except (np.linalg.LinAlgError, ValueError):
            pass
        w_exc = 2 * np.pi * min(max(prep.f_excited_hz, 1e-6), 0.4 * prep.rate_hz)
        starts.append(-np.geomspace(max(w_lo * 1.5, w_exc / 30.0), max(w_exc, w_lo * 3.0), n) + 0j)
    iters = 30 if (init is not None and n_train >= 5000) else 80
    def make_cost(n_real: int):
        def cost(th: np.ndarray) -> float:
            try:
                num, sse, _ = _solve_num(prep, _poles_from_theta(th, n_real, w_lo, w_hi))
            except (np.linalg.LinAlgError, ValueError, StopIteration, BadInputError):
                return np.inf
            # right half-plane zeros are penalised (a hard wall would leave the search no slope)
            return sse * (1.0 + 10.0 * _rhp_zeros(num))
        return cost

    best = None
    for p0 in starts:
        th0, n_real = _theta_from_poles(p0, w_lo)
        cost = make_cost(n_real)
        c0 = cost(th0)
        if best is not None and c0 > 100 * best[0]:
            continue
        res = optimize.minimize(cost, th0, method="Nelder-Mead",
                                options={"maxiter": iters * th0.size, "xatol": 1e-2, "fatol": 1e-9})
        th, c = (res.x, res.fun) if res.fun <= c0 else (th0, c0)
        if best is None or c < best[0]:
            best = (c, th, n_real)
    _, th, n_real = best
    num, _, den = _solve_num(prep, _poles_from_theta(th, n_real, w_lo, w_hi))
    if not _minimum_phase(num):
        return num, den, np.inf
    # score the model itself (a near-singular basis can look better than the model it adds up
    # to), with its best offset
    sim = LinearSim(num, den, prep.rate_hz, prep.sample_offset)
    es = [(rec.y - sim.run(rec.u))[rec.train] for rec in prep.records if rec.train.any()]
    e = np.concatenate(es)
    e = e - e.mean()
    sse = float(np.einsum('i,i->', e, e))
    return num, den, sse if np.isfinite(sse) else np.inf


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
        Start from ``init_poles`` alone, also on short logs (which otherwise try the ARX
        and spread starts too): for many small changes of the data, as a profile over a
        delay makes.

    Returns
    -------
    num, den : ndarray
        Descending powers of s.
    info : dict
        ``{"order", "nrmse_train", "orders": {n: nrmse}}``.

    Raises
    ------
    BadInputError
        When no order gives a model, or there are no training samples (one line saying so).
    """
    if not any(r.train.any() for r in prep.records):
        raise BadInputError("no training samples to identify a linear model from")
    y = np.concatenate([r.y[r.train] for r in prep.records])
    fits = {}  # nrmse here is with the best offset (the model's own scale of error)
    for n in (orders or range(1, max_order + 1)):
        try:
            with np.errstate(all="ignore"):
                num, den, sse = _fit_order(prep, n, init_poles, warm_only)
        except (np.linalg.LinAlgError, ValueError, BadInputError):
            continue
        if not np.isfinite(sse):
            continue
        fits[n] = (num, den, float(np.sqrt(sse) / np.linalg.norm(y - y.mean())))
    if not fits:
        raise BadInputError("no linear model could be fitted to the log (try a longer log or a richer "
                            "excitation, or give a nominal model)")
    best = min(f[2] for f in fits.values())
    order = min(n for n, f in fits.items() if f[2] <= 1.03 * best + 1e-12)
    num, den, e = fits[order]
    if not np.isfinite(e):
        raise BadInputError("no stable minimum-phase linear model could be fitted to the log (give a nominal "
                            "model)")
    return num, den, {"order": order, "nrmse_train": e, "orders": {n: f[2] for n, f in fits.items()},
                      "method": "internal output-error fit"}

