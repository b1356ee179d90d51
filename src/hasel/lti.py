"""Linear time-invariant blocks: exact zero-order-hold discretisation and stateful filtering.

A continuous transfer function driven by an input that is constant over each sample
period is integrated exactly by its zero-order-hold (ZOH) discretisation; that is how
the simulator steps P(s) at 10 kHz (no Euler error). Discrete systems are kept as
second-order sections, which stay well conditioned for the lightly damped, repeated
poles of P(s) where a single high-order polynomial would not.
"""
from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from scipy import linalg, signal

from hasel.errors import BadInputError
from hasel.validate import positive

__all__ = ["zoh_sos", "ZohAt", "butter2_analog", "critical2_analog", "SosFilter", "tf_freqresp", "is_stable"]


def _as_coeffs(name: str, c: Sequence[float] | np.ndarray) -> np.ndarray:
    arr = np.atleast_1d(np.asarray(c, dtype=float))
    if arr.ndim != 1 or arr.size == 0 or not np.all(np.isfinite(arr)):
        raise BadInputError(f"{name} must be a non-empty 1-D array of finite numbers, got {c!r}")
    return np.trim_zeros(arr, "f") if np.any(arr) else arr


def _pair(roots: np.ndarray) -> list[np.ndarray]:
    """Group roots into conjugate pairs and pairs of reals (at most one single left)."""
    roots = np.asarray(roots, complex)
    cplx = roots[np.imag(roots) > 1e-9 * np.maximum(1.0, np.abs(roots))]
    real = np.sort(np.real(roots[np.abs(np.imag(roots)) <= 1e-9 * np.maximum(1.0, np.abs(roots))]))
    groups = [np.array([r, np.conj(r)]) for r in cplx]
    groups += [real[i:i + 2].astype(complex) for i in range(0, real.size, 2)]
    return groups


def _clean_roots(roots: np.ndarray) -> np.ndarray:
    """Make near-real roots exactly real and complex ones exact conjugate pairs."""
    roots = np.asarray(roots, complex)
    tol = 1e-9 * np.maximum(1.0, np.abs(roots))
    real = np.real(roots[np.abs(np.imag(roots)) <= tol])
    upper = roots[np.imag(roots) > tol]
    return np.concatenate([real.astype(complex), upper, np.conj(upper)])


def _series_ss(z: np.ndarray, p: np.ndarray, k: float) -> tuple[np.ndarray, ...]:
    """A well-conditioned state space of zpk: a series of first/second-order sections."""
    pole_groups = _pair(p)
    zero_groups = _pair(z)
    # spread the zeros over the sections so that each section stays proper
    zeros_for: list[list[complex]] = [[] for _ in pole_groups]
    flat_z = [zz for g in zero_groups for zz in g]
    i = 0
    for gi, pg in enumerate(pole_groups):
        while len(zeros_for[gi]) < len(pg) and i < len(flat_z):
            # keep conjugates together
            zeros_for[gi].append(flat_z[i])
            i += 1
    if i < len(flat_z):
        raise BadInputError("the transfer function must be proper (deg num <= deg den)")
    A = np.zeros((0, 0)); B = np.zeros((0, 1)); C = np.zeros((1, 0)); D = np.array([[k]])
    for pg, zg in zip(pole_groups, zeros_for):
        den = np.real(np.poly(pg))
        num = np.real(np.poly(zg)) if zg else np.array([1.0])
        num = np.concatenate([np.zeros(den.size - num.size), num])
        n = den.size - 1
        a = np.zeros((n, n)); a[0, :] = -den[1:]
        if n > 1:
            a[1:, :-1] = np.eye(n - 1)
        b = np.zeros((n, 1)); b[0, 0] = 1.0
        d = num[0]
        c = (num[1:] - d * den[1:]).reshape(1, n)
        # series: previous (A,B,C,D) feeds this section
        m = A.shape[0]
        A = np.block([[A, np.zeros((m, n))], [b @ C, a]])
        B = np.vstack([B, b @ D])
        C = np.hstack([d * C, c])
        D = d * D
    return A, B, C, D


def _ss_zeros(A: np.ndarray, B: np.ndarray, C: np.ndarray, D: np.ndarray) -> np.ndarray:
    """Finite invariant zeros of a SISO state space, from the Rosenbrock pencil."""
    n = A.shape[0]
    M = np.block([[A, B], [C, D]])
    N = np.zeros_like(M); N[:n, :n] = np.eye(n)
    w = linalg.eigvals(M, N)
    return w[np.isfinite(w) & (np.abs(w) < 1e12)]


def zoh_sos(num: Sequence[float], den: Sequence[float], dt_s: float, *,
            output: str = "start") -> np.ndarray:
    """Exact ZOH discretisation of ``num(s)/den(s)`` as second-order sections.

    The continuous system is realised as a series of low-order sections (well
    conditioned), discretised by the matrix exponential, and its discrete zeros are
    taken from the system pencil rather than from a polynomial, so lightly damped,
    repeated and widely spread poles (as in P(s) with the 500 Hz amplifier) keep
    their accuracy.

    Parameters
    ----------
    num, den : array_like
        Coefficients in descending powers of s (units of the system, s in rad/s).
    dt_s : float
        Sample period, seconds.
    output : {"start", "end"}
        ``"start"``: output n is the continuous output at t_n, when input n starts
        (the usual discretisation; a strictly proper system then has a one-sample
        delay). ``"end"``: output n is the output at t_{n+1}, after input n has been
        held for one period (strictly proper systems only). A simulator stepping in
        blocks uses ``"end"`` so that a block's last sample lands on the next tick.

    Returns
    -------
    sos : ndarray, shape (n_sections, 6)
        For :func:`scipy.signal.sosfilt`.
    """
    dt_s = positive("dt_s", dt_s)
    if output not in ("start", "end"):
        raise BadInputError(f"output must be 'start' or 'end', got {output!r}")
    num_a, den_a = _as_coeffs("num", num), _as_coeffs("den", den)
    if num_a.size > den_a.size:
        raise BadInputError("the transfer function must be proper (deg num <= deg den)")
    if output == "end" and num_a.size == den_a.size:
        raise BadInputError("output='end' needs a strictly proper transfer function")
    z, p, k = signal.tf2zpk(num_a, den_a)
    A, B, C, D = _series_ss(z, p, float(k))
    n = A.shape[0]
    M = np.zeros((n + 1, n + 1)); M[:n, :n] = A; M[:n, n:] = B
    E = linalg.expm(M * dt_s)
    Ad, Bd = E[:n, :n], E[:n, n:]
    if output == "end":  # y_end[n] = C x[n+1] = C Ad x[n] + C Bd u[n]
        C, D = C @ Ad, C @ Bd
    pd = linalg.eigvals(Ad)
    zd = _ss_zeros(Ad, Bd, C, D)
    zd, pd = _clean_roots(zd), _clean_roots(pd)
    # the gain, by matching the state space at DC (z = 1), or at a generic point when a
    # zero or pole sits at z = 1 (s = 0) and leaves nothing to match there
    near_one = np.concatenate([zd, pd])
    z0 = 1.0 if near_one.size == 0 or np.min(np.abs(1.0 - near_one)) > 1e-9 else 1.7 + 0.3j
    g0 = (C @ np.linalg.solve(z0 * np.eye(n) - Ad, Bd) + D)[0, 0]
    kd = float(np.real(g0 * np.prod(z0 - pd) / np.prod(z0 - zd)))
    sos = signal.zpk2sos(zd, pd, kd)
    # zpk2sos pads missing zeros with zeros at z = 0, which would advance the output;
    # the discrete system has its relative degree as pure delay, so shift those sections.
    for _ in range(pd.size - zd.size):
        i = next(i for i in range(sos.shape[0]) if sos[i, 2] == 0.0 and sos[i, 0] != 0.0)
        sos[i, :3] = [0.0, sos[i, 0], sos[i, 1]]
    return sos


class ZohAt:
    """Exact zero-order-hold discretisations of one ``num(s)/den(s)`` with the output read inside the interval.

    For an input held over each sample interval ``[t_k, t_k + dt_s)`` the state-space solution
    gives the output a fraction ``a`` of the period into the interval exactly:
    ``y(t_k + a dt_s) = C e^{A a dt_s} x_k + (C Gamma(a) + D) u_k`` with
    ``Gamma(a) = int_0^{a dt_s} e^{A s} ds B``. :meth:`parts` returns it as a strictly proper
    discrete system of ``u`` (second-order sections, the ``x_k`` part, built like
    :func:`zoh_sos` ``output="start"``) plus a direct gain (the ``u_k`` part): no interpolation
    between interval starts. The realisation and the period's exponential are built once per
    model; each fraction costs one small matrix exponential and the discrete zeros.

    Parameters
    ----------
    num, den : array_like
        Coefficients in descending powers of s (s in rad/s).
    dt_s : float
        Sample period, s.
    """

    def __init__(self, num: Sequence[float], den: Sequence[float], dt_s: float) -> None:
        dt_s = positive("dt_s", dt_s)
        num_a, den_a = _as_coeffs("num", num), _as_coeffs("den", den)
        if num_a.size > den_a.size:
            raise BadInputError("the transfer function must be proper (deg num <= deg den)")
        z, p, k = signal.tf2zpk(num_a, den_a)
        A, B, C, D = _series_ss(z, p, float(k))
        n = A.shape[0]
        M = np.zeros((n + 1, n + 1)); M[:n, :n] = A; M[:n, n:] = B
        self._M, self._C, self._D, self._n = M * dt_s, C, float(D[0, 0]), n
        self._sizes = [len(g) for g in _pair(p)]   # the sections of _series_ss, in its order
        if n:
            E = linalg.expm(self._M)
            self._Ad, self._Bd = E[:n, :n], E[:n, n:]
            self._pd = _clean_roots(linalg.eigvals(self._Ad))

    def rows(self, a: float) -> tuple[np.ndarray, float]:
        """``(c, d)``: ``y(t_k + a dt_s) = c . x_k + d u_k`` for ``0 <= a <= 1`` (``x_k`` from :meth:`states`)."""
        n = self._n
        if n == 0:
            return np.zeros(0), self._D
        Ea = linalg.expm(self._M * float(a))
        return (self._C @ Ea[:n, :n])[0], float((self._C @ Ea[:n, n:])[0, 0]) + self._D

    def rows_grid(self, a0: float, step: float, count: int) -> tuple[np.ndarray, np.ndarray]:
        """:meth:`rows` at ``a0 + j step`` (``j = 0 .. count-1``, all within [0, 1]): ``(c`` shape ``(count, n)``, ``d``
        shape ``(count,))``, by repeated products with one step's exponential (two matrix exponentials in all)."""
        n = self._n
        if n == 0:
            return np.zeros((count, 0)), np.full(count, self._D)
        r = np.concatenate([self._C[0], [0.0]]) @ linalg.expm(self._M * float(a0))
        Es = linalg.expm(self._M * float(step))
        out = np.empty((count, n + 1))
        for j in range(count):
            out[j] = r
            r = r @ Es
        return out[:, :n], out[:, n] + self._D

    def states(self, u: np.ndarray) -> np.ndarray:
        """The realisation's states ``x_k`` at the interval starts, shape ``(len(u), n)``, at rest with ``u[0]`` before.

        The realisation is a series of first- and second-order sections, so its discrete state
        matrix is block lower triangular: each section's states are filtered (second order at
        most, :func:`scipy.signal.lfilter`) from ``u`` and the states of the sections before it.
        Any output fraction is then ``x_k . c + d u_k`` (:meth:`rows`) at the cost of one small
        matrix exponential.
        """
        u = np.asarray(u, float)
        n = self._n
        X = np.zeros((u.size, n))
        if n == 0 or u.size == 0:
            return X
        Ad, Bd = self._Ad, self._Bd[:, 0]
        du = u - u[0]   # deviations from the rest at u[0], from a zero state
        i0 = 0
        for size in self._sizes:
            sl = slice(i0, i0 + size)
            g = np.outer(du, Bd[sl])
            if i0:
                g += X[:, :i0] @ Ad[sl, :i0].T
            F = Ad[sl, sl]
            if size == 1:   # x[k+1] = f x[k] + g[k]
                X[:, i0] = signal.lfilter([0.0, 1.0], [1.0, -F[0, 0]], g[:, 0])
            else:           # x[k+1] = F x[k] + g[k]: adj(zI - F) / det(zI - F)
                a = [1.0, -(F[0, 0] + F[1, 1]), F[0, 0] * F[1, 1] - F[0, 1] * F[1, 0]]
                X[:, i0] = (signal.lfilter([0.0, 1.0, -F[1, 1]], a, g[:, 0])
                            + signal.lfilter([0.0, 0.0, F[0, 1]], a, g[:, 1]))
                X[:, i0 + 1] = (signal.lfilter([0.0, 0.0, F[1, 0]], a, g[:, 0])
                                + signal.lfilter([0.0, 1.0, -F[0, 0]], a, g[:, 1]))
            i0 += size
        return X + np.linalg.solve(np.eye(n) - Ad, Bd) * u[0]

    def _strict_sos(self, Ca: np.ndarray) -> np.ndarray:
        """Sections of the strictly proper discrete system ``(Ad, Bd, Ca, 0)``."""
        n = self._n
        Ad, Bd, pd = self._Ad, self._Bd, self._pd
        zd = _clean_roots(_ss_zeros(Ad, Bd, Ca, np.zeros((1, 1))))
        near_one = np.concatenate([zd, pd])
        z0 = 1.0 if near_one.size == 0 or np.min(np.abs(1.0 - near_one)) > 1e-9 else 1.7 + 0.3j
        g0 = (Ca @ np.linalg.solve(z0 * np.eye(n) - Ad, Bd))[0, 0]
        kd = float(np.real(g0 * np.prod(z0 - pd) / np.prod(z0 - zd)))
        sos = signal.zpk2sos(zd, pd, kd)
        for _ in range(pd.size - zd.size):   # relative degree as delay, as in zoh_sos
            i = next(i for i in range(sos.shape[0]) if sos[i, 2] == 0.0 and sos[i, 0] != 0.0)
            sos[i, :3] = [0.0, sos[i, 0], sos[i, 1]]
        return sos

    def parts(self, a: float) -> tuple[np.ndarray | None, float]:
        """``(sos, d)``: ``y(t_k + a dt_s) = sosfilt(sos, u)[k] + d u[k]`` for ``0 <= a <= 1`` (working samples).

        ``sos`` (for :func:`scipy.signal.sosfilt`, output unit per input unit) is ``None`` for a
        static gain; ``d`` is the direct gain ``C Gamma(a) + D``. At ``a = 0`` this is the
        interval-start discretisation; at ``a = 1`` the output after the whole hold.
        """
        a = float(a)
        if not 0.0 <= a <= 1.0:
            raise BadInputError(f"the fraction of the interval must be within [0, 1], got {a}")
        n = self._n
        if n == 0:
            return None, self._D
        c, d = self.rows(a)
        return self._strict_sos(c.reshape(1, -1)), d


def critical2_analog(cutoff_hz: float) -> tuple[np.ndarray, np.ndarray]:
    """Unity-gain 2nd-order low-pass with a double real pole, -3 dB at ``cutoff_hz`` (analog).

    H(s) = a^2 / (s + a)^2 with a = wc / sqrt(sqrt(2) - 1). Its impulse response is
    non-negative, so its output always lies between the smallest and the largest
    input it has seen: it cannot overshoot.
    """
    a = 2.0 * np.pi * positive("cutoff_hz", cutoff_hz) / np.sqrt(np.sqrt(2.0) - 1.0)
    return np.array([a * a]), np.array([1.0, 2.0 * a, a * a])


def butter2_analog(cutoff_hz: float) -> tuple[np.ndarray, np.ndarray]:
    """Unity-gain 2nd-order Butterworth low-pass, analog: (num, den) in s (rad/s)."""
    wc = 2.0 * np.pi * positive("cutoff_hz", cutoff_hz)
    return np.array([wc * wc]), np.array([1.0, np.sqrt(2.0) * wc, wc * wc])


class SosFilter:
    """A discrete filter in second-order sections that keeps its state between calls.

    Parameters
    ----------
    sos : ndarray, shape (n, 6)
        Sections as from :func:`scipy.signal.butter` or :func:`zoh_sos`.
    """

    def __init__(self, sos: np.ndarray) -> None:
        self.sos = np.asarray(sos, dtype=float)
        self._zi_unit = signal.sosfilt_zi(self.sos)  # steady state for a unit constant input
        self.dc_gain = float(np.prod(self.sos[:, :3].sum(axis=1) / self.sos[:, 3:].sum(axis=1)))
        self.zi = np.zeros_like(self._zi_unit)
        self._maps: dict[int, tuple[np.ndarray, ...]] = {}

    def reset(self, u0: float = 0.0) -> None:
        """Put the filter at rest for a constant input ``u0`` held forever."""
        self.zi = self._zi_unit * float(u0)

    def _block_maps(self, n: int) -> tuple[np.ndarray, ...]:
        """Linear maps of an n-sample block with a constant input u, found once by
        running the filter itself on each state basis vector and on a unit input:
        y = Y_zi @ zi + y_u * u and zi' = Z_zi @ zi + z_u * u (exact, by linearity)."""
        maps = self._maps.get(n)
        if maps is None:
            k = self.zi.size
            Y = np.empty((n, k))
            Z = np.empty((k, k))
            for j in range(k):
                e = np.zeros(k)
                e[j] = 1.0
                y, zf = signal.sosfilt(self.sos, np.zeros(n), zi=e.reshape(self.zi.shape))
                Y[:, j], Z[:, j] = y, zf.ravel()
            yu, zu = signal.sosfilt(self.sos, np.ones(n), zi=np.zeros_like(self.zi))
            maps = self._maps[n] = (Y, yu, Z, zu.ravel())
        return maps

    def run_constant(self, u: float, n: int) -> np.ndarray:
        """Filter ``n`` samples of the constant input ``u``, continuing from the state.

        The same numbers as :meth:`run` on ``np.full(n, u)`` (to rounding) at a
        fraction of the cost: the simulator's closed loop holds each command for a
        whole loop period.
        """
        Y, yu, Z, zu = self._block_maps(n)
        z = self.zi.ravel()
        y = Y @ z + yu * u
        self.zi = (Z @ z + zu * u).reshape(self.zi.shape)
        return y

    def run(self, u: np.ndarray | float) -> np.ndarray:
        """Filter the samples ``u`` (1-D), continuing from the current state."""
        x = np.atleast_1d(np.asarray(u, dtype=float))
        y, self.zi = signal.sosfilt(self.sos, x, zi=self.zi)
        return y

    def step(self, u: float) -> float:
        """Filter one sample (convenience for 200 Hz loops)."""
        return float(self.run(np.array([u]))[0])


def tf_freqresp(num: Sequence[float], den: Sequence[float], f_hz: np.ndarray) -> np.ndarray:
    """Complex response of ``num(s)/den(s)`` at the frequencies ``f_hz`` (Hz)."""
    s = 2j * np.pi * np.asarray(f_hz, dtype=float)
    return np.polyval(np.asarray(num, float), s) / np.polyval(np.asarray(den, float), s)


def is_stable(den: Sequence[float]) -> bool:
    """True when every root of the continuous ``den(s)`` has a negative real part."""
    return bool(np.all(np.real(np.roots(np.asarray(den, float))) < 0.0))
