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
                                            the input moves at most ``S`` per second;
                                            (``output:slew``) the output likewise
static_nonlinearity input or internal       input map ``x + s sum_j a_j z^j`` (degree 5),
                    (or after_hysteresis)   (``after_hysteresis``: the same map of the
                                            hysteresis output, offered only beside an
                                            accepted hysteresis),
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
                                            ``model:zeta``: their frequency over
                                            ``sqrt(1 + mu)``, damping ratio kept;
                                            ``model:damp``: frequency over
                                            ``sqrt(1 + mu)``, damping ratio times
                                            ``delta``; ``model:mode``: an added
                                            pole pair above the resonance;
                                            ``model:notch``: the zero pairs (the
                                            anti-resonance) moved; ``model:pair``: an
                                            added pole-zero pair below the resonance;
                                            ``model:real``: the real poles times a
                                            factor (a viscous load);
                                            ``...:sag``: and a static
                                            offset ``<= 0`` (the load's weight)
asymmetric_dynamics output                  first-order lag, one time constant while
                                            the output rises, another while it falls
                                            (log-linear in the level); or
                                            (``rate_limit:falling|rising``) a speed
                                            limit ``R`` per second in one direction
charge_drift        output                  ``y (1 + g q) + s o q``, ``q`` a slow
                                            (``tau``) low-pass of the input's history
sensor_nonlinearity output (last)           ``y + s sum_j c_j w^j`` (degree 5)
=================== ======================= =========================================

The chain order is: delay, input saturation, input map, hysteresis, map after the hysteresis, G (with load),
internal map, asymmetric lag, drift, output saturation, sensor map, measured clip.
:class:`Pipeline` simulates any combination with caching of the unchanged upstream
stages; :func:`fit_family` fits one family's few parameters on the training samples
with the others held fixed (linear least squares where the form is linear in its
parameters, a small grid plus bounded refinement otherwise).

Each family's form, fit, bounds and description live in its own module under
:mod:`hasel.effects` (registered in :mod:`hasel.effects.registry`); this module is the
diagnosis's pipeline over them and keeps the names the diagnosis imports.
"""
from __future__ import annotations

import hashlib
import math
from dataclasses import dataclass, field

import numpy as np
from scipy import optimize, signal

from hasel.diagnose.pool import pmap
from hasel.diagnose.prep import LinearSim, Prepared, dominant_time_constant_s, flat_extremes
from hasel.effects.asymmetric import DIRECTIONS, speed_limit  # noqa: F401 - kept importable here
from hasel.effects.asymmetric import INPUT as ASYM_INPUT
from hasel.effects.asymmetric import lag as _asym_lag
from hasel.effects.base import LINEAR, SLOT_ORDER, EffectFit
from hasel.effects.delay import delay_max as _delay_max
from hasel.effects.delay import shift as _shift
from hasel.effects.drift import _tau_min, fit_drift_on_repeats
from hasel.effects.drift import pipe_output as drift_output
from hasel.effects.fitkit import (POLY_RIDGE, STATIC_DEGREE, _downstream_nonlinear, _fit_scalar,  # noqa: F401
                                  _ls, _poly_ls, _refine, _sse, _train_halves, _train_smooth, _with, fit_log_scalar,
                                  monomial, monomials, poly_map, rate_grid, sumsq)
from hasel.effects.hysteresis import HYST_THRESHOLDS, output_thresholds
from hasel.effects.hysteresis import OUTPUT as OUTPUT_HYST
from hasel.effects.hysteresis import branch as _branch
from hasel.effects.load import (LOAD_SAG_MIN_MU, apply_zero_form, damping_factor, keeps_zeta, load_offset,  # noqa: F401
                               loaded_den, mode_of, zero_form)
from hasel.effects.operators import play
from hasel.effects.registry import FAMILIES as _REGISTRY
from hasel.effects.saturation import clip as _clip
from hasel.effects.saturation import OUTPUT_SLEW, measured_clip, slew_limit
from hasel.effects.static_map import NEAR_LINEAR_SHARE, linear_static  # noqa: F401
from hasel.effects.static_map import AFTER_HYST, apply_input
from hasel.effects.static_map import max_degree as _max_degree

__all__ = ["EffectFit", "Pipeline", "fit_family", "linear_static", "fit_drift_on_repeats", "measured_clip",
           "joint_refine", "family_bounds", "FAMILIES", "HYST_THRESHOLDS", "describe_params", "LINEAR", "INPUT_SIDE",
           "make_linear", "split_linear", "family_signature"]

#: Effect names in chain order of their (first) slot.
FAMILIES = ("time_delay", "saturation", "static_nonlinearity", "hysteresis", "load_mass",
            "asymmetric_dynamics", "charge_drift", "sensor_nonlinearity")
#: Families whose fits the diagnosis also tries with the linear model re-identified through them (by name: see
#: :func:`hasel.diagnose.core._relinear` for why not by slot).
INPUT_SIDE = ("time_delay", "saturation", "static_nonlinearity", "hysteresis")
_SLOT = SLOT_ORDER


def _load_form(f: "EffectFit | None") -> tuple:
    """The arguments of :meth:`Pipeline.loaded` for the load fit ``f`` (None: no load): mass ratio, gain
    factor, damping ratio kept, damping factor (or None), added mode ``(Hz, damping ratio)`` (or None) and the
    numerator's change (:func:`hasel.effects.load.zero_form`, or None)."""
    if f is None:
        return 0.0, 1.0, False, None, None, None
    return float(f.theta[0]), float(f.theta[1]), keeps_zeta(f), damping_factor(f), mode_of(f), zero_form(f)


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
        self.nominal = self.prep.sim(self.num, self.den)
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
        # the held-out block score a family's own choice between its forms asks (the diagnosis sets its
        # DiagnoseOptions.t_min here; None: no held-out choice, as outside a diagnosis)
        self.t_min: float | None = None
        # the measured output piling up on its extreme (a clip): that value is a candidate limit
        self.clips = {end: v for end, (v, _) in flat_extremes(self.prep.records[0].y).items()}

    def retime(self, offset: float) -> None:
        """Take the output at ``offset`` working samples into each interval from now on
        (:attr:`Prepared.sample_offset`): the nominal simulation is rebuilt and every cached linear
        simulation and stage output dropped."""
        self.prep.sample_offset = float(offset)
        self.nominal = self.prep.sim(self.num, self.den)
        self._lin.clear()
        self._cache.clear()

    @property
    def span_s(self) -> float:
        """Length of the data log, s."""
        r = self.prep.records[0]
        return float(r.t_s[-1] - r.t_s[0] + self.prep.dt_s)

    # -- linear model with load --------------------------------------------------------------
    def loaded(self, mu: float, kappa: float = 1.0, lin: "EffectFit | None" = None,
               zeta_kept: bool = False, damping: float | None = None,
               mode: tuple[float, float] | None = None, zeros: tuple | None = None) -> LinearSim:
        """The model (``lin``, a re-identified linear part, or the nominal) with ``1 + mu`` times
        the inertia of its resonances (``zeta_kept``: their frequency lowered, damping ratio kept;
        ``damping``: their frequency over ``sqrt(1 + mu)`` and their damping ratio times ``damping``;
        ``mode``: an added pole pair (Hz, damping ratio); :func:`hasel.effects.load.loaded_den`; ``zeros``: the
        zero pairs moved, a pole-zero pair added or the real poles scaled, :func:`hasel.effects.load.apply_zero_form`) (cached), times the
        gain ``kappa``."""
        base = ("nominal",) if lin is None else lin.theta
        if damping is not None and damping == 1.0 and mu == 0.0:
            damping = None
        key = (round(mu, 12), bool(zeta_kept) and mu != 0.0,
               None if damping is None else round(float(damping), 12), mode, zeros) + base
        sim = self._lin.get(key)
        if sim is None:
            num, den = (self.num, self.den) if lin is None else split_linear(lin)
            if mu == 0.0 and damping is None and mode is None and zeros is None:
                sim = self.nominal if lin is None else self.prep.sim(num, den)
            else:
                sim = self.prep.sim(*apply_zero_form(num, loaded_den(den, mu, zeta_kept=zeta_kept, damping=damping,
                                                                     mode=mode), zeros))
            if len(self._lin) > 64:
                self._lin.clear()
            self._lin[key] = sim
        if kappa == 1.0:
            return sim
        return _Scaled(sim, kappa)  # type: ignore[return-value]

    def linear_of(self, effects: dict[str, "EffectFit"]) -> "LinearSim | _Scaled":
        """The linear part of the chain for ``effects`` (re-identified model and load included)."""
        mu, kappa, zk, dk, md, zf = _load_form(effects.get("load_mass"))
        return self.loaded(mu, kappa, effects.get(LINEAR), zk, dk, md, zf)

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

        Keys: ``"x_delay"``, ``"x_sat"``, ``"x_map"``, ``"x_hyst"`` (after the hysteresis), ``"x_eff"`` (after
        a map of the hysteresis output, if any: the linear part's input) (input side), ``"y_lin"``,
        ``"y_int"``, ``"y_asym"`` (after an asymmetric lag and a loop of the output, ``hysteresis:output``),
        ``"y_drift"``, ``"y_sat"``, ``"y"`` (output side); a stage
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
        f = e.get("asymmetric_dynamics")
        if f is not None and f.variant == ASYM_INPUT:  # the lag of the voltage itself (what a drift then sees)
            key += ("ai",) + f.theta
            x = self._memo(("x", ri) + key, lambda x=x, f=f: _asym_lag(x, self.prep.dt_s, f.theta, self.u_c,
                                                                          self.u_s))
        out["x_sat"] = x
        f = e.get("static_nonlinearity")
        if f is not None and f.variant.split(":")[0] == "input":  # the polynomial or the dead band
            key += ("mi", f.variant) + f.theta
            x = apply_input(f, x, self.u_c, self.u_s)
        out["x_map"] = x
        f = e.get("hysteresis")
        if f is not None and f.variant != OUTPUT_HYST:
            # the starting branch is that of the log it was fitted on (record 0); another log's
            # history is unknown: its plays start centred
            ps = self.plays(ri, x, key, _branch(f) if ri == 0 else 0.0)
            k2 = key + ("h",) + f.theta
            x = x + sum(w * (p - x) for w, p in zip(f.theta[:len(HYST_THRESHOLDS)], ps))
            key = k2
        out["x_hyst"] = x
        f = e.get("static_nonlinearity")
        # a map of the hysteresis output (the polynomial or the knee; before the dynamics)
        if f is not None and f.variant.split(":")[0] == AFTER_HYST:
            key += ("mh", f.variant) + f.theta
            x = apply_input(f, x, self.u_c, self.u_s)
        out["x_eff"] = x
        f = e.get("load_mass")
        mu, kappa, zk, dk, md, zf = _load_form(f)
        lin = e.get(LINEAR)
        key += ("l", mu, kappa, zk, dk, md, zf) + (lin.theta if lin is not None else ())
        sim = self.loaded(mu, kappa, lin, zk, dk, md, zf)
        y = self._memo(("y", ri) + key, lambda: sim.run(x))
        if f is not None and "sag" in f.variant.split(":"):  # the load's weight: a static offset (a sag)
            key += ("sag", load_offset(f))
            y = y + load_offset(f)
        out["y_lin"] = y
        f = e.get("static_nonlinearity")
        if f is not None and f.variant == "internal":
            key += ("mn",) + f.theta
            w = (y - self.y_c) / self.y_s
            y = y + self.unit(sim).run(self.y_s * poly_map(f.theta, w))
        out["y_int"] = y
        f = e.get("asymmetric_dynamics")
        if f is not None and f.variant != ASYM_INPUT:
            # a state-dependent recursion: kept for the fits that hold it fixed (of the stages after it)
            key += ("a", f.variant) + f.theta
            y = self._memo(("ya", ri) + key, lambda y=y, f=f: self._asym(y, f))
        f = e.get("hysteresis")
        if f is not None and f.variant == OUTPUT_HYST:
            # a loop of the stroke; its starting branch as the input's (record 0's own, others centred)
            c = _branch(f) if ri == 0 else 0.0
            key += ("ho", c) + f.theta
            y = self._memo(("yh", ri) + key, lambda y=y, f=f, c=c: y + sum(
                w * (play(y, r, float(y[0]) + c * r) - y)
                for w, r in zip(f.theta[:len(HYST_THRESHOLDS)], output_thresholds(self.y_s))))
        out["y_asym"] = y
        f = e.get("charge_drift")
        if f is not None and f.variant != "output":
            y = drift_output(self, out["x_sat"], y, f)
        elif f is not None:
            q = self.charge(out["x_sat"], f.theta[0])
            y = y * (1.0 + f.theta[1] * q) + self.y_s * f.theta[2] * q
        out["y_drift"] = y
        f = e.get("saturation")
        if f is not None and f.variant == OUTPUT_SLEW:
            y = slew_limit(y, f.theta[0], self.prep.dt_s)
        elif f is not None and f.variant.startswith("output"):
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

    def _asym(self, y: np.ndarray, f: EffectFit) -> np.ndarray:
        """The asymmetric-dynamics stage ``f`` applied to the output ``y`` (speed limit or lag)."""
        if f.variant.startswith("rate_limit"):
            return speed_limit(y, f.theta[0], self.prep.dt_s, f.variant.split(":")[1])
        return _asym_lag(y, self.prep.dt_s, f.theta, self.y_c, self.y_s)

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



class _Scaled:
    """A linear simulator times a constant."""

    def __init__(self, sim: LinearSim, k: float) -> None:
        self.sim, self.k = sim, float(k)
        self.dc_gain = sim.dc_gain * self.k

    def run(self, u: np.ndarray) -> np.ndarray:
        return self.k * self.sim.run(u)


def make_linear(num: np.ndarray, den: np.ndarray) -> EffectFit:
    """A re-identified linear model as the pseudo-effect :data:`LINEAR`."""
    num = np.atleast_1d(np.asarray(num, float))
    den = np.atleast_1d(np.asarray(den, float))
    return EffectFit(LINEAR, "model", (float(num.size),) + tuple(map(float, num)) + tuple(map(float, den)))


def split_linear(fit: EffectFit) -> tuple[np.ndarray, np.ndarray]:
    """``(num, den)`` of a :data:`LINEAR` pseudo-effect."""
    k = int(fit.theta[0])
    return np.asarray(fit.theta[1:1 + k]), np.asarray(fit.theta[1 + k:])



# ---------------------------------------------------------------------------------------------
# the families, through the registry


def family_bounds(pipe: Pipeline, fit: EffectFit) -> tuple[np.ndarray, np.ndarray]:
    """Lower and upper bounds of ``fit``'s parameters (for refinement): the family's own."""
    return _REGISTRY[fit.name].bounds(pipe, fit)


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
        # the finite-difference columns are independent: they run in the diagnosis's processes
        # (the same evaluations as in series; :mod:`hasel.diagnose.pool`)
        res = optimize.least_squares(lambda x: pipe.residuals(build(x), "train"), x0, bounds=(lo, hi),
                                     method="trf", max_nfev=max_nfev, x_scale="jac", diff_step=1e-3, workers=pmap)
    except (ValueError, np.linalg.LinAlgError):
        return {**effects, **fixed}
    return build(res.x) if 2.0 * res.cost < base_cost else {**effects, **fixed}



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
    fam = _REGISTRY[name]
    try:
        if init is not None and init.name == name and fam.warm_start:
            return fam.refine_from(pipe, base, init)
        return fam.fit(pipe, base)
    except (np.linalg.LinAlgError, ValueError, FloatingPointError):
        return None


def describe_params(pipe: Pipeline, fit: EffectFit, units: tuple[str, str] = ("", ""),
                    effects: dict[str, EffectFit] | None = None) -> dict:
    """The fitted parameters of ``fit`` in physical terms (JSON-ready): the family's own description.

    ``effects`` (the whole augmented set) lets a static map's offset be given in output
    units through the linear part's static gain."""
    return _REGISTRY[fit.name].describe(pipe, fit, units, effects or {})


def family_signature(pipe: Pipeline, fit: EffectFit, effects: dict[str, EffectFit] | None = None) -> dict:
    """The family's own evidence for ``fit`` (e.g. where in frequency it moves the response)."""
    return _REGISTRY[fit.name].signature(pipe, fit, effects or {})
