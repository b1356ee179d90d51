"""Generic parametric augmentations of a nominal linear simulator, one per effect name.

None of them knows how a particular simulator or rig produces its effect: each is
the simplest generic form that has the effect's *signature*, fitted to the data.

=================== ======================= =========================================
name                slot in the chain       form (x input, y output, G the model)
=================== ======================= =========================================
time_delay          input                   x(t - d)
saturation          input or output         clip at a lower or an upper limit; or
                    measured (last)         the measured range where the output
                                            piles up on its extremes (a sensor's
                                            or a physical limit seen in the data);
                                            or (``slew``, input) a slew-rate limit:
                                            the input moves at most ``S`` per second
static_nonlinearity input or internal       input map ``x + s sum_j a_j z^j`` (degree 5),
                                            or (internal, a stiffness-like force)
                                            ``y + G1(s sum_j b_j w^j)``
                                            ``G1 = G / G(0)``, ``z``, ``w`` the
                                            normalised input and output; a map
                                            that is nearly a line (a linear
                                            correction, not a nonlinearity) keeps
                                            only its offset
hysteresis          input                   Prandtl-Ishlinskii:
                                            ``x + sum_j w_j (play_rj(x) - x)``,
                                            ``w_j >= 0``, five fixed thresholds, the
                                            plays starting at ``x_0 + c r_j``
                                            (``c`` in [-1, 1]: the branch the log
                                            starts on; a memory of what came before)
load_mass           model                   inertia of G's resonances (or its slowest
                                            real pole) times ``1 + mu``, gain ``kappa``;
                                            ``model:sag``: and a static offset
                                            ``<= 0`` (the load's weight compresses)
asymmetric_dynamics output                  first-order lag, one time constant while
                                            the output rises, another while it falls
                                            (log-linear in the level); or
                                            (``rate_limit:falling|rising``) a speed
                                            limit ``R`` per second in one direction
charge_drift        output                  ``y (1 + g q) + s o q``, ``q`` a slow
                                            (``tau``) low-pass of the input's history
sensor_nonlinearity output (last)           ``y + s sum_j c_j w^j`` (degree 5)
=================== ======================= =========================================

The chain order is: delay, input saturation, input map, hysteresis, G (with load),
internal map, asymmetric lag, drift, output saturation, sensor map, measured clip.
:class:`Pipeline` simulates any combination with caching of the unchanged upstream
stages; :func:`fit_family` fits one family's few parameters on the training samples
with the others held fixed (linear least squares where the form is linear in its
parameters, a small grid plus bounded refinement otherwise).
"""
from __future__ import annotations

import hashlib
import math
from dataclasses import dataclass, field

import numpy as np
from scipy import optimize, signal

from hasel.diagnose.prep import LinearSim, Prepared, dominant_time_constant_s, flat_extremes
from hasel.diagnose.ratelimit import DIRECTIONS, fit_log_scalar, rate_grid, slew_limit, speed_limit
from hasel.effects.operators import asymmetric_lag, monotone_runs, play, scale_resonances

__all__ = ["EffectFit", "Pipeline", "fit_family", "linear_static", "fit_drift_on_repeats", "measured_clip", "joint_refine", "family_bounds", "FAMILIES",
           "HYST_THRESHOLDS",
           "describe_params", "LINEAR", "INPUT_SIDE", "make_linear", "split_linear"]

#: Effect names in chain order of their (first) slot.
FAMILIES = ("time_delay", "saturation", "static_nonlinearity", "hysteresis", "load_mass",
            "asymmetric_dynamics", "charge_drift", "sensor_nonlinearity")
#: Highest degree of the static and sensor maps' polynomials (offset and linear terms included;
#: 1, 3 or this, chosen by cross-validation within the training samples).
STATIC_DEGREE = 5
#: Ridge of the polynomial maps' least squares, relative to the mean squared column norm.
POLY_RIDGE = 1e-4
#: Play-operator half-widths as fractions of the input's range (1st-99th percentile).
HYST_THRESHOLDS = (0.01, 0.03, 0.07, 0.15, 0.3)
#: A static map whose curvature (its deviation from its best line) removes less than this share
#: of what the map removes beyond its offset is a linear correction (a gain, a changed dynamic):
#: only its offset is kept.
NEAR_LINEAR_SHARE = 0.1
#: Least change of the inertia (``|mu|``) for a load to carry a static offset (its weight's sag).
LOAD_SAG_MIN_MU = 0.1
# stages whose presence downstream keeps a least-squares basis exact
_LINEAR_STAGES = {"time_delay", "load_mass", "_linear"}
#: Name of the pseudo-effect holding a re-identified linear model (not an effect: never named).
LINEAR = "_linear"
#: Families acting before the linear model (a linear model can be re-identified through them).
INPUT_SIDE = ("time_delay", "saturation", "static_nonlinearity", "hysteresis")
_SLOT = {LINEAR: 4, "time_delay": 0, "saturation:input": 1, "saturation:slew": 1, "static_nonlinearity:input": 2,
         "hysteresis": 3,
         "load_mass": 4, "static_nonlinearity:internal": 5, "asymmetric_dynamics": 6, "charge_drift": 7,
         "saturation:output": 8, "sensor_nonlinearity": 9, "saturation:measured": 10}


@dataclass(frozen=True)
class EffectFit:
    """One fitted augmentation.

    Attributes
    ----------
    name : str
        Effect name.
    variant : str
        Where or how it acts (e.g. ``"input"``/``"internal"``, ``"output:upper"``).
    theta : tuple of float
        Parameters in the family's internal order.
    """

    name: str
    variant: str
    theta: tuple[float, ...]

    @property
    def n_params(self) -> int:
        """Number of fitted parameters (what the penalty counts; a re-identified nominal counts none)."""
        return 0 if self.name == LINEAR else len(self.theta)

    @property
    def slot(self) -> int:
        """Position in the chain."""
        key = f"{self.name}:{self.variant.split(':')[0]}"
        return _SLOT.get(key, _SLOT.get(self.name, 0))


@dataclass
class Pipeline:
    """The nominal model plus augmentations, simulated on the prepared records.

    Parameters
    ----------
    prep : Prepared
        Working-rate data.
    num, den : ndarray
        Nominal model (descending powers of s).
    delay_s : float
        The nominal model's own input delay, s (MODEL.json ``delay_s``).
    """

    prep: Prepared
    num: np.ndarray
    den: np.ndarray
    delay_s: float = 0.0
    _cache: dict = field(default_factory=dict)
    _lin: dict = field(default_factory=dict)

    def __post_init__(self) -> None:
        self.num = np.asarray(self.num, float)
        self.den = np.asarray(self.den, float)
        self.nominal = LinearSim(self.num, self.den, self.prep.rate_hz, self.prep.sample_offset)
        self.inputs = [(_shift(r.t_s, r.u, self.delay_s) if self.delay_s > 0 else r.u) for r in self.prep.records]
        self.t_dom = max(min(dominant_time_constant_s(self.den), self.span_s), 2.0 * self.prep.dt_s)
        # maps are normalised on the training samples: [-1, 1] spans their 0.5-99.5 percentiles,
        # and a polynomial map is held constant beyond (never extrapolated)
        u = self.prep.stacked("u")
        u_tr = self.prep.stacked("u", "train")
        lo, hi = np.percentile(u_tr, [0.5, 99.5])
        self.u_c = 0.5 * (lo + hi)
        self.u_s = max(0.5 * (hi - lo), 1e-12 * max(1.0, abs(self.u_c)), 1e-300)
        y0 = np.concatenate([self.nominal.run(x)[r.train] for x, r in zip(self.inputs, self.prep.records)])
        lo, hi = np.percentile(y0, [0.5, 99.5])
        self.y_c = 0.5 * (lo + hi)
        self.y_s = max(0.5 * (hi - lo), 1e-300)
        self.thresholds = tuple(2.0 * self.u_s * f for f in HYST_THRESHOLDS)
        self.n_evals = 0
        self.max_degree = _max_degree(u, self.u_s)
        # the measured output piling up on its extreme (a clip): that value is a candidate limit
        self.clips = {end: v for end, (v, _) in flat_extremes(self.prep.records[0].y).items()}

    @property
    def span_s(self) -> float:
        """Length of the data log, s."""
        r = self.prep.records[0]
        return float(r.t_s[-1] - r.t_s[0] + self.prep.dt_s)

    # -- linear model with load --------------------------------------------------------------
    def loaded(self, mu: float, kappa: float = 1.0, lin: "EffectFit | None" = None) -> LinearSim:
        """The model (``lin``, a re-identified linear part, or the nominal) with ``1 + mu`` times
        the inertia of its resonances (cached), times the gain ``kappa``."""
        base = ("nominal",) if lin is None else lin.theta
        key = (round(mu, 12),) + base
        sim = self._lin.get(key)
        if sim is None:
            num, den = (self.num, self.den) if lin is None else split_linear(lin)
            if mu == 0.0:
                sim = self.nominal if lin is None else LinearSim(num, den, self.prep.rate_hz, self.prep.sample_offset)
            else:
                p = np.roots(den)
                if np.any(np.abs(p.imag) > 1e-9 * np.maximum(1.0, np.abs(p))):
                    den2 = scale_resonances(den, 1.0 + mu)
                    den2 = den2 * (den[-1] / den2[-1])
                else:  # no resonance: the slowest real pole carries the inertia
                    i = int(np.argmin(np.abs(p.real)))
                    p2 = p.copy()
                    p2[i] = p[i] / (1.0 + mu)
                    den2 = np.real(np.poly(p2)) * den[0]
                    den2 = den2 * (den[-1] / den2[-1])
                sim = LinearSim(num, den2, self.prep.rate_hz, self.prep.sample_offset)
            if len(self._lin) > 64:
                self._lin.clear()
            self._lin[key] = sim
        if kappa == 1.0:
            return sim
        return _Scaled(sim, kappa)  # type: ignore[return-value]

    def linear_of(self, effects: dict[str, "EffectFit"]) -> "LinearSim | _Scaled":
        """The linear part of the chain for ``effects`` (re-identified model and load included)."""
        f = effects.get("load_mass")
        mu, kappa = (f.theta[:2] if f is not None else (0.0, 1.0))
        return self.loaded(mu, kappa, effects.get(LINEAR))

    # -- stages ---------------------------------------------------------------------------------
    def _memo(self, key: tuple, fn):
        v = self._cache.get(key)
        if v is None:
            if len(self._cache) > 256:
                self._cache.clear()
            v = fn()
            self._cache[key] = v
        return v

    def plays(self, ri: int, x: np.ndarray, key: tuple, branch: float = 0.0) -> list[np.ndarray]:
        """Play operators of the fixed thresholds on ``x`` (cached under ``key``), each starting at
        ``x[0] + branch r_j`` (``branch`` -1: on the rising branch, as after a rise to ``x[0]``;
        0: centred; 1: on the falling branch)."""
        def make() -> list[np.ndarray]:
            if branch == 0.0:
                return list(play(x, np.asarray(self.thresholds), float(x[0])))
            return [play(x, r, float(x[0]) + branch * r) for r in self.thresholds]

        return self._memo(("plays", ri, round(float(branch), 12)) + key, make)

    def stages(self, effects: dict[str, EffectFit], ri: int, upto: int = 99) -> dict[str, np.ndarray]:
        """Intermediate signals of record ``ri`` through the chain (up to slot ``upto``, exclusive).

        Keys: ``"x_delay"``, ``"x_sat"``, ``"x_map"``, ``"x_eff"`` (input side), ``"y_lin"``,
        ``"y_int"``, ``"y_asym"``, ``"y_drift"``, ``"y_sat"``, ``"y"`` (output side); a stage
        past ``upto`` is the identity.
        """
        rec = self.prep.records[ri]
        e = {k: v for k, v in effects.items() if v.slot < upto}
        out: dict[str, np.ndarray] = {}
        key: tuple = ()
        x = self.inputs[ri]
        f = e.get("time_delay")
        if f is not None:
            key += ("d",) + f.theta
            x = self._memo(("x", ri) + key, lambda x=x, f=f: _shift(rec.t_s, x, f.theta[0]))
        out["x_delay"] = x
        f = e.get("saturation")
        if f is not None and f.variant == "slew":
            key += ("ss",) + f.theta
            x = self._memo(("x", ri) + key, lambda x=x, f=f: slew_limit(x, f.theta[0], self.prep.dt_s))
        elif f is not None and f.variant.startswith("input"):
            key += ("si", f.variant) + f.theta
            x = _clip(x, f)
        out["x_sat"] = x
        f = e.get("static_nonlinearity")
        if f is not None and f.variant == "input":
            key += ("mi",) + f.theta
            z = (x - self.u_c) / self.u_s
            x = x + self.u_s * poly_map(f.theta, z)
        out["x_map"] = x
        f = e.get("hysteresis")
        if f is not None:
            # the starting branch is that of the log it was fitted on (record 0); another log's
            # history is unknown: its plays start centred
            ps = self.plays(ri, x, key, _branch(f) if ri == 0 else 0.0)
            k2 = key + ("h",) + f.theta
            x = x + sum(w * (p - x) for w, p in zip(f.theta[:len(HYST_THRESHOLDS)], ps))
            key = k2
        out["x_eff"] = x
        f = e.get("load_mass")
        mu, kappa = (f.theta[:2] if f is not None else (0.0, 1.0))
        lin = e.get(LINEAR)
        key += ("l", mu, kappa) + (lin.theta if lin is not None else ())
        sim = self.loaded(mu, kappa, lin)
        y = self._memo(("y", ri) + key, lambda: sim.run(x))
        if f is not None and len(f.theta) > 2:  # the load's weight: a static offset (a sag)
            y = y + f.theta[2]
        out["y_lin"] = y
        f = e.get("static_nonlinearity")
        if f is not None and f.variant == "internal":
            w = (y - self.y_c) / self.y_s
            y = y + self.unit(sim).run(self.y_s * poly_map(f.theta, w))
        out["y_int"] = y
        f = e.get("asymmetric_dynamics")
        if f is not None and f.variant.startswith("rate_limit"):
            y = speed_limit(y, f.theta[0], self.prep.dt_s, f.variant.split(":")[1])
        elif f is not None:
            y = _asym_lag(y, self.prep.dt_s, f.theta, self.y_c, self.y_s)
        out["y_asym"] = y
        f = e.get("charge_drift")
        if f is not None:
            q = self.charge(out["x_sat"], f.theta[0])
            y = y * (1.0 + f.theta[1] * q) + self.y_s * f.theta[2] * q
        out["y_drift"] = y
        f = e.get("saturation")
        if f is not None and f.variant.startswith("output"):
            y = _clip(y, f)
        out["y_sat"] = y
        f = e.get("sensor_nonlinearity")
        if f is not None:
            w = (y - self.y_c) / self.y_s
            y = y + self.y_s * poly_map(f.theta, w)
        f = e.get("saturation")
        if f is not None and f.variant.startswith("measured"):
            y = _clip(y, f)
        out["y"] = y
        self.n_evals += 1
        return out

    def unit(self, sim: LinearSim) -> "LinearSim | _Scaled":
        """``sim`` scaled to unit DC gain (or unscaled if its DC gain is ~0)."""
        g = sim.dc_gain
        return _Scaled(sim, 1.0 / g) if abs(g) > 1e-12 else sim

    def charge(self, x: np.ndarray, tau_s: float) -> np.ndarray:
        """Slow history of the input: a first-order low-pass (``tau_s``) from zero (nothing
        stored when the log starts), of the input pre-smoothed by two first-order stages of
        a tenth of the shortest drift time constant (so that no fast part of the input, which
        a plain low-pass passes with a 90 degree lag, leaks in), over the input's scale."""
        key = ("charge", hashlib.blake2b(np.ascontiguousarray(x).tobytes(), digest_size=16).digest(), tau_s)
        cached = self._cache.get(key)
        if cached is not None:
            return cached
        dt = self.prep.dt_s
        ts = 0.1 * _tau_min(self)
        b = -math.expm1(-dt / ts)
        xs = signal.lfilter([b], [1.0, b - 1.0], x)
        xs = signal.lfilter([b], [1.0, b - 1.0], xs)
        a = -math.expm1(-dt / tau_s)
        q = signal.lfilter([a], [1.0, a - 1.0], xs) / self.u_s
        self._cache[key] = q
        return q

    def simulate(self, effects: dict[str, EffectFit], ri: int) -> np.ndarray:
        """Output of record ``ri`` for the nominal model plus ``effects``."""
        return self.stages(effects, ri)["y"]

    def residuals(self, effects: dict[str, EffectFit], mask: str) -> np.ndarray:
        """Stacked ``y - y_hat`` over the records' ``mask`` ("train" or "hold") samples."""
        parts = []
        for ri, rec in enumerate(self.prep.records):
            m = getattr(rec, mask)
            if m.any():
                parts.append((rec.y - self.simulate(effects, ri))[m])
        return np.concatenate(parts) if parts else np.zeros(0)


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


def make_linear(num: np.ndarray, den: np.ndarray) -> EffectFit:
    """A re-identified linear model as the pseudo-effect :data:`LINEAR`."""
    num = np.atleast_1d(np.asarray(num, float))
    den = np.atleast_1d(np.asarray(den, float))
    return EffectFit(LINEAR, "model", (float(num.size),) + tuple(map(float, num)) + tuple(map(float, den)))


def split_linear(fit: EffectFit) -> tuple[np.ndarray, np.ndarray]:
    """``(num, den)`` of a :data:`LINEAR` pseudo-effect."""
    k = int(fit.theta[0])
    return np.asarray(fit.theta[1:1 + k]), np.asarray(fit.theta[1 + k:])


class _Scaled:
    """A linear simulator times a constant."""

    def __init__(self, sim: LinearSim, k: float) -> None:
        self.sim, self.k = sim, float(k)
        self.dc_gain = sim.dc_gain * self.k

    def run(self, u: np.ndarray) -> np.ndarray:
        return self.k * self.sim.run(u)


def _asym_lag(y: np.ndarray, dt: float, theta: tuple[float, ...], y_c: float, y_s: float) -> np.ndarray:
    """Direction-dependent lag: ``tau_rise`` while rising, ``tau_fall exp(k w)`` while falling.

    ``w = (z - y_c) / y_s`` (clipped to [-2, 2]) lets the falling time constant depend on
    the level (log-linearly; ``k = 0``: constant).
    """
    tau_up, tau_dn = theta[0], theta[1]
    k = theta[2] if len(theta) > 2 else 0.0
    if k == 0.0:
        return asymmetric_lag(y, dt, tau_up, tau_dn, float(y[0]))
    a_up = 1.0 if tau_up <= 0 else -math.expm1(-dt / tau_up)
    z = float(y[0])
    out = [0.0] * y.size
    inv = 1.0 / y_s
    exp = math.exp
    for i, xi in enumerate(y.tolist()):
        d = xi - z
        if d > 0.0:
            z += d * a_up
        else:
            w = (z - y_c) * inv
            w = 2.0 if w > 2.0 else (-2.0 if w < -2.0 else w)
            tau = tau_dn * exp(k * w)
            z += d * (dt / (tau + dt))
        out[i] = z
    return np.asarray(out)


def _shift(t: np.ndarray, x: np.ndarray, d: float) -> np.ndarray:
    return np.interp(t - d, t, x, left=x[0], right=x[-1])


def _clip(x: np.ndarray, f: EffectFit) -> np.ndarray:
    if f.variant.endswith("both"):
        return np.clip(x, f.theta[0], f.theta[1])
    return np.minimum(x, f.theta[0]) if f.variant.endswith("upper") else np.maximum(x, f.theta[0])


def measured_clip(clips: dict[str, float]) -> EffectFit | None:
    """The clip of the measured range at ``clips`` (``{"upper"|"lower": value}``), as a saturation
    acting last in the chain (variant ``measured:upper|lower|both``), or ``None`` for no ends."""
    if not clips:
        return None
    if len(clips) == 2:
        return EffectFit("saturation", "measured:both", (float(clips["lower"]), float(clips["upper"])))
    (end, v), = clips.items()
    return EffectFit("saturation", f"measured:{end}", (float(v),))


# ---------------------------------------------------------------------------------------------
# fitting


def _train_target(pipe: Pipeline) -> tuple[list[np.ndarray], list[np.ndarray]]:
    ys, ms = [], []
    for rec in pipe.prep.records:
        ys.append(rec.y)
        ms.append(rec.train)
    return ys, ms


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
        sol = optimize.lsq_linear(A / scale, b, bounds=(0.0, np.inf)).x
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


def _fit_delay(pipe: Pipeline, effects: dict[str, EffectFit]) -> EffectFit | None:
    dt = pipe.prep.dt_s
    d_max = _delay_max(pipe)
    grid = dt * np.array([0.5, 1, 1.5, 2, 3, 4, 6, 8, 12, 16, 24, 32, 48, 64, 96, 128, 192, 256])
    grid = grid[grid <= d_max]
    return _fit_scalar(pipe, effects, lambda d: EffectFit("time_delay", "input", (d,)), grid)


def _fit_saturation(pipe: Pipeline, effects: dict[str, EffectFit]) -> EffectFit | None:
    best, best_cost = None, np.inf
    st = [pipe.stages(effects, ri) for ri in range(len(pipe.prep.records))]
    xs = np.concatenate([s["x_sat"] for s in st])
    ys = np.concatenate([s["y_drift"] for s in st])
    qs = np.array([0.6, 0.75, 0.85, 0.92, 0.96, 0.98, 0.99, 0.995])
    for side, sig in (("input", xs), ("output", ys)):
        for end in ("upper", "lower"):
            variant = f"{side}:{end}"
            grid = np.unique(np.quantile(sig, qs if end == "upper" else 1.0 - qs))
            fit = _fit_scalar(pipe, effects, lambda v, variant=variant: EffectFit("saturation", variant, (v,)), grid)
            if fit is None:
                continue
            c = _sse(pipe, _with(effects, fit))
            if c < best_cost:
                best, best_cost = fit, c
    # a slew-rate limit of the input: the gap only where the input moves faster than the limit
    grid = rate_grid(st[0]["x_delay"], pipe.prep.dt_s)
    rate, c = fit_log_scalar(lambda v: _sse(pipe, _with(effects, EffectFit("saturation", "slew", (v,)))), grid)
    if c < best_cost:
        best, best_cost = EffectFit("saturation", "slew", (rate,)), c
    return best


def _max_degree(u: np.ndarray, u_s: float) -> int:
    """Highest polynomial degree of a static map that the input's levels can identify.

    A static map is identified from the levels the input holds; when the input is a
    staircase (held most of the time), a polynomial through its ``L`` distinct held levels
    has at most degree ``L - 1`` (two levels, a single step: an affine map). Otherwise
    (a continuously varying input) :data:`STATIC_DEGREE`.
    """
    du = np.abs(np.diff(u))
    held = du <= 1e-9 * max(u_s, 1e-300)
    if held.mean() < 0.8:
        return STATIC_DEGREE
    levels = np.unique(np.round(u[1:][held] / (0.01 * 2 * u_s)))
    return int(max(1, min(STATIC_DEGREE, levels.size - 1)))


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

    def solve(cols_: slice, rows: np.ndarray) -> np.ndarray:
        # a little ridge on the unit-norm columns: monomials of high degree are nearly
        # collinear, and unregularised they trade huge coefficients of opposite signs
        M = An[rows][:, cols_]
        k = M.shape[1]
        lam = POLY_RIDGE * float(np.trace(M.T @ M)) / k
        return np.linalg.solve(M.T @ M + lam * np.eye(k), M.T @ r[rows])

    # two held levels (a step) cannot tell an affine map from a gain change of the linear
    # part: the map keeps only its offset then (a gain change is the load family's)
    degrees = tuple(d for d in degrees if d <= pipe.max_degree) if pipe.max_degree > 1 else (0,)
    best_d, best_cv = degrees[-1], np.inf
    if ha.any() and (~ha).any():
        for d in degrees:
            c = slice(0, d + 1)
            cv = 0.0
            for tr, te in ((ha, ~ha), (~ha, ha)):
                e = r[te] - An[te][:, c] @ solve(c, tr)
                cv += sumsq(e)
            if cv < best_cv * (1 - 1e-3):
                best_d, best_cv = d, cv
    c = slice(0, best_d + 1)
    return solve(c, np.ones(r.size, bool)) / scale[c]


def _fit_static(pipe: Pipeline, effects: dict[str, EffectFit]) -> EffectFit | None:
    best, best_cost = None, np.inf
    for variant in ("input", "internal"):
        slot = _SLOT[f"static_nonlinearity:{variant}"]
        base = {k: v for k, v in effects.items() if k != "static_nonlinearity"}
        basis = _static_basis(pipe, base, variant)
        th = _poly_ls(pipe, base, basis)
        if th.size > 1 and _nearly_linear(pipe, base, variant, basis, th):
            th = _poly_ls(pipe, base, basis, degrees=(0,))
        fit = EffectFit("static_nonlinearity", variant, tuple(map(float, th)))
        if _downstream_nonlinear(base, slot) or (variant == "input" and "hysteresis" in base):
            fit = _refine(pipe, base, fit, -np.inf, np.inf, max_nfev=25)
        c = _sse(pipe, _with(base, fit))
        if c < best_cost:
            best, best_cost = fit, c
    return best


def _static_basis(pipe: Pipeline, effects: dict[str, EffectFit], variant: str):
    """Least-squares basis of the static map ``variant``: the responses to its monomials."""
    def basis(ri, st):
        sim = pipe.linear_of(effects)
        if variant == "input":
            z = (st["x_map"] - pipe.u_c) / pipe.u_s
            return [sim.run(pipe.u_s * m) for m in monomials(z, STATIC_DEGREE + 1)]
        w = (st["y_lin"] - pipe.y_c) / pipe.y_s
        g1 = pipe.unit(sim)
        return [g1.run(pipe.y_s * m) for m in monomials(w, STATIC_DEGREE + 1)]

    return basis


def linear_static(pipe: Pipeline, effects: dict[str, EffectFit]) -> bool:
    """Whether the static map among ``effects`` is a linear correction rather than a nonlinearity.

    A map with a slope (any fit, e.g. one refined jointly with other effects) whose curvature
    removes less than :data:`NEAR_LINEAR_SHARE` of what the map removes beyond its offset, with
    the others in place, acts as a gain or a changed dynamic (an internal map's line passes
    through the dynamics once more), not as a static nonlinearity."""
    f = effects.get("static_nonlinearity")
    if f is None or len(f.theta) <= 1:
        return False
    base = {k: v for k, v in effects.items() if k != "static_nonlinearity"}
    return _nearly_linear(pipe, base, f.variant, _static_basis(pipe, base, f.variant), np.asarray(f.theta))


def _nearly_linear(pipe: Pipeline, base: dict[str, EffectFit], variant: str, basis, th: np.ndarray) -> bool:
    """Whether the map ``th`` is nearly a line: beyond its offset (the best constant map), its
    curvature (the part beyond the best line) removes less than :data:`NEAR_LINEAR_SHARE` of what
    the whole map removes; the rest is a slope, a linear correction."""
    def sse(t: np.ndarray) -> float:
        return _sse(pipe, _with(base, EffectFit("static_nonlinearity", variant, tuple(map(float, t)))))

    s_full = sse(th)
    beyond_offset = sse(_poly_ls(pipe, base, basis, degrees=(0,))) - s_full
    if beyond_offset <= 0:
        return False
    s_line = s_full if th.size <= 2 else sse(_poly_ls(pipe, base, basis, degrees=(1,)))
    return s_line - s_full < NEAR_LINEAR_SHARE * beyond_offset


def _fit_sensor(pipe: Pipeline, effects: dict[str, EffectFit]) -> EffectFit | None:
    def basis(ri, st):
        w = (st["y_sat"] - pipe.y_c) / pipe.y_s
        return [pipe.y_s * m for m in monomials(w, STATIC_DEGREE + 1)]

    th = _poly_ls(pipe, effects, basis)
    return EffectFit("sensor_nonlinearity", "output", tuple(map(float, th)))


def _reversals(pipe: Pipeline, u: np.ndarray) -> int:
    """Turning points of the input, ignoring wiggles smaller than a tenth of its range (1-99 %)."""
    return int(monotone_runs(play(u, 0.1 * pipe.u_s, float(u[0]))).size - 1)


def _branch(fit: EffectFit) -> float:
    """The starting branch ``c`` of a hysteresis fit (0 for fits without one)."""
    return float(fit.theta[len(HYST_THRESHOLDS)]) if len(fit.theta) > len(HYST_THRESHOLDS) else 0.0


def _fit_hysteresis(pipe: Pipeline, effects: dict[str, EffectFit]) -> EffectFit | None:
    """Weights by non-negative least squares for each starting branch of a small grid, then the
    branch refined between the best's neighbours: a log that starts after an unknown history
    starts somewhere inside the loop (its rest level is not the loop's centre)."""
    if min(_reversals(pipe, r.u) for r in pipe.prep.records if r.train.any()) < 2:
        return None  # a loop needs the input to turn back and forth: a step or a ramp cannot show one
    key = ("hfit",) + tuple(sorted((k, v.variant, v.theta) for k, v in effects.items() if v.slot < 3))

    def at(c: float) -> EffectFit:
        def basis(ri, st):
            sim = pipe.linear_of(effects)
            x = st["x_map"]
            return [sim.run(p - x) for p in pipe.plays(ri, x, key, c)]

        th = _ls(pipe, effects, basis, nonneg=True)
        return EffectFit("hysteresis", "input", tuple(map(float, th)) + (float(c),))

    fit = _fit_scalar(pipe, effects, at, np.array([-1.0, -0.5, 0.0, 0.5, 1.0]), maxiter=6)
    if fit is not None and _downstream_nonlinear(effects, 3):
        lo, hi = family_bounds(pipe, fit)
        fit = _refine(pipe, effects, fit, lo, hi, max_nfev=25)
    return fit


def _fit_load(pipe: Pipeline, effects: dict[str, EffectFit]) -> EffectFit | None:
    best, best_cost = None, np.inf
    for mu in (-0.5, -0.3, -0.15, 0.0, 0.15, 0.3, 0.6, 1.0, 2.0):
        base = _with(effects, EffectFit("load_mass", "model", (mu, 1.0)))
        # kappa enters linearly when nothing nonlinear is downstream: y_new = kappa * y_lin + rest
        cols, rhs = [], []
        for ri, rec in enumerate(pipe.prep.records):
            if rec.train.any():
                st = pipe.stages(base, ri)
                cols.append(st["y_lin"][rec.train])
                rhs.append((rec.y - st["y"] + st["y_lin"])[rec.train])
        a, b = np.concatenate(cols), np.concatenate(rhs)
        kappa = float(np.clip(np.einsum("i,i->", a, b) / max(sumsq(a), 1e-300), 0.05, 20.0))
        fit = EffectFit("load_mass", "model", (mu, kappa))
        c = _sse(pipe, _with(effects, fit))
        if c < best_cost:
            best, best_cost = fit, c
    assert best is not None
    fit = _refine(pipe, effects, best, np.array([-0.8, 0.05]), np.array([10.0, 20.0]), max_nfev=30,
                  x_scale=np.array([0.1, 0.1]))
    # the load's weight compresses the actuator: a static offset (a sag, <= 0) beside the changed
    # dynamics; only with a real change of the inertia (an offset alone is no sign of a load), and
    # kept when it lowers the training BIC (one more parameter, noise variance unknown)
    r = pipe.residuals(_with(effects, fit), "train")
    if r.size > 1 and r.mean() < 0 and abs(fit.theta[0]) >= LOAD_SAG_MIN_MU:
        sag = EffectFit("load_mass", "model:sag", fit.theta + (float(r.mean()),))
        lo, hi = family_bounds(pipe, sag)
        sag = _refine(pipe, effects, sag, lo, hi, max_nfev=15, x_scale=np.array([0.1, 0.1, 0.1 * pipe.y_s]))
        s0, s1 = sumsq(r), _sse(pipe, _with(effects, sag))
        if abs(sag.theta[0]) >= LOAD_SAG_MIN_MU and s1 > 0 and r.size * math.log(s0 / s1) > math.log(r.size):
            return sag
    return fit


def _fit_asym(pipe: Pipeline, effects: dict[str, EffectFit]) -> EffectFit | None:
    tdom = max(pipe.t_dom, 2 * pipe.prep.dt_s)
    best, best_cost = None, np.inf
    for k in (0.15, 0.5, 1.5, 4.0):
        for slow_down in (True, False):
            th = (0.0, k * tdom, 0.0) if slow_down else (k * tdom, 0.0, 0.0)
            fit = EffectFit("asymmetric_dynamics", "output", th)
            c = _sse(pipe, _with(effects, fit))
            if c < best_cost:
                best, best_cost = fit, c
    assert best is not None
    hi = 20.0 * tdom
    lag = _refine(pipe, effects, best, np.array([0.0, 0.0, -3.0]), np.array([hi, hi, 3.0]), max_nfev=15,
                  x_scale=np.array([0.1 * tdom, 0.1 * tdom, 0.3]))
    best, best_cost = lag, _sse(pipe, _with(effects, lag))
    # or a speed limit in one direction: the gap only while the output moves fast that way
    y_in = pipe.stages(effects, 0)["y_int"]
    for direction in DIRECTIONS:
        variant = f"rate_limit:{direction}"
        grid = rate_grid(y_in, pipe.prep.dt_s, direction=direction)
        rate, c = fit_log_scalar(
            lambda v, variant=variant: _sse(pipe, _with(effects, EffectFit("asymmetric_dynamics", variant, (v,)))), grid)
        if c < best_cost:
            best, best_cost = EffectFit("asymmetric_dynamics", variant, (rate,)), c
    return best


def _fit_drift(pipe: Pipeline, effects: dict[str, EffectFit]) -> EffectFit | None:
    span = pipe.span_s
    tau_min = _tau_min(pipe)
    taus = span * np.array([0.15, 0.3, 0.6, 1.2, 2.5, 5.0])
    taus = np.unique(np.clip(taus, tau_min, None))

    # drift is slow: its weights are fitted on slow parts only, else its low-pass (a 90 degree
    # lag at any fast frequency) could pose as the quadrature part of a hysteresis loop
    n_min = min(r.u.size for r in pipe.prep.records)
    smooth = int(min(max(10.0 * pipe.t_dom, 0.25 * tau_min) * pipe.prep.rate_hz, n_min / 4))

    def ls_at(tau: float) -> EffectFit:
        def basis(ri, st):
            q = pipe.charge(st["x_sat"], tau)
            return [st["y_asym"] * q, pipe.y_s * q]

        base = {k: v for k, v in effects.items() if k != "charge_drift"}
        g, o = _ls(pipe, base, basis, smooth=smooth)
        return EffectFit("charge_drift", "output", (float(tau), float(g), float(o)))

    best = min((ls_at(float(t)) for t in taus), key=lambda f: _sse(pipe, _with(effects, f)))
    lt = math.log(best.theta[0])
    res = optimize.minimize_scalar(lambda v: _sse(pipe, _with(effects, ls_at(math.exp(v)))),
                                   bounds=(max(lt - 0.7, math.log(tau_min)), lt + 0.7), method="bounded",
                                   options={"maxiter": 12})
    cand = ls_at(math.exp(float(res.x)))
    if _sse(pipe, _with(effects, cand)) < _sse(pipe, _with(effects, best)):
        best = cand
    return best  # no refinement on the full residual: that would undo the slow-only fit


def fit_drift_on_repeats(pipe: Pipeline, effects: dict[str, EffectFit], period_s: float
                         ) -> tuple[EffectFit, dict] | None:
    """Charge drift fitted on the change of the residual between repeats of the excitation.

    Where the input one period later is the same, a time-invariant model (any static map,
    lag or memory that has settled) predicts the same output, so the change of the
    residual between repeats is noise plus what varies in time: the drift's signature,
    free of the level-dependent part that a static map can take over when the levels of
    a log follow its history. The drift's weights are fitted by least squares on those
    changes over training pairs (both samples training), for each time constant of a grid.

    Returns
    -------
    (EffectFit, dict) or None
        The fit and ``{"train": (sse_before, sse_after, n, ||fitted||^2), "valid": (...)}``
        of the repeat changes (pairs with a validation sample and no final one); ``None`` when the
        log has too few matching pairs.
    """
    rec = pipe.prep.records[0]
    t, u = rec.t_s, rec.u
    tp = t + period_s
    inside = tp <= t[-1]
    same = np.zeros(t.size, bool)
    same[inside] = np.abs(np.interp(tp[inside], t, u) - u[inside]) <= 1e-3 * max(float(np.ptp(u)), 1e-300)
    k = np.clip(np.round((tp - t[0]) * pipe.prep.rate_hz).astype(int), 0, t.size - 1)
    pair_tr = same & rec.train & rec.train[k]
    pair_va = same & (rec.valid | rec.valid[k]) & ~rec.hold & ~rec.hold[k]
    if pair_tr.sum() < 50 or pair_va.sum() < 20:
        return None
    base = {k2: v for k2, v in effects.items() if k2 != "charge_drift"}
    st = pipe.stages(base, 0)

    def later(x: np.ndarray) -> np.ndarray:
        return np.interp(tp, t, x) - x

    d_r = later(rec.y - st["y"])
    tau_min = _tau_min(pipe)
    taus = np.unique(np.clip(pipe.span_s * np.array([0.15, 0.3, 0.6, 1.2, 2.5, 5.0]), tau_min, None))
    best = None
    for tau in taus:
        q = pipe.charge(st["x_sat"], float(tau))
        A = np.column_stack([later(st["y_asym"] * q), later(pipe.y_s * q)])
        sol = np.linalg.lstsq(A[pair_tr], d_r[pair_tr], rcond=None)[0]
        sse = sumsq(d_r[pair_tr] - A[pair_tr] @ sol)
        if best is None or sse < best[0]:
            best = (sse, float(tau), sol, A)
    _, tau, sol, A = best
    fit = EffectFit("charge_drift", "output", (tau, float(sol[0]), float(sol[1])))
    fitted = A @ sol

    def sse_pair(m: np.ndarray) -> tuple[float, float, int, float]:
        return sumsq(d_r[m]), sumsq(d_r[m] - fitted[m]), int(m.sum()), sumsq(fitted[m])

    return fit, {"train": sse_pair(pair_tr), "valid": sse_pair(pair_va)}


def family_bounds(pipe: Pipeline, fit: EffectFit) -> tuple[np.ndarray, np.ndarray]:
    """Lower and upper bounds of ``fit``'s parameters (for refinement)."""
    n = fit.n_params
    inf = np.full(n, np.inf)
    tdom = max(pipe.t_dom, 2 * pipe.prep.dt_s)
    if fit.name == "time_delay":
        return np.zeros(1), np.array([_delay_max(pipe)])
    if fit.name == "hysteresis":
        lo, hi = np.zeros(n), inf.copy()
        if n > len(HYST_THRESHOLDS):
            lo[len(HYST_THRESHOLDS)], hi[len(HYST_THRESHOLDS)] = -1.0, 1.0
        return lo, hi
    if fit.name == "load_mass" and n > 2:
        return np.array([-0.8, 0.05, -np.inf]), np.array([10.0, 20.0, 0.0])
    if fit.name == "load_mass":
        return np.array([-0.8, 0.05]), np.array([10.0, 20.0])
    if fit.variant == "slew" or fit.variant.startswith("rate_limit"):
        return np.array([1e-12]), np.array([np.inf])
    if fit.name == "asymmetric_dynamics":
        return np.array([0.0, 0.0, -3.0]), np.array([20.0 * tdom, 20.0 * tdom, 3.0])
    if fit.name == "charge_drift":
        return np.array([_tau_min(pipe), -np.inf, -np.inf]), np.array([10 * pipe.span_s, np.inf, np.inf])
    return -inf, inf


def joint_refine(pipe: Pipeline, effects: dict[str, EffectFit], max_nfev: int = 12) -> dict[str, EffectFit]:
    """All parameters of ``effects`` refined together on the training samples (variants kept)."""
    if not effects:
        return effects
    # the drift's weights stay as fitted on slow parts (see _fit_drift), a measured range as measured
    fixed = {k: v for k, v in effects.items()
             if k in (LINEAR, "charge_drift") or v.variant.startswith("measured")}
    effects = {k: v for k, v in effects.items() if k not in fixed}
    if not effects:
        return fixed
    names = list(effects)
    sizes = [effects[k].n_params for k in names]
    x0 = np.concatenate([np.asarray(effects[k].theta, float) for k in names])
    bl = [family_bounds(pipe, effects[k]) for k in names]
    lo = np.concatenate([b[0] for b in bl])
    hi = np.concatenate([b[1] for b in bl])
    x0 = np.clip(x0, lo, hi)

    def build(x: np.ndarray) -> dict[str, EffectFit]:
        out, i = dict(fixed), 0
        for k, m in zip(names, sizes):
            out[k] = EffectFit(k, effects[k].variant, tuple(map(float, x[i:i + m])))
            i += m
        return out

    base_cost = _sse(pipe, build(x0))
    try:
        res = optimize.least_squares(lambda x: pipe.residuals(build(x), "train"), x0, bounds=(lo, hi),
                                     method="trf", max_nfev=max_nfev, x_scale="jac", diff_step=1e-3)
    except (ValueError, np.linalg.LinAlgError):
        return {**effects, **fixed}
    return build(res.x) if 2.0 * res.cost < base_cost else {**effects, **fixed}


def _delay_max(pipe: Pipeline) -> float:
    dt = pipe.prep.dt_s
    return min(0.1 * pipe.span_s, max(60.0 * dt, 0.5 * pipe.t_dom))


def _tau_min(pipe: Pipeline) -> float:
    return max(20.0 * pipe.t_dom, 0.3 * pipe.span_s, 50.0 * pipe.prep.dt_s)


_FITTERS = {
    "time_delay": _fit_delay, "saturation": _fit_saturation, "static_nonlinearity": _fit_static,
    "hysteresis": _fit_hysteresis, "load_mass": _fit_load, "asymmetric_dynamics": _fit_asym,
    "charge_drift": _fit_drift, "sensor_nonlinearity": _fit_sensor,
}


def fit_family(pipe: Pipeline, effects: dict[str, EffectFit], name: str,
               init: EffectFit | None = None) -> EffectFit | None:
    """Fit the augmentation ``name`` on the training samples with ``effects`` held fixed.

    ``init`` (a previous fit of the same family) lets the families searched by a grid and
    a nonlinear refinement (asymmetric dynamics, load) skip the grid: a warm start.

    Returns
    -------
    EffectFit or None
        ``None`` if the family cannot be fitted on these data.
    """
    base = {k: v for k, v in effects.items() if k != name}
    try:
        if init is not None and init.name == name and name in ("asymmetric_dynamics", "load_mass"):
            lo, hi = family_bounds(pipe, init)
            return _refine(pipe, base, init, lo, hi, max_nfev=10)
        return _FITTERS[name](pipe, base)
    except (np.linalg.LinAlgError, ValueError, FloatingPointError):
        return None


def describe_params(pipe: Pipeline, fit: EffectFit, units: tuple[str, str] = ("", ""),
                    effects: dict[str, EffectFit] | None = None) -> dict:
    """The fitted parameters of ``fit`` in physical terms (JSON-ready).

    ``effects`` (the whole augmented set) lets a static map's offset be given in output
    units through the linear part's static gain."""
    ui, uo = units
    th = fit.theta
    out: dict = {"variant": fit.variant}
    if fit.name == "time_delay":
        out["delay_s"] = th[0]
    elif fit.name == "saturation" and fit.variant == "slew":
        out["acts_on"] = "input"
        out["slew_rate_limit"] = th[0]
        out["unit"] = f"{ui}/s" if ui else "input units/s"
        out["form"] = "x_k = x_(k-1) + clip(u_k - x_(k-1), -S dt, S dt): the input moves at most S per second"
    elif fit.name == "saturation":
        side, end = fit.variant.split(":")
        out["acts_on"] = "output" if side == "measured" else side
        out["unit"] = ui if side == "input" else uo
        if end == "both":
            out["lower"], out["upper"] = th[0], th[1]
        else:
            out["upper" if end == "upper" else "lower"] = th[0]
        if side == "measured":
            out["measured_range"] = True
            out["note"] = "the measured output piles up on these values: applied last, to what is measured"
    elif fit.name in ("static_nonlinearity", "sensor_nonlinearity"):
        side = "output" if fit.name == "sensor_nonlinearity" else ("input" if fit.variant == "input" else "output")
        c, s = (pipe.u_c, pipe.u_s) if side == "input" else (pipe.y_c, pipe.y_s)
        names = (tuple(f"z^{j}" for j in range(len(th))) if fit.name == "static_nonlinearity"
                 else tuple(f"w^{j}" for j in range(len(th))))
        out["coefficients"] = dict(zip(names, th))
        out["normalisation"] = {"centre": c, "half_range": s, "unit": ui if side == "input" else uo,
                                "form": ("x + s*sum_j a_j z^j, z = (x - c)/s"
                                         if fit.name == "static_nonlinearity" and fit.variant == "input" else
                                         "y + G1(s*sum_j b_j w^j), w = (y - c)/s, G1 = G/G(0)"
                                         if fit.name == "static_nonlinearity" else
                                         "y + s*sum_j c_j w^j, w = (y - c)/s")}
        xs = np.linspace(c - s, c + s, 9)
        z = (xs - c) / s
        dev = s * poly_map(th, z)
        out["curve"] = {"at": xs.tolist(), "deviation": dev.tolist()}
        if fit.name == "static_nonlinearity":
            g0 = pipe.linear_of(effects or {}).dc_gain if fit.variant == "input" else 1.0
            out["output_offset_at_centre"] = float(g0 * s * th[0])
            out["output_offset_unit"] = uo
    elif fit.name == "hysteresis":
        out["thresholds"] = list(pipe.thresholds)
        out["weights"] = list(th[:len(HYST_THRESHOLDS)])
        out["unit"] = ui
        out["loop_half_width"] = float(sum(w * r for w, r in zip(th, pipe.thresholds)))
        out["initial_branch"] = _branch(fit)
        out["initial_branch_note"] = "plays start at x0 + c*r: -1 rising branch, 0 centred, 1 falling branch"
    elif fit.name == "load_mass":
        out["mass_ratio"] = th[0]
        out["gain_factor"] = th[1]
        out["resonance_factor"] = 1.0 / math.sqrt(1.0 + th[0]) if th[0] > -1 else float("nan")
        if len(th) > 2:
            out["offset"] = th[2]
            out["offset_unit"] = uo
            out["offset_note"] = "a static offset beside the changed dynamics: the load's weight compresses"
    elif fit.name == "asymmetric_dynamics" and fit.variant.startswith("rate_limit"):
        out["direction"] = fit.variant.split(":")[1]
        out["speed_limit"] = th[0]
        out["unit"] = f"{uo}/s" if uo else "output units/s"
        out["form"] = (f"the output follows at once, but while {out['direction']} moves at most "
                       f"speed_limit per second")
    elif fit.name == "asymmetric_dynamics":
        out["tau_rising_s"] = th[0] if th[0] >= 1e-6 else 0.0
        out["tau_falling_s"] = th[1] if th[1] >= 1e-6 else 0.0
        out["falling_tau_level_slope"] = th[2]
        out["form"] = "lag: tau_rising while rising, tau_falling*exp(k*w) while falling, w = (y - c)/s"
    elif fit.name == "charge_drift":
        out["tau_s"] = th[0]
        out["gain_change_per_input_half_range"] = th[1]
        out["offset_per_input_half_range"] = th[2] * pipe.y_s
        out["unit"] = uo
    return out
