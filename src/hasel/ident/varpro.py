"""Output-error fit by variable projection: the poles searched, the numerator solved for given poles.

The second mode of the linear identifier (the first is :func:`hasel.ident.timefit.oe_fit`,
a Levenberg-Marquardt fit of every coefficient from a given start). For given poles the
output of any model with those poles is a combination of the modal responses
(:func:`~hasel.ident.timefit.modal_basis`, the same exact ZOH sections that
:func:`~hasel.ident.timefit.simulate_zoh` adds up), so the numerator is solved by least
squares inside the loop and only the poles are searched (Nelder-Mead), from the poles of
an ARX model (:func:`~hasel.ident.timefit.arx_lstsq`, the regression of
:func:`~hasel.ident.timefit.arx_start`) mapped to continuous time and from poles spread
over the excited band. It needs no start model, which is why the diagnosis uses it on
logs given without a nominal model.

One output offset, shared by every segment, is fitted alongside but left out of the
model, which goes through the origin: a log whose output is not zero at zero input then
shows that as a static map with an offset. Right half-plane zeros are penalised in the
search and a model with one is refused (a rational model imitates a dead time with them;
kept minimum-phase, a delay stays visible). The order is the lowest whose training error
is within 3 % of the best.
"""
from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from scipy import optimize

from hasel.errors import BadInputError
from hasel.ident.tffit import TFModel
from hasel.ident.timefit import arx_lstsq, modal_basis, simulate_zoh

__all__ = ["Stretch", "vp_fit"]

#: One stretch of a log: input, output (their own units, one rate) and the samples fitted (bool).
Stretch = tuple[np.ndarray, np.ndarray, np.ndarray]


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
    """The free parameters of :func:`_poles_from_theta` for poles ``p`` (rad/s), and the number of real poles."""
    real = np.sort(np.real(p[np.abs(p.imag) < 1e-9 * np.maximum(1, np.abs(p))]))
    cplx = p[p.imag >= 1e-9 * np.maximum(1, np.abs(p))]
    th = list(np.log(np.maximum(-real - w_lo, 1e-3 * w_lo + 1e-12)))
    for c in cplx:
        wn = abs(c)
        zeta = float(np.clip(-c.real / wn, 0.02, 0.98))
        th += [np.log(max(wn - w_lo, 1e-3 * w_lo + 1e-12)), np.log(zeta / (1 - zeta))]
    return np.asarray(th, float), real.size


def _arx_poles(segments: Sequence[Stretch], n: int, rate_hz: float) -> np.ndarray:
    """``n`` stable continuous poles (rad/s) from an ARX model of the mean-removed segments.

    Poles on or outside the unit circle are pulled inside, a negative real z (no continuous
    counterpart) becomes a fast real pole, a pole on the imaginary axis is moved left.
    """
    segs = [(u - u.mean(), y - y.mean(), m) for u, y, m in segments if m.sum() > 3 * n]
    theta = arx_lstsq(segs, n)
    if theta is None:
        raise ValueError("no segment long enough for an ARX start")
    z = np.roots(np.concatenate([[1.0], theta[:n]]))
    z = np.where(np.abs(z) >= 0.999, 0.999 * z / np.abs(z), z)
    s = np.log(z.astype(complex)) * rate_hz
    # negative real z have no continuous counterpart: take them as fast real poles
    s = np.where((np.abs(z.imag) < 1e-12) & (z.real <= 0), -0.5 * np.pi * rate_hz + 0j, s)
    s = np.where(s.real > -1e-6, -1e-3 * rate_hz + 1j * s.imag, s)
    # keep conjugate pairs consistent
    return np.concatenate([s[np.abs(s.imag) < 1e-9], s[s.imag >= 1e-9], np.conj(s[s.imag >= 1e-9])])


def _modal_poles(poles: np.ndarray) -> np.ndarray:
    """Real poles, then one pole (positive imaginary part) of each conjugate pair."""
    tol = 1e-9 * np.maximum(1.0, np.abs(poles))
    return np.concatenate([np.real(poles[np.abs(poles.imag) <= tol]).astype(complex), poles[poles.imag > tol]])


class _Problem:
    """The segments' fitted samples, with each segment's input minus its first sample kept for the basis."""

    def __init__(self, segments: Sequence[Stretch], rate_hz: float, shift: float):
        self.segments = [(np.asarray(u, float), np.asarray(y, float), np.asarray(m, bool)) for u, y, m in segments
                         if np.any(m)]
        self.rate_hz, self.shift = float(rate_hz), float(shift)
        if not self.segments:
            raise BadInputError("no training samples to identify a linear model from")
        self.y_fit = np.concatenate([y[m] for _, y, m in self.segments])

    def solve_num(self, poles: np.ndarray) -> tuple[np.ndarray, float, np.ndarray]:
        """Best numerator for the given poles (least squares on the fitted samples).

        The output is a combination of the modal responses (partial fractions), so for
        given poles the numerator is linear and found by least squares; an output offset is
        fitted alongside and dropped from the model (the dynamics and the incremental gain
        come out right, and an offset is left for the caller to name).

        Returns the numerator, the SSE on the fitted samples (output unit squared) and the
        denominator (descending powers of s, rad/s).
        """
        poles = np.asarray(poles, complex)
        if not np.all(np.isfinite(poles)):
            raise ValueError("non-finite poles")
        mp = _modal_poles(poles)
        blocks = []
        for u, _, m in self.segments:
            cols = modal_basis(mp, u, self.rate_hz, shift=self.shift)
            B = np.empty((int(np.count_nonzero(m)), len(cols) + 1))
            for j, c in enumerate(cols):
                B[:, j] = c[m]
            B[:, -1] = 1.0
            blocks.append(B)
        A = blocks[0] if len(blocks) == 1 else np.vstack(blocks)
        b = self.y_fit
        scale = np.sqrt(np.einsum("ij,ij->j", A, A))
        scale[scale == 0] = 1.0
        c = np.linalg.lstsq(A / scale, b, rcond=None)[0] / scale
        r = b - A @ c
        return _numerator(mp, c), float(np.einsum('i,i->', r, r)), np.real(np.poly(_all_poles(mp)))

    def model_sse(self, num: np.ndarray, den: np.ndarray) -> float:
        """SSE of the model ``num/den`` itself (simulated from rest at each segment's first input), best offset."""
        model = TFModel(num=np.asarray(num, float), den=np.asarray(den, float))
        g0 = model.dc_gain
        es = [(y - simulate_zoh(model, u - u[0], self.rate_hz, shift=self.shift) - g0 * u[0])[m]
              for u, y, m in self.segments]
        e = np.concatenate(es)
        e = e - e.mean()
        return float(np.einsum('i,i->', e, e))


def _all_poles(mp: np.ndarray) -> np.ndarray:
    """The modal poles with the conjugate of each pair appended."""
    return np.concatenate([mp, np.conj(mp[mp.imag > 0])])


def _numerator(mp: np.ndarray, c: np.ndarray) -> np.ndarray:
    """Numerator (descending powers of s) of the combination ``c`` of :func:`modal_basis`'s columns for ``mp``."""
    full = _all_poles(mp)
    n = full.size
    num = np.zeros(n, complex)
    i = 0
    for k, p in enumerate(mp):
        drop = {k} if p.imag == 0 else {k, mp.size + int(np.sum(mp[:k].imag > 0))}
        # the product of the other factors (s - q), as np.poly forms it, without its checks
        rest = np.ones(1, complex)
        for j, q in enumerate(full):
            if j not in drop:
                rest = np.convolve(rest, np.array([1.0, -q]))
        rest = rest.real   # the other factors are real or in conjugate pairs
        if p.imag == 0:
            term = c[i] * rest
            i += 1
        else:
            term = np.polymul([c[i], -c[i] * p.real + c[i + 1] * p.imag], rest)
            i += 2
        num[n - term.size:] += term
    return np.real(num)


def _rhp_zeros(num: np.ndarray) -> int:
    """Number of zeros of ``num`` in the open right half-plane (zeros on the imaginary axis not counted)."""
    nz = np.trim_zeros(np.asarray(num, float), "f")
    if nz.size <= 1:
        return 0
    z = np.roots(nz)
    return int(np.sum(np.real(z) > 1e-6 * np.maximum(np.abs(z), 1e-12)))


def _fit_order(prob: _Problem, n: int, span_s: float, f_excited_hz: float, init: np.ndarray | None = None,
               warm_only: bool = False) -> tuple[np.ndarray, np.ndarray, float]:
    """The best model of ``n`` poles from each start (Nelder-Mead over the poles), and its own SSE (inf if refused)."""
    rate_hz = prob.rate_hz
    # modes slower than a twentieth of the log are offsets or drifts, not dynamics it can identify
    w_lo = 20.0 / (span_s + 1e-9)
    w_hi = 0.45 * np.pi * rate_hz
    starts = []
    n_train = prob.y_fit.size
    if init is not None and np.asarray(init).size == n:
        starts.append(np.asarray(init, complex))  # a warm start (alone on long logs, to save time)
    if not starts or (n_train < 5000 and not warm_only):
        try:
            starts.append(_arx_poles(prob.segments, n, rate_hz))
        except (np.linalg.LinAlgError, ValueError):
            pass
        w_exc = 2 * np.pi * min(max(f_excited_hz, 1e-6), 0.4 * rate_hz)
        starts.append(-np.geomspace(max(w_lo * 1.5, w_exc / 30.0), max(w_exc, w_lo * 3.0), n) + 0j)
    iters = 30 if (init is not None and n_train >= 5000) else 80

    def make_cost(n_real: int):
        def cost(th: np.ndarray) -> float:
            try:
                num, sse, _ = prob.solve_num(_poles_from_theta(th, n_real, w_lo, w_hi))
            except (np.linalg.LinAlgError, ValueError, StopIteration):
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
    num, _, den = prob.solve_num(_poles_from_theta(th, n_real, w_lo, w_hi))
    if _rhp_zeros(num):
        return num, den, np.inf
    # score the model itself (a near-singular basis can look better than the model it adds up
    # to), with its best offset
    try:
        sse = prob.model_sse(num, den)
    except StopIteration:   # hasel.lti's pairing of (nearly) repeated poles gave up: no usable model
        return num, den, np.inf
    return num, den, sse if np.isfinite(sse) else np.inf


def vp_fit(segments: Sequence[Stretch], rate_hz: float, *, span_s: float, f_excited_hz: float, shift: float = 0.0,
           max_order: int = 4, orders: tuple[int, ...] | None = None, init_poles: np.ndarray | None = None,
           warm_only: bool = False) -> tuple[np.ndarray, np.ndarray, dict]:
    """Identify a stable, strictly proper, minimum-phase continuous model ``num/den`` by variable projection.

    Parameters
    ----------
    segments : sequence of (u, y, mask)
        Input and output samples at ``rate_hz`` (their own units; the input held over each
        interval) and the samples fitted (bool); each segment is simulated from rest at
        its first input, one output offset is shared by all.
    rate_hz : float
        Sample rate, Hz.
    span_s : float
        Length of the log, s: modes slower than ``20 / span_s`` rad/s are not searched.
    f_excited_hz : float
        Upper edge of the input's excited band, Hz (where the spread start's poles go).
    shift : float
        Where the output samples sit in their interval, samples (-1 .. 1), as
        :func:`~hasel.ident.timefit.simulate_zoh`'s ``shift``.
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
        Descending powers of s (s in rad/s), output unit per input unit.
    info : dict
        ``{"order", "nrmse_train", "orders": {n: nrmse}, "method"}`` (NRMSE of the fitted
        samples, with the best offset).

    Raises
    ------
    BadInputError
        When there are no fitted samples, no order gives a model, or the arithmetic fails
        (one line saying so).
    """
    if not (np.isfinite(rate_hz) and rate_hz > 0 and np.isfinite(span_s) and span_s > 0):
        raise BadInputError(f"the linear fit needs a positive rate and log length, got {rate_hz} Hz and {span_s} s")
    if not (np.isfinite(shift) and -1.0 <= shift <= 1.0):
        raise BadInputError(f"the output sampling offset must be within one sample, got {shift}")
    for i, (u, y, m) in enumerate(segments):
        if not (np.ndim(u) == np.ndim(y) == np.ndim(m) == 1 and np.size(u) == np.size(y) == np.size(m) > 0):
            raise BadInputError(f"segment {i} of the linear fit: input, output and mask must be 1-D arrays of one "
                                f"length, got shapes {np.shape(u)}, {np.shape(y)}, {np.shape(m)}")
        if not (np.all(np.isfinite(u)) and np.all(np.isfinite(np.asarray(y)[np.asarray(m, bool)]))):
            raise BadInputError(f"segment {i} of the linear fit has non-finite samples")
    try:
        return _vp_fit(segments, rate_hz, span_s, f_excited_hz, shift, max_order, orders, init_poles, warm_only)
    except (np.linalg.LinAlgError, ValueError) as err:
        if isinstance(err, BadInputError):
            raise
        raise BadInputError(f"the linear fit failed ({type(err).__name__}: {err}); try a longer log or a richer "
                            "excitation, or give a nominal model") from err


def _vp_fit(segments, rate_hz, span_s, f_excited_hz, shift, max_order, orders, init_poles, warm_only):
    prob = _Problem(segments, rate_hz, shift)
    y = prob.y_fit
    spread = float(np.linalg.norm(y - y.mean()))
    if not spread > 0:
        raise BadInputError("the log's output does not vary on the training samples: no linear model can be fitted")
    fits = {}  # nrmse here is with the best offset (the model's own scale of error)
    for n in (orders or range(1, max_order + 1)):
        try:
            with np.errstate(all="ignore"):
                num, den, sse = _fit_order(prob, n, span_s, f_excited_hz, init_poles, warm_only)
        except (np.linalg.LinAlgError, ValueError):
            continue
        if not np.isfinite(sse):
            continue
        fits[n] = (num, den, float(np.sqrt(sse) / spread))
    if not fits:
        raise BadInputError("no linear model could be fitted to the log (try a longer log or a richer "
                            "excitation, or give a nominal model)")
    best = min(f[2] for f in fits.values())
    order = min(n for n, f in fits.items() if f[2] <= 1.03 * best + 1e-12)
    num, den, e = fits[order]
    return num, den, {"order": order, "nrmse_train": e, "orders": {n: f[2] for n, f in fits.items()},
                      "method": "internal output-error fit"}
