"""Memory operators behind the effects, vectorised where the maths allows.

- :func:`play` — the play (backlash) operator of width ``2 r``, the building block
  of Prandtl-Ishlinskii hysteresis.
- :class:`BoucWen` — a rate-independent Bouc-Wen element (exponent 1), integrated
  exactly: within a monotone run of the input its state obeys a linear ODE in the
  input's path length, solved in closed form, so only the runs are looped over.
- :func:`asymmetric_lag` — a first-order lag whose time constant depends on the
  direction (and optionally on the level); a per-sample recursion.
- :func:`scale_resonances` — multiply the inertia (``s^2`` term) of every complex
  pole pair of a denominator.
- :class:`DelayLine` — an integer-sample delay that keeps its memory across blocks.
"""
from __future__ import annotations

import math

import numpy as np

__all__ = ["play", "BoucWen", "asymmetric_lag", "scale_resonances", "DelayLine", "monotone_runs"]


def monotone_runs(x: np.ndarray) -> np.ndarray:
    """Start indices of the monotone runs of ``x`` (flat steps join the current run).

    Returns the indices ``i`` where a run starts: 0 and every turning point. Run ``j``
    covers ``x[start_j .. start_{j+1}]`` (neighbouring runs share their turning point).
    """
    d = np.sign(np.diff(np.asarray(x, float)))
    nz = np.flatnonzero(d)
    if nz.size == 0:
        return np.array([0], int)
    s = d[nz]
    change = nz[1:][s[1:] != s[:-1]]
    return np.unique(np.concatenate([[0], change])).astype(int)


def play(x: np.ndarray, r: float | np.ndarray, y0: float | None = None) -> np.ndarray:
    """Play operator of half-width ``r``: ``y_k = min(max(y_{k-1}, x_k - r), x_k + r)``.

    Each step is a clamp to ``[x_k - r, x_k + r]``, and a composition of clamps is a
    clamp (``clamp(clamp(y, l1, h1), l2, h2) = clamp(y, clamp(l1, l2, h2),
    clamp(h1, l2, h2))``), so the whole recursion is a prefix scan of clamps: about
    ``log2(n)`` vector passes instead of a loop over samples.

    Parameters
    ----------
    x : ndarray, shape (n,)
        Input samples.
    r : float or ndarray, shape (m,)
        Half-width(s) (>= 0), in the unit of ``x``.
    y0 : float, optional
        State before the first sample (default ``x[0]``: centred).

    Returns
    -------
    ndarray, shape (n,) for a scalar ``r``, else (m, n)
    """
    xs = np.asarray(x, float)
    rr = np.atleast_1d(np.asarray(r, float))[:, None]
    lo = xs[None, :] - rr
    hi = xs[None, :] + rr
    n = xs.size
    d = 1
    while d < n:
        l_prev, h_prev = lo[:, :-d], hi[:, :-d]
        l_cur, h_cur = lo[:, d:], hi[:, d:]
        new_lo = np.minimum(np.maximum(l_prev, l_cur), h_cur)
        new_hi = np.minimum(np.maximum(h_prev, l_cur), h_cur)
        lo[:, d:], hi[:, d:] = new_lo, new_hi
        d *= 2
    start = float(xs[0]) if y0 is None else float(y0)
    out = np.minimum(np.maximum(start, lo), hi)
    return out[0] if np.ndim(r) == 0 else out


class BoucWen:
    """Rate-independent Bouc-Wen element ``dh = dv - beta |dv| h - gamma dv |h|``.

    Parameters
    ----------
    beta, gamma : float
        Shape parameters, 1/(unit of v), ``beta > |gamma|`` (then ``|h|`` stays below
        ``1 / (beta + gamma)``).
    """

    def __init__(self, beta: float, gamma: float) -> None:
        if not beta > abs(gamma):
            raise ValueError(f"Bouc-Wen needs beta > |gamma|, got {beta}, {gamma}")
        self.beta, self.gamma = float(beta), float(gamma)
        self.h = 0.0
        self.v_last: float | None = None

    def reset(self, v0: float, h0: float = 0.0) -> None:
        """At rest at input ``v0`` with state ``h0``."""
        self.v_last, self.h = float(v0), float(h0)

    def _advance(self, h0: float, s: float, x: np.ndarray) -> np.ndarray:
        """State along path lengths ``x >= 0`` of a run in direction ``s`` from ``h0``."""
        b, g = self.beta, self.gamma
        sigma = 1.0 if (h0 > 0.0 or (h0 == 0.0 and s > 0)) else -1.0
        lam = b + s * g * sigma
        heq = s / lam
        if (heq > 0) == (sigma > 0):  # no zero crossing: exponential approach to heq
            return heq + (h0 - heq) * np.exp(-lam * x)
        xc = math.log((h0 - heq) / (-heq)) / lam  # where h crosses zero
        lam2 = b + s * g * (-sigma)
        heq2 = s / lam2
        before = heq + (h0 - heq) * np.exp(-lam * np.minimum(x, xc))
        after = heq2 * (1.0 - np.exp(-lam2 * np.maximum(x - xc, 0.0)))
        return np.where(x <= xc, before, after)

    def run(self, v: np.ndarray) -> np.ndarray:
        """The state ``h`` after each input sample ``v`` (continues from the last call)."""
        v = np.asarray(v, float)
        if v.size == 0:
            return v.copy()
        prev = v[0] if self.v_last is None else self.v_last
        full = np.concatenate([[prev], v])
        out = np.empty(v.size)
        starts = monotone_runs(full)
        ends = np.concatenate([starts[1:], [full.size - 1]])
        h = self.h
        for a, e in zip(starts.tolist(), ends.tolist()):
            seg = full[a:e + 1]  # includes the run's starting point
            if seg.size < 2:
                continue
            dv = seg[-1] - seg[0]
            if dv == 0.0:
                out[a:e] = h
                continue
            s = 1.0 if dv > 0 else -1.0
            x = np.abs(seg[1:] - seg[0])
            hh = self._advance(h, s, x)
            out[a:e] = hh
            h = float(hh[-1])
        self.h, self.v_last = h, float(v[-1])
        return out


def asymmetric_lag(x: np.ndarray, dt_s: float, tau_up_s: float, tau_down_s: float, z0: float | None = None,
                   *, level_dependence: float = 0.0, level_ref: float = 1.0) -> np.ndarray:
    """First-order lag with a direction-dependent time constant.

    ``z`` follows ``x`` with time constant ``tau_up_s`` when ``x > z`` and
    ``tau_down_s * (1 + level_dependence * max(0, 1 - z / level_ref))`` otherwise;
    each step is exact for the time constant in force (``1 - exp(-dt / tau)``).

    Parameters
    ----------
    x : ndarray, shape (n,)
        Input (the level the output tends to).
    dt_s : float
        Sample period, s.
    tau_up_s, tau_down_s : float
        Time constants, s (0: follow at once).
    z0 : float, optional
        Initial output (default ``x[0]``).
    level_dependence, level_ref : float
        Growth of the down time constant towards zero level, and the level where it
        is ``tau_down_s``.

    Returns
    -------
    ndarray, shape (n,)
    """
    xs = np.asarray(x, float)
    a_up = 1.0 if tau_up_s <= 0 else -math.expm1(-dt_s / tau_up_s)
    z = float(xs[0]) if z0 is None else float(z0)
    out = [0.0] * xs.size
    if level_dependence == 0.0:
        a_dn = 1.0 if tau_down_s <= 0 else -math.expm1(-dt_s / tau_down_s)
        for i, xi in enumerate(xs.tolist()):
            d = xi - z
            z += d * (a_up if d > 0.0 else a_dn)
            out[i] = z
    else:
        inv_ref = 1.0 / level_ref
        for i, xi in enumerate(xs.tolist()):
            d = xi - z
            if d > 0.0:
                z += d * a_up
            else:
                g = 1.0 - z * inv_ref
                tau = tau_down_s * (1.0 + level_dependence * (g if g > 0.0 else 0.0))
                z += d * (dt_s / (tau + dt_s) if tau > 0 else 1.0)
            out[i] = z
    return np.asarray(out)


def scale_resonances(den: np.ndarray, inertia_factor: float) -> np.ndarray:
    """Denominator with the ``s^2`` term of each complex pole pair multiplied.

    ``s^2 + a s + b`` becomes ``k s^2 + a s + b`` (``k = inertia_factor``), so the
    natural frequency and the damping ratio both fall by ``sqrt(k)``; real poles and
    the DC value ``den(0)`` are kept.

    Parameters
    ----------
    den : array_like
        Coefficients in descending powers of s.
    inertia_factor : float
        ``k > 0``.

    Returns
    -------
    ndarray
    """
    d = np.asarray(den, float)
    roots = np.roots(d)
    lead = d[0]
    out = np.array([lead])
    tol = 1e-9 * np.maximum(1.0, np.abs(roots))
    for r in roots[np.abs(roots.imag) <= tol]:
        out = np.polymul(out, [1.0, -r.real])
    for r in roots[roots.imag > tol]:
        a, b = -2.0 * r.real, abs(r) ** 2
        out = np.polymul(out, [inertia_factor, a, b])
    return np.real(out)


class DelayLine:
    """Integer-sample delay keeping its memory across calls.

    Parameters
    ----------
    n_samples : int
        Delay, samples (>= 0).
    """

    def __init__(self, n_samples: int) -> None:
        self.n = int(n_samples)
        self.buf = np.zeros(self.n)

    def reset(self, x0: float) -> None:
        """Memory filled with ``x0`` (held forever)."""
        self.buf = np.full(self.n, float(x0))

    def run(self, x: np.ndarray) -> np.ndarray:
        """The input delayed by ``n_samples``."""
        x = np.asarray(x, float)
        if self.n == 0:
            return x.copy()
        full = np.concatenate([self.buf, x])
        self.buf = full[full.size - self.n:]
        return full[:x.size]
