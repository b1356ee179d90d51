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
- :class:`DelayStage` — a (fractional) sample delay that keeps its memory across blocks;
  :class:`DelayLine`, the integer one.
- :func:`rate_limited` — a signal followed at a bounded speed in either direction (slew and
  speed limits).
"""
from __future__ import annotations

import math
from bisect import bisect_left
from collections import deque

import numpy as np

__all__ = ["play", "BoucWen", "asymmetric_lag", "scale_resonances", "map_resonances", "DelayLine", "DelayStage", "monotone_runs", "rate_limited",
           "rate_step"]


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
    change = nz[1:][s[1:] != s[:-1]]  # increasing, all >= 1
    return np.concatenate([[0], change]).astype(int)


def _play_scan(xs: np.ndarray, rr: np.ndarray, start: float) -> np.ndarray:
    """The play operators of half-widths ``rr`` (shape (m, 1)) on ``xs`` from ``start``, as a prefix
    scan of clamps (shape (m, n))."""
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
    return np.minimum(np.maximum(start, lo), hi)


def play(x: np.ndarray, r: float | np.ndarray, y0: float | None = None) -> np.ndarray:
    """Play operator of half-width ``r``: ``y_k = min(max(y_{k-1}, x_k - r), x_k + r)``.

    Each step is a clamp to ``[x_k - r, x_k + r]``, and a composition of clamps is a
    clamp (``clamp(clamp(y, l1, h1), l2, h2) = clamp(y, clamp(l1, l2, h2),
    clamp(h1, l2, h2))``), so the whole recursion is a prefix scan of clamps: about
    ``log2(n)`` vector passes instead of a loop over samples. Over a monotone run of ``x``
    the clamps in between compose to the one at the run's end (rising: ``y_k = max(y_a,
    x_k - r)`` from the run's start ``a``), so the scan runs over the turning points only
    and the runs are filled in from them: every output is the same float as the full
    scan's (each is one of ``y0``, ``x_i - r``, ``x_i + r``, chosen by comparisons).

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
    start = float(xs[0]) if y0 is None else float(y0)
    n = xs.size
    knots = monotone_runs(xs) if n > 2 else np.arange(n)
    if knots[-1] != n - 1:
        knots = np.append(knots, n - 1)
    if knots.size > n // 3:  # many reversals (a noisy input): the plain scan
        out = _play_scan(xs, rr, start)
    else:
        at = _play_scan(xs[knots], rr, start)  # the outputs at the turning points
        # each sample's run (from its starting knot) and direction: +1 rising, -1 falling; a falling
        # run's min(y_a, x + r) is computed as -max(-y_a, -x - r) (negation is exact)
        run = np.repeat(np.arange(knots.size - 1), np.diff(knots))
        sign_run = np.where(xs[knots[1:]] >= xs[knots[:-1]], 1.0, -1.0)
        sgn = np.append(sign_run[run], 1.0)
        out = (sgn * xs)[None, :] - rr
        np.maximum(out[:, :-1], (at[:, :-1] * sign_run)[:, run], out=out[:, :-1])
        out *= sgn
        out[:, knots] = at
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


class _FallingLaw:
    """A falling step law for :func:`_shoot_lag`: ``a(z)``, the step's share of ``x - z``.

    ``kind`` ``"const"``: ``a = a_dn``; ``"linear"`` (the truth form): ``dt / (tau + dt)``,
    ``tau = tau_down (1 + L max(0, 1 - z / ref))`` (1 where ``tau <= 0``); ``"exp"`` (the
    generic form): ``dt / (T + dt)``, ``T = tau_down exp(k clip((z - c) / s, -2, 2))``. The
    vector arithmetic is the scalar loops' own, in the same order.
    """

    def __init__(self, kind: str, dt_s: float = 1.0, tau_down_s: float = 0.0, slope: float = 0.0,
                 centre: float = 0.0, scale: float = 1.0, a_dn: float = 1.0) -> None:
        self.kind, self.dt, self.tau, self.k = kind, float(dt_s), float(tau_down_s), float(slope)
        self.c, self.inv, self.a_dn = float(centre), 1.0 / float(scale), float(a_dn)

    def a(self, z: np.ndarray) -> np.ndarray:
        """Falling step shares at states ``z``."""
        if self.kind == "const":
            return np.full(z.shape, self.a_dn)
        if self.kind == "linear":
            g = 1.0 - z * self.inv
            tau = self.tau * (1.0 + self.k * np.maximum(g, 0.0))
            pos = tau > 0
            return np.where(pos, self.dt / (np.where(pos, tau, 1.0) + self.dt), 1.0)
        w = (z - self.c) * self.inv
        np.minimum(w, 2.0, out=w)
        np.maximum(w, -2.0, out=w)
        w *= self.k
        big = self.tau * np.exp(w, out=w)
        big += self.dt
        return np.divide(self.dt, big, out=big)

    def scalar(self, z: float) -> float:
        """The falling step share at one state ``z`` (the scalar loops' expression)."""
        if self.kind == "const":
            return self.a_dn
        if self.kind == "linear":
            g = 1.0 - z * self.inv
            tau = self.tau * (1.0 + self.k * (g if g > 0.0 else 0.0))
            return self.dt / (tau + self.dt) if tau > 0 else 1.0
        w = (z - self.c) * self.inv
        if w > 2.0:
            w = 2.0
        elif w < -2.0:
            w = -2.0
        return self.dt / (self.tau * math.exp(self.k * w) + self.dt)


#: Samples per segment of :func:`_shoot_lag`'s sweeps, and the shortest signal it is used on.
_SEG = 64
_MIN_SHOOT = 4096
#: Segments still moving after a sweep below which the rest is repaired one sample at a time.
_REPAIR = 48


def _shoot_lag(xs: np.ndarray, z0: float, a_up: float, law: _FallingLaw, max_sweeps: int = 6) -> np.ndarray:
    """The direction-dependent lag ``z_k = z_{k-1} + a (x_k - z_{k-1})`` by multiple shooting.

    ``a = a_up`` while ``x_k > z_{k-1}``, else ``law.a(z_{k-1})``. The signal is cut into
    segments of :data:`_SEG` samples, all stepped at once (one vector operation per sample
    position instead of one Python step per sample) from guessed start states; a start
    that differs from the end of the segment before is corrected by a Newton step through
    the segments' end sensitivities (``dz_end / dz_start``: the product of ``1 - a``, exactly
    0 after a rise with ``a_up = 1``; the level law's own slope is left out, so the steps are
    quasi-Newton), and only the segments whose start moved are stepped again. The steps
    are the recursion's own arithmetic, so once every start matches the previous end (to
    a few units in the last place of the signal's scale) the samples are the recursion's.
    When few segments still move (:data:`_REPAIR`), or after ``max_sweeps`` sweeps, the
    rest is done one sample at a time in order (:func:`_repair`): exact, and in the worst
    case as slow as the plain recursion.
    """
    n = xs.size
    L = _SEG
    M = -(-n // L)
    X = np.empty(M * L)
    X[:n] = xs
    X[n:] = xs[-1]
    XT = np.ascontiguousarray(X.reshape(M, L).T)  # row j: sample j of every segment
    ZT = np.empty((L, M))
    s = np.empty(M)
    s[0] = z0
    s[1:] = XT[-1, :-1]  # guess: the input at the end of the segment before
    scale = max(float(np.max(np.abs(xs))), abs(z0), 1e-300)
    tol = 8.0 * np.finfo(float).eps * scale
    idx = None  # all segments
    for _ in range(max_sweeps):
        Xa = XT if idx is None else XT[:, idx]
        Za = np.empty_like(Xa)
        z = s.copy() if idx is None else s[idx]
        sens = np.ones(z.size)
        for j in range(L):
            d = Xa[j] - z
            a = law.a(z)
            a[d > 0.0] = a_up
            d *= a
            z = z + d
            Za[j] = z
            # each segment's sensitivity of its end to its start, without the level law's own slope
            # (the Newton steps need not be exact: the starts are checked against the ends)
            np.subtract(1.0, a, out=a)
            sens *= a
        if idx is None:
            ZT[:] = Za
            S = sens
        else:
            ZT[:, idx] = Za
            S[idx] = sens
        # starts against the ends before them; a Newton step along the chain of segments
        ends = ZT[-1].tolist()
        sl, Sl = s.tolist(), S.tolist()
        ds = [0.0] * M
        moved = []
        prev = 0.0
        for m in range(1, M):
            dm = ends[m - 1] + Sl[m - 1] * prev - sl[m]
            if -tol <= dm <= tol:
                dm = 0.0
            else:
                moved.append(m)
            ds[m] = dm
            prev = dm
        if len(moved) <= _REPAIR:
            break
        idx = np.array(moved)
        s[idx] += np.asarray(ds)[idx]
    _repair(XT, ZT, a_up, law, 0.0 if law.kind != "exp" else tol)
    return ZT.T.reshape(-1)[:n].copy()


def _repair(XT: np.ndarray, ZT: np.ndarray, a_up: float, law: _FallingLaw, tol: float) -> None:
    """Make the segments (columns of ``ZT``) continue each other.

    The first step of every segment is taken again from the stored end of the one before
    (all at once); where it does not give the stored first sample (equal, or within ``tol``),
    the segment is stepped again one sample at a time, in order, from the end before it until
    its samples meet the stored ones (from there on the same steps follow); a segment whose
    end moved sends the next one through the same. With ``tol = 0`` the result is the plain
    recursion's, bit for bit, as far as the vector steps are (the constant and linear laws:
    the same operations in the same order).
    """
    L, M = ZT.shape
    if M < 2:
        return
    zp = ZT[L - 1, :-1].copy()
    d = XT[0, 1:] - zp
    a = law.a(zp.copy())
    a[d > 0.0] = a_up
    first = zp + d * a
    diff = np.abs(first - ZT[0, 1:])
    queue = deque((np.flatnonzero(~(diff <= tol)) + 1).tolist())
    step = law.scalar
    exp_law = law.kind == "exp"
    dt, tau, k, c, inv, exp = law.dt, law.tau, law.k, law.c, law.inv, math.exp
    while queue:
        m = queue.popleft()
        col = ZT[:, m]
        x = XT[:, m].tolist()
        z = float(ZT[L - 1, m - 1])
        for j in range(L):
            d0 = x[j] - z
            if d0 > 0.0:
                z += d0 * a_up
            elif exp_law:  # law.scalar written out (the hot case)
                w = (z - c) * inv
                if w > 2.0:
                    w = 2.0
                elif w < -2.0:
                    w = -2.0
                z += d0 * (dt / (tau * exp(k * w) + dt))
            else:
                z += d0 * step(z)
            old = float(col[j])
            if z == old or abs(z - old) <= tol:
                break
            col[j] = z
        else:  # the end moved: the next segment starts elsewhere
            if m + 1 < M and (not queue or queue[0] != m + 1):
                queue.appendleft(m + 1)


def _lag_loop(xs: np.ndarray, z: float, a_up: float, a_dn: float) -> np.ndarray:
    """The constant-time-constant recursion, one sample at a time (the definition)."""
    out: list[float] = []
    append = out.append
    for xi in xs.tolist():
        d = xi - z
        z += d * (a_up if d > 0.0 else a_dn)
        append(z)
    return np.array(out, dtype=float)


def _lag_loop_linear_level(xs: np.ndarray, z: float, a_up: float, dt_s: float, tau_down_s: float,
                           level_dependence: float, level_ref: float) -> np.ndarray:
    """The truth form's level-dependent recursion, one sample at a time (the definition)."""
    out: list[float] = []
    append = out.append
    inv_ref = 1.0 / level_ref
    for xi in xs.tolist():
        d = xi - z
        if d > 0.0:
            z += d * a_up
        else:
            g = 1.0 - z * inv_ref
            tau = tau_down_s * (1.0 + level_dependence * (g if g > 0.0 else 0.0))
            z += d * (dt_s / (tau + dt_s) if tau > 0 else 1.0)
        append(z)
    return np.array(out, dtype=float)


def exp_level_lag_loop(x: np.ndarray, dt_s: float, tau_up_s: float, tau_down_s: float, k: float, y_c: float,
                       y_s: float, z0: float) -> np.ndarray:
    """:func:`exp_level_lag` one sample at a time (the definition; the reference of the fast kernel)."""
    a_up = 1.0 if tau_up_s <= 0 else -math.expm1(-dt_s / tau_up_s)
    z = float(z0)
    out: list[float] = []
    append = out.append
    inv = 1.0 / y_s
    exp = math.exp
    for xi in np.asarray(x, float).tolist():
        d = xi - z
        if d > 0.0:
            z += d * a_up
        else:
            w = (z - y_c) * inv
            if w > 2.0:
                w = 2.0
            elif w < -2.0:
                w = -2.0
            z += d * (dt_s / (tau_down_s * exp(k * w) + dt_s))
        append(z)
    return np.array(out, dtype=float)


def _lag_start(x: np.ndarray, dt_s: float, tau_up_s: float, z0: float | None) -> tuple[np.ndarray, float, float]:
    """The input as floats, the initial output (default ``x[0]``; 0 for an empty input) and the
    rising step share ``1 - exp(-dt / tau_up)`` (1 for ``tau_up <= 0``)."""
    xs = np.asarray(x, float)
    z = (float(xs[0]) if xs.size else 0.0) if z0 is None else float(z0)
    return xs, z, 1.0 if tau_up_s <= 0 else -math.expm1(-dt_s / tau_up_s)


def exp_level_lag(x: np.ndarray, dt_s: float, tau_up_s: float, tau_down_s: float, k: float, y_c: float,
                  y_s: float, z0: float | None = None) -> np.ndarray:
    """Lag with ``tau_up_s`` while rising and ``tau_down_s exp(k w)`` while falling, ``w = (z - y_c) / y_s``
    clipped to [-2, 2] (the generic ``asymmetric_dynamics`` form).

    Each step: ``z += d a``, ``d = x_k - z``, ``a = 1 - exp(-dt / tau_up_s)`` if ``d > 0`` else
    ``dt / (tau_down_s exp(k w) + dt)``. Long signals run through :func:`_shoot_lag` (the
    same samples to rounding), short ones one sample at a time (:func:`exp_level_lag_loop`).

    Parameters
    ----------
    x : ndarray, shape (n,)
        Input (the level the output tends to), unit of ``y_c``.
    dt_s, tau_up_s, tau_down_s : float
        Sample period and time constants, s (a time constant 0: follow at once).
    k : float
        Log-linear level slope of the falling time constant.
    y_c, y_s : float
        Centre and scale (> 0) of the level, unit of ``x``.
    z0 : float, optional
        Initial output (default ``x[0]``).

    Returns
    -------
    ndarray, shape (n,)
    """
    xs, z, a_up = _lag_start(x, dt_s, tau_up_s, z0)
    if xs.size >= _MIN_SHOOT:
        return _shoot_lag(xs, z, a_up, _FallingLaw("exp", dt_s, tau_down_s, k, y_c, y_s))
    return exp_level_lag_loop(xs, dt_s, tau_up_s, tau_down_s, k, y_c, y_s, z)


def asymmetric_lag(x: np.ndarray, dt_s: float, tau_up_s: float, tau_down_s: float, z0: float | None = None,
                   *, level_dependence: float = 0.0, level_ref: float = 1.0) -> np.ndarray:
    """First-order lag with a direction-dependent time constant.

    ``z`` follows ``x`` with time constant ``tau_up_s`` when ``x > z`` and
    ``tau_down_s * (1 + level_dependence * max(0, 1 - z / level_ref))`` otherwise;
    each step is exact for the time constant in force (``1 - exp(-dt / tau)``) when
    ``level_dependence`` is 0, else ``dt / (tau + dt)`` while falling.

    Long signals run through :func:`_shoot_lag` (all segments stepped at once, the same
    samples to rounding); short ones one sample at a time.

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
    xs, z, a_up = _lag_start(x, dt_s, tau_up_s, z0)
    if level_dependence == 0.0:
        a_dn = 1.0 if tau_down_s <= 0 else -math.expm1(-dt_s / tau_down_s)
        law = _FallingLaw("const", a_dn=a_dn)
    else:
        law = _FallingLaw("linear", dt_s, tau_down_s, level_dependence, 0.0, level_ref)
    if xs.size >= _MIN_SHOOT:
        return _shoot_lag(xs, z, a_up, law)
    if level_dependence == 0.0:
        return _lag_loop(xs, z, a_up, a_dn)
    return _lag_loop_linear_level(xs, z, a_up, dt_s, tau_down_s, level_dependence, level_ref)


def map_resonances(den: np.ndarray, pair) -> np.ndarray:
    """Denominator (descending powers of s) with each complex pole pair's factor replaced.

    The real poles' factors ``s - p`` and the leading coefficient are kept; each complex pole
    ``r`` (upper half-plane) gives the quadratic ``pair(r) = (a2, a1, a0)``, i.e.
    ``a2 s^2 + a1 s + a0``, in place of ``s^2 - 2 Re(r) s + |r|^2``.
    """
    d = np.asarray(den, float)
    roots = np.roots(d)
    out = np.array([d[0]])
    tol = 1e-9 * np.maximum(1.0, np.abs(roots))
    for r in roots[np.abs(roots.imag) <= tol]:
        out = np.polymul(out, [1.0, -r.real])
    for r in roots[roots.imag > tol]:
        out = np.polymul(out, list(pair(r)))
    return np.real(out)


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
    return map_resonances(den, lambda r: (inertia_factor, -2.0 * r.real, abs(r) ** 2))


class DelayStage:
    """A delay of ``delay_samples`` (>= 0, fractional allowed) samples, chunk by chunk.

    ``y_k = x_(k-n) + f (x_(k-n-1) - x_(k-n))`` with ``n + f = delay_samples``: linear
    interpolation between the two samples around ``t_k - d``; before the first sample
    the input is the value it was reset to.
    """

    def __init__(self, delay_samples: float) -> None:
        if not delay_samples >= 0:
            raise ValueError(f"delay must be >= 0 samples, got {delay_samples}")
        self.n = int(math.floor(delay_samples))
        self.f = float(delay_samples - self.n)
        self.m = self.n + 1  # memory: x_(k-n-1) .. x_(k-1)
        self.buf = np.zeros(self.m)

    def reset(self, x0: float) -> None:
        """Memory filled with ``x0`` (held forever before)."""
        self.buf = np.full(self.m, float(x0))

    def run(self, x: np.ndarray, u: np.ndarray | None = None) -> np.ndarray:
        """The next samples ``x``, delayed."""
        x = np.asarray(x, float)
        full = np.concatenate([self.buf, x])
        k = np.arange(x.size)
        a = full[k + self.m - self.n]
        y = a if self.f == 0.0 else a + self.f * (full[k + self.m - self.n - 1] - a)
        self.buf = full[full.size - self.m:]
        return y


class DelayLine(DelayStage):
    """Integer-sample delay keeping its memory across calls (a :class:`DelayStage` without fraction).

    Parameters
    ----------
    n_samples : int
        Delay, samples (>= 0).
    """

    def __init__(self, n_samples: int) -> None:
        super().__init__(int(n_samples))


def rate_limited(x: np.ndarray, up: float, down: float, y0: float | None = None) -> np.ndarray:
    """``y_k = y_{k-1} + clip(x_k - y_{k-1}, -down, up)`` (steps per sample, ``inf``: free).

    Starts from ``y0`` (default ``x[0]``); feeding consecutive chunks with ``y0`` the last
    output of the previous chunk gives the same samples as one call.

    The limit acts only where the signal moves faster than it (or after it did, until the
    output has caught up): the samples in between are copied, only the active runs looped.
    """
    xs = np.asarray(x, float)
    out = xs.copy()
    if xs.size == 0:
        return out
    y = float(xs[0]) if y0 is None else float(y0)
    d0 = np.diff(xs, prepend=y)
    fast = np.flatnonzero((d0 > up) | (d0 < -down)).tolist()
    vals = xs.tolist()
    n = xs.size
    j = 0
    while j < len(fast):
        k = fast[j]
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
        j = bisect_left(fast, k)  # caught up: copy until the next fast sample
    return out


def rate_step(rate: float, dt: float) -> float:
    """Largest change per sample for ``rate`` (units per second) at ``dt`` (s); ``rate`` must be > 0."""
    step = float(rate) * float(dt)
    if not step > 0:
        raise ValueError(f"rate limit must be > 0, got {rate}")
    return step
