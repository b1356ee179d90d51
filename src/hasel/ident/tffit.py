"""Continuous-time transfer-function fit to frequency-response data (like MATLAB ``tfest``).

The model is ``G(s) = B(s) / A(s) * exp(-s tau)``, proper, with every pole in the
open left half-plane. Frequencies are scaled internally (``x = s / w0``, ``w0`` the
highest fitted frequency in rad/s) so the polynomials stay well conditioned from
0.1 to tens of Hz. Each fit has two steps:

1. Sanathanan-Koerner iterations: the weighted linear least-squares problem
   ``min sum |w_i (B(x_i) - H_i A(x_i)) / (H_i A_prev(x_i))|^2`` under a unit-norm
   constraint on the coefficients (smallest singular vector, columns scaled), which
   converges to the relative-error fit; unstable poles are then reflected into the
   left half-plane and the numerator refitted.
2. Non-linear refinement (:func:`scipy.optimize.least_squares`, analytic Jacobian)
   of the log error ``w_i log(G(x_i) / H_i)``, whose real part is the magnitude
   error in nepers and imaginary part the phase error in radians. The denominator is
   a product of ``x^2 + a x + b`` (and one ``x + c``) with ``a, b, c = exp(p)``, so
   every iterate is stable. Weights ``w_i = 1 / max(sigma_i / |H_i|, rel_floor)``
   come from the data's uncertainty (coherence), so the residual is about one per
   point when the model fits to the noise.

The order (numerator and denominator degrees) is chosen on frequencies held out of
the fit: every ``heldout_every``-th point is left out, each candidate order is fitted
to the others, and the simplest order whose held-out error is within ``rel_tol`` of
the best is refitted on all points.
"""
from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass, field

import numpy as np
from scipy import optimize

from hasel.errors import BadInputError

__all__ = ["TFModel", "OrderScore", "TFFit", "fit_tf", "fit_tf_order", "default_orders", "quality"]


@dataclass(frozen=True)
class TFModel:
    """A continuous transfer function ``num(s) / den(s) * exp(-s delay_s)``.

    Attributes
    ----------
    num, den : ndarray
        Coefficients in descending powers of s (s in rad/s); ``den`` is monic.
    delay_s : float
        Input delay, s.
    """

    num: np.ndarray
    den: np.ndarray
    delay_s: float = 0.0

    def freqresp(self, f_hz: np.ndarray) -> np.ndarray:
        """Complex response at the frequencies ``f_hz`` (Hz)."""
        s = 2j * np.pi * np.asarray(f_hz, float)
        return np.polyval(self.num, s) / np.polyval(self.den, s) * np.exp(-s * self.delay_s)

    @property
    def zeros(self) -> np.ndarray:
        """Zeros, rad/s."""
        return np.roots(self.num) if self.num.size > 1 else np.zeros(0, complex)

    @property
    def poles(self) -> np.ndarray:
        """Poles, rad/s."""
        return np.roots(self.den)

    @property
    def gain(self) -> float:
        """Gain ``k`` of the zero-pole-gain form ``k prod(s - z) / prod(s - p)``."""
        return float(self.num[0] / self.den[0])

    @property
    def dc_gain(self) -> float:
        """``G(0)``, output unit per input unit (``inf`` with a pole at 0)."""
        return float(self.num[-1] / self.den[-1]) if self.den[-1] != 0 else float("inf")


@dataclass(frozen=True)
class OrderScore:
    """Held-out score of one candidate order."""

    nz: int
    np: int
    fit_cost: float
    heldout_cost: float


@dataclass(frozen=True)
class TFFit:
    """A fitted transfer function and how well it fits.

    Attributes
    ----------
    model : TFModel
        The fit.
    nz, np : int
        Numerator and denominator degrees.
    cost : float
        Weighted RMS of the log error over the points (about 1 at the noise level).
    rms_db, max_db : float
        RMS and largest magnitude error over points of finite uncertainty, dB.
    rms_deg, max_deg : float
        RMS and largest phase error over the same points, degrees.
    fit_percent : float
        ``100 (1 - ||H - G|| / ||H - mean(H)||)`` over the same points.
    band_hz : (float, float)
        Lowest and highest fitted frequency, Hz.
    scores : list of OrderScore
        The candidates tried (empty when the order was fixed).
    """

    model: TFModel
    nz: int
    np: int
    cost: float
    rms_db: float
    max_db: float
    rms_deg: float
    max_deg: float
    fit_percent: float
    band_hz: tuple[float, float]
    scores: list[OrderScore] = field(default_factory=list)


def default_orders(max_poles: int = 8, max_rel_degree: int | None = None) -> list[tuple[int, int]]:
    """Candidate ``(nz, np)``: ``1 <= np <= max_poles``, ``np - max_rel_degree <= nz <= np``."""
    out = []
    for n_p in range(1, max_poles + 1):
        lo = 0 if max_rel_degree is None else max(0, n_p - max_rel_degree)
        out.extend((n_z, n_p) for n_z in range(lo, n_p + 1))
    return out


# -- internals --------------------------------------------------------------------------------------

@dataclass
class _Data:
    x: np.ndarray       # j w / w0
    H: np.ndarray
    w: np.ndarray       # weights of the log error
    w0: float
    _pow: np.ndarray | None = None

    @property
    def log_pmin(self) -> float:
        """Log of the smallest pole magnitude allowed (scaled): a twentieth of the lowest frequency."""
        return float(np.log(0.05 * np.min(np.abs(self.x))))

    def powers(self, n: int) -> np.ndarray:
        """``x[:, None] ** arange(n)``, cached."""
        if self._pow is None or self._pow.shape[1] < n:
            self._pow = self.x[:, None] ** np.arange(max(n, 10))
        return self._pow[:, :n]


def _sk(d: _Data, nz: int, n_p: int, iters: int = 12) -> tuple[np.ndarray, np.ndarray]:
    """Sanathanan-Koerner: ascending coefficients (b, a) in x."""
    x, H = d.x, d.H
    Vb = d.powers(nz + 1)
    Va = d.powers(n_p + 1)
    rel = d.w / np.abs(H)
    a_prev = np.ones(x.size, complex)
    b = a = None
    for _ in range(iters):
        wt = rel / np.abs(a_prev)
        M = np.hstack([Vb, -H[:, None] * Va]) * wt[:, None]
        R = np.vstack([M.real, M.imag])
        scale = np.linalg.norm(R, axis=0)
        scale[scale == 0] = 1.0
        _, _, vt = np.linalg.svd(R / scale, full_matrices=False)
        theta = vt[-1] / scale
        b, a = theta[: nz + 1], theta[nz + 1:]
        a_new = Va @ a
        if not np.all(np.isfinite(a_new)) or np.any(a_new == 0):
            break
        if np.allclose(np.abs(a_new) / np.max(np.abs(a_new)), np.abs(a_prev) / np.max(np.abs(a_prev)),
                       rtol=1e-6, atol=1e-9):
            a_prev = a_new
            break
        a_prev = a_new
    assert b is not None and a is not None
    return b, a


def _stable_den(a_asc: np.ndarray) -> np.ndarray:
    """Monic ascending denominator with the roots of ``a_asc`` reflected into Re < 0."""
    a = np.trim_zeros(a_asc[::-1], "f")
    roots = np.roots(a) if a.size > 1 else np.zeros(0)
    n_p = a_asc.size - 1
    roots = np.where(np.real(roots) > 0, -np.conj(roots), roots)
    roots = np.where(np.abs(np.real(roots)) < 1e-6 * np.maximum(np.abs(roots), 1e-3),
                     roots - 1e-6 * np.maximum(np.abs(roots), 1e-3), roots)
    # degree lost in the fit: poles far above the band
    roots = np.concatenate([roots, -1e3 * np.ones(n_p - roots.size)])
    return np.real(np.poly(roots))[::-1]


def _num_ls(d: _Data, nz: int, a_asc: np.ndarray) -> np.ndarray:
    """Numerator (ascending) minimising the relative error for a fixed denominator."""
    A = d.powers(a_asc.size) @ a_asc
    Vb = d.powers(nz + 1)
    wt = d.w / np.abs(d.H)
    M = Vb / A[:, None] * wt[:, None]
    rhs = d.H * wt
    R = np.vstack([M.real, M.imag])
    r = np.concatenate([rhs.real, rhs.imag])
    scale = np.linalg.norm(R, axis=0)
    scale[scale == 0] = 1.0
    sol = np.linalg.lstsq(R / scale, r, rcond=None)[0]
    return sol / scale


def _den_to_params(a_asc: np.ndarray) -> np.ndarray:
    roots = np.roots(a_asc[::-1]) if a_asc.size > 1 else np.zeros(0)
    roots = np.where(np.real(roots) >= 0, -np.abs(roots) - 1e-9, roots)
    cplx = roots[np.imag(roots) > 1e-12 * np.maximum(np.abs(roots), 1.0)]
    real = np.sort(-np.real(roots[np.abs(np.imag(roots)) <= 1e-12 * np.maximum(np.abs(roots), 1.0)]))
    quads = [(-2.0 * np.real(p), np.abs(p) ** 2) for p in cplx]
    i = 0
    while i + 1 < real.size:
        quads.append((real[i] + real[i + 1], real[i] * real[i + 1]))
        i += 2
    params = [np.log(max(v, 1e-12)) for q in quads for v in q]
    if i < real.size:
        params.append(np.log(max(real[i], 1e-12)))
    return np.array(params, float)


def _eval(theta: np.ndarray, d: _Data, nz: int, n_p: int, delay: bool):
    """log G(x) and its Jacobian (complex)."""
    with np.errstate(all="ignore"):
        return _eval_raw(_clip_theta(theta, nz, n_p, d.log_pmin), d, nz, n_p, delay)


#: Bounds of the log-parameters of the denominator (scaled frequency).
_LOG_MIN, _LOG_MAX = np.log(1e-12), np.log(1e12)


def _clip_theta(theta: np.ndarray, nz: int, n_p: int, log_pmin: float) -> np.ndarray:
    """Keep the denominator finite and every pole at least ``exp(log_pmin)`` from s = 0.

    Data say nothing about poles far below their lowest frequency; unbounded, a fit may
    put a pole pair near 0 whose effect cancels in band and wrecks the static gain.
    """
    out = np.array(theta, float)
    den = out[nz + 1: nz + 1 + n_p]
    den[:] = np.clip(den, _LOG_MIN, _LOG_MAX)
    nq = n_p // 2
    den[1:2 * nq:2] = np.maximum(den[1:2 * nq:2], 2.0 * log_pmin)   # b = |p|^2 of each x^2 + a x + b
    if n_p % 2:
        den[2 * nq] = max(den[2 * nq], log_pmin)                      # c of x + c
    return out


def _eval_raw(theta: np.ndarray, d: _Data, nz: int, n_p: int, delay: bool):
    x = d.x
    b = theta[: nz + 1]
    nq = n_p // 2
    pq = theta[nz + 1: nz + 1 + 2 * nq]
    alpha, beta = np.exp(pq[0::2]), np.exp(pq[1::2])
    k = nz + 1 + 2 * nq
    gamma = np.exp(theta[k]) if n_p % 2 else None
    k += n_p % 2
    tau = theta[k] if delay else 0.0
    Vb = d.powers(nz + 1)
    B = Vb @ b
    Q = x[:, None] ** 2 + alpha * x[:, None] + beta
    logA = np.sum(np.log(Q), axis=1)
    cols = [Vb / B[:, None], -(alpha * x[:, None]) / Q, -beta / Q]
    if gamma is not None:
        logA = logA + np.log(x + gamma)
        cols_g = [-(gamma / (x + gamma))[:, None]]
    else:
        cols_g = []
    # interleave alpha/beta columns as in theta
    J = np.empty((x.size, theta.size), complex)
    J[:, : nz + 1] = cols[0]
    J[:, nz + 1: nz + 1 + 2 * nq: 2] = cols[1]
    J[:, nz + 2: nz + 1 + 2 * nq: 2] = cols[2]
    if cols_g:
        J[:, nz + 1 + 2 * nq] = cols_g[0][:, 0]
    if delay:
        J[:, -1] = -x
    logG = np.log(B) - logA - x * tau
    return logG, J


def _residual(theta, d, nz, n_p, delay):
    logG, _ = _eval(theta, d, nz, n_p, delay)
    with np.errstate(all="ignore"):
        e = np.log(np.exp(logG) / d.H)  # principal branch of the ratio: no 2 pi jumps
    e = np.where(np.isfinite(e), e, 50.0)
    r = d.w * e
    return np.concatenate([r.real, r.imag])


def _jac(theta, d, nz, n_p, delay):
    _, J = _eval(theta, d, nz, n_p, delay)
    Jw = J * d.w[:, None]
    Jw = np.where(np.isfinite(Jw), Jw, 0.0)
    return np.vstack([Jw.real, Jw.imag])


def _theta_to_tf(theta: np.ndarray, nz: int, n_p: int, delay: bool, w0: float, log_pmin: float) -> TFModel:
    theta = _clip_theta(theta, nz, n_p, log_pmin)
    b = theta[: nz + 1]
    nq = n_p // 2
    pq = theta[nz + 1: nz + 1 + 2 * nq]
    den = np.array([1.0])
    for al, be in zip(np.exp(pq[0::2]), np.exp(pq[1::2])):
        den = np.polymul(den, [1.0, al, be])
    k = nz + 1 + 2 * nq
    if n_p % 2:
        den = np.polymul(den, [1.0, np.exp(theta[k])])
        k += 1
    tau = float(theta[k]) / w0 if delay else 0.0
    # x = s / w0: coefficient of x^k -> s^k / w0^k; then make den monic in s
    num_s = b[::-1] / w0 ** np.arange(nz, -1, -1)
    den_s = den / w0 ** np.arange(n_p, -1, -1)
    lead = den_s[0]
    return TFModel(num=np.asarray(num_s / lead, float), den=np.asarray(den_s / lead, float), delay_s=tau)


def _fit(d: _Data, nz: int, n_p: int, delay: bool, max_nfev: int) -> tuple[np.ndarray, float]:
    b, a = _sk(d, nz, n_p)
    a = _stable_den(a)
    b = _num_ls(d, nz, a)
    theta = np.concatenate([b, _den_to_params(a)] + ([np.zeros(1)] if delay else []))
    if delay:
        res = optimize.least_squares(_residual, theta, jac=_jac, args=(d, nz, n_p, True), method="trf",
                                     bounds=(np.r_[np.full(theta.size - 1, -np.inf), 0.0], np.inf),
                                     x_scale="jac", max_nfev=max_nfev)
    else:
        res = optimize.least_squares(_residual, theta, jac=_jac, args=(d, nz, n_p, False), method="lm",
                                     x_scale="jac", max_nfev=max_nfev)
    theta = res.x if np.all(np.isfinite(res.fun)) else theta
    r = _residual(theta, d, nz, n_p, delay)
    return theta, float(np.sqrt(np.mean(r[: r.size // 2] ** 2 + r[r.size // 2:] ** 2)))


def _prepare(f_hz, H, sigma, rel_floor) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    f = np.asarray(f_hz, float)
    Hc = np.asarray(H, complex)
    if f.ndim != 1 or f.shape != Hc.shape:
        raise BadInputError(f"f_hz and H must be 1-D arrays of the same length, got {f.shape} and {Hc.shape}")
    if sigma is None:
        rel = np.full(f.size, rel_floor)
    else:
        s = np.asarray(sigma, float)
        if s.shape != f.shape:
            raise BadInputError(f"sigma must have the shape of f_hz {f.shape}, got {s.shape}")
        with np.errstate(divide="ignore", invalid="ignore"):
            rel = np.maximum(s / np.abs(Hc), rel_floor)
    ok = np.isfinite(f) & (f > 0) & np.isfinite(Hc) & (np.abs(Hc) > 0) & np.isfinite(rel)
    if np.count_nonzero(ok) < 4:
        raise BadInputError(f"need at least 4 usable frequency points to fit a transfer function, got "
                            f"{np.count_nonzero(ok)}")
    order = np.argsort(f[ok])
    return f[ok][order], Hc[ok][order], (1.0 / rel[ok])[order]


def _quality(model: TFModel, f: np.ndarray, H: np.ndarray, w: np.ndarray, nz: int, n_p: int, cost: float,
             scores: list[OrderScore]) -> TFFit:
    G = model.freqresp(f)
    with np.errstate(all="ignore"):
        e = np.log(G / H)
    db = 20.0 / np.log(10.0) * np.real(e)
    deg = np.degrees(np.imag(e))
    fit = 100.0 * (1.0 - np.linalg.norm(H - G) / np.linalg.norm(H - np.mean(H)))
    return TFFit(model=model, nz=nz, np=n_p, cost=cost, rms_db=float(np.sqrt(np.mean(db**2))),
                 max_db=float(np.max(np.abs(db))), rms_deg=float(np.sqrt(np.mean(deg**2))),
                 max_deg=float(np.max(np.abs(deg))), fit_percent=float(fit),
                 band_hz=(float(f[0]), float(f[-1])), scores=scores)


def quality(model: TFModel, resp, nz: int, n_p: int, cost: float, scores: list[OrderScore], *,
            rel_floor: float = 0.003) -> TFFit:
    """A :class:`TFFit` for a given ``model`` against a measured response ``resp`` (a FreqResp).

    ``cost`` and ``scores`` are stored as given; the dB, degree and percent errors are
    computed over ``resp``'s points of finite uncertainty.
    """
    f, Hc, w = _prepare(resp.f_hz, resp.H, resp.sigma, rel_floor)
    return _quality(model, f, Hc, w, nz, n_p, cost, scores)


def fit_tf_order(f_hz: np.ndarray, H: np.ndarray, nz: int, np_: int, *, sigma: np.ndarray | None = None,
                 delay: bool = False, rel_floor: float = 0.003, max_nfev: int = 400) -> TFFit:
    """Fit ``B(s)/A(s) [exp(-s tau)]`` of fixed degrees to a frequency response.

    Parameters
    ----------
    f_hz : ndarray, shape (n,)
        Frequencies, Hz (> 0).
    H : ndarray of complex, shape (n,)
        Measured response, output unit per input unit.
    nz, np_ : int
        Numerator and denominator degrees (``0 <= nz <= np_``, ``np_ >= 1``).
    sigma : ndarray, shape (n,), optional
        Standard deviation of ``H`` (complex), as :class:`~hasel.ident.freqresp.FreqResp`
        gives; points with ``inf`` are ignored. Default: equal weights.
    delay : bool
        Fit an input delay ``tau >= 0`` too.
    rel_floor : float
        Smallest relative uncertainty used in the weights, so that a few very clean
        points do not dominate the fit.
    max_nfev : int
        Budget of the non-linear refinement.

    Returns
    -------
    TFFit
    """
    if not (0 <= nz <= np_ and np_ >= 1):
        raise BadInputError(f"need 0 <= nz <= np and np >= 1 (a proper model), got nz={nz}, np={np_}")
    f, Hc, w = _prepare(f_hz, H, sigma, rel_floor)
    w0 = 2.0 * np.pi * f[-1]
    d = _Data(x=1j * 2.0 * np.pi * f / w0, H=Hc, w=w, w0=w0)
    theta, cost = _fit(d, nz, np_, delay, max_nfev)
    return _quality(_theta_to_tf(theta, nz, np_, delay, w0, d.log_pmin), f, Hc, w, nz, np_, cost, [])


def fit_tf(f_hz: np.ndarray, H: np.ndarray, *, sigma: np.ndarray | None = None,
           orders: Iterable[tuple[int, int]] | None = None, max_poles: int = 8, delay: bool = False,
           heldout_every: int = 3, rel_tol: float = 0.1, rel_floor: float = 0.003,
           max_nfev: int = 400, patience: int = 2, adequate: float = 1.0) -> TFFit:
    """Fit a stable transfer function, choosing its order on held-out frequencies.

    Parameters
    ----------
    f_hz, H, sigma :
        As for :func:`fit_tf_order`.
    orders : iterable of (int, int), optional
        Candidate ``(nz, np)``; default :func:`default_orders` up to ``max_poles``.
    max_poles : int
        Highest denominator degree tried by default.
    delay : bool
        Fit an input delay too.
    heldout_every : int
        Every ``heldout_every``-th frequency (from the second) is held out of the
        fit that scores a candidate (>= 2).
    rel_tol : float
        The simplest candidate (fewest parameters, then fewest poles) whose held-out
        cost is within ``(1 + rel_tol)`` times the best, or at most ``adequate``, is
        chosen.
    adequate : float
        Held-out cost that counts as fitting the data: about 1 means errors at the
        level of the data's uncertainty (or of ``rel_floor``).
    rel_floor, max_nfev :
        As for :func:`fit_tf_order`.
    patience : int
        Denominator degrees are tried in increasing order; the search stops after
        ``patience`` degrees in a row that did not lower the best held-out cost by
        ``rel_tol``.

    Returns
    -------
    TFFit
        The chosen order refitted on all points, with the scores of every candidate.
    """
    f, Hc, w = _prepare(f_hz, H, sigma, rel_floor)
    if heldout_every < 2:
        raise BadInputError(f"heldout_every must be >= 2, got {heldout_every}")
    cands = list(orders) if orders is not None else default_orders(max_poles)
    if not cands:
        raise BadInputError("no candidate orders given")
    w0 = 2.0 * np.pi * f[-1]
    x = 1j * 2.0 * np.pi * f / w0
    held = np.zeros(f.size, bool)
    held[1::heldout_every] = True
    d_fit = _Data(x=x[~held], H=Hc[~held], w=w[~held], w0=w0)
    d_held = _Data(x=x[held], H=Hc[held], w=w[held], w0=w0)
    n_fit = int(np.count_nonzero(~held))
    for nz, n_p in cands:
        if not (0 <= nz <= n_p and n_p >= 1):
            raise BadInputError(f"candidate order must have 0 <= nz <= np and np >= 1, got ({nz}, {n_p})")
    scores: list[OrderScore] = []
    best_so_far, stale = np.inf, 0
    for n_p in sorted({c[1] for c in cands}):
        level_best = np.inf
        for nz in sorted(c[0] for c in cands if c[1] == n_p):
            if 2 * n_fit <= nz + 1 + n_p + int(delay):
                continue
            theta, cost = _fit(d_fit, nz, n_p, delay, min(max_nfev, 60))
            r = _residual(theta, d_held, nz, n_p, delay)
            held_cost = float(np.sqrt(np.mean(r[: r.size // 2] ** 2 + r[r.size // 2:] ** 2)))
            scores.append(OrderScore(nz=nz, np=n_p, fit_cost=cost, heldout_cost=held_cost))
            level_best = min(level_best, held_cost)
        # stop once more poles have not helped for `patience` denominator degrees
        if level_best < (1.0 - rel_tol) * best_so_far:
            stale = 0
        else:
            stale += 1
        best_so_far = min(best_so_far, level_best)
        if stale >= patience or best_so_far <= adequate / 2:
            break
    if not scores:
        raise BadInputError(f"too few frequency points ({f.size}) for any candidate order")
    best = min(s.heldout_cost for s in scores)
    ok = [s for s in scores if s.heldout_cost <= max((1.0 + rel_tol) * best, adequate)]
    choice = min(ok, key=lambda s: (s.nz + s.np, s.np))
    d_all = _Data(x=x, H=Hc, w=w, w0=w0)
    theta, cost = _fit(d_all, choice.nz, choice.np, delay, max_nfev)
    model = _theta_to_tf(theta, choice.nz, choice.np, delay, w0, d_all.log_pmin)
    return _quality(model, f, Hc, w, choice.nz, choice.np, cost, scores)
