"""``asymmetric_dynamics``: relaxation slower (or faster) than activation.

Forms
-----
- truth :class:`AsymmetricDynamics`: a first-order lag on the stroke, ``tau_activate_s``
  while rising and ``tau_relax_s (1 + k max(0, 1 - z / stroke_ref_mm))`` while falling
  (:func:`hasel.effects.operators.asymmetric_lag`).
- generic ``output`` (``theta = (tau_rise, tau_fall, k)``): the same lag, the falling time
  constant ``tau_fall exp(k w)`` log-linear in the level ``w = (y - y_c) / y_s``
  (:func:`lag`; ``k = 0`` runs the truth form's kernel);
- generic ``rate_limit:falling|rising`` (``(R,)``): the output follows at once, but moves
  at most ``R`` per second in that direction (:func:`speed_limit`);
- generic ``input`` (``(tau_rise, tau_fall)``): the same direction-dependent lag on the
  voltage, before the input map and the dynamics (an amplifier that charges the actuator
  fast and lets it discharge through a resistor, or the reverse); slot
  ``asymmetric_dynamics:input`` of :data:`hasel.effects.base.SLOT_ORDER`.

All carry their last output between chunks (:class:`LagStage`, :class:`SpeedStage`).
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import ClassVar

import numpy as np

from hasel.effects.base import Effect, EffectFamily, EffectFit, FitContext, Scales
from hasel.effects.drift import _held_out_prefers
from hasel.effects.fitkit import _refine, _sse, _with, fit_log_scalar, rate_grid
from hasel.effects.operators import asymmetric_lag, exp_level_lag, rate_limited, rate_step
from hasel.validate import in_range, positive

__all__ = ["AsymmetricDynamics", "DIRECTIONS", "INPUT", "speed_limit", "lag", "LagStage", "SpeedStage",
           "AsymmetricFamily", "FAMILY"]

#: Directions a speed limit of the output may act in.
DIRECTIONS = ("falling", "rising")
#: The variant of the lag on the voltage (before the dynamics).
INPUT = "input"
#: The input lag is a candidate only where its slower time constant is at least this many times its faster one
#: (a direction-dependent lag; a round factor of two, set before any run on the tuning sets).
INPUT_ASYMMETRY = 2.0


@dataclass(frozen=True)
class AsymmetricDynamics(Effect):
    """Relaxation slower and more damped than activation.

    The stroke follows the nominal stroke ``z_n`` through a first-order lag whose time
    constant depends on the direction: ``tau_activate_s`` while ``z_n`` is above the
    stroke (activation, the electrostatic force pulls), and during relaxation (the
    elastic wrap pushes the liquid back through the zipped region) ``tau_relax_s``,
    growing as the stroke falls: ``tau_relax_s (1 + stroke_dependence *
    max(0, 1 - z / stroke_ref_mm))``.

    Attributes
    ----------
    tau_relax_s : float
        Relaxation time constant at ``stroke_ref_mm``, s.
    tau_activate_s : float
        Activation time constant, s (0: activation follows the nominal model).
    stroke_dependence : float
        Relative growth of the relaxation time constant towards zero stroke.
    stroke_ref_mm : float
        Stroke where the relaxation time constant is ``tau_relax_s``, mm.
    """

    name: ClassVar[str] = "asymmetric_dynamics"
    tau_relax_s: float = 0.08
    tau_activate_s: float = 0.0
    stroke_dependence: float = 0.5
    stroke_ref_mm: float = 8.0

    def __post_init__(self) -> None:
        positive("tau_relax_s", self.tau_relax_s)
        in_range("tau_activate_s", self.tau_activate_s, 0.0, 10.0)
        in_range("stroke_dependence", self.stroke_dependence, 0.0, 10.0)
        positive("stroke_ref_mm", self.stroke_ref_mm)

    @classmethod
    def sample_params(cls, rng: np.random.Generator) -> "AsymmetricDynamics":
        return cls(tau_relax_s=float(rng.uniform(0.03, 0.15)), tau_activate_s=float(rng.uniform(0.0, 0.004)),
                   stroke_dependence=float(rng.uniform(0.0, 1.0)), stroke_ref_mm=8.0)


def speed_limit(z: np.ndarray, rate: float, dt: float, direction: str = "falling",
                y0: float | None = None) -> np.ndarray:
    """``z`` followed at once in one direction and at most at ``rate`` in the other.

    Parameters
    ----------
    z : ndarray, shape (n,)
        The unlimited output, sampled every ``dt`` seconds.
    rate : float
        Largest speed in ``direction``, units of ``z`` per second (> 0; ``inf``: no limit).
    dt : float
        Sample interval, s.
    direction : {"falling", "rising"}
        The limited direction.
    y0 : float, optional
        State before the first sample (default ``z[0]``).

    Returns
    -------
    ndarray, shape (n,)
        Falling: ``y_k = z_k`` if ``z_k >= y_{k-1}``, else ``max(z_k, y_{k-1} - rate dt)``.
    """
    if direction not in DIRECTIONS:
        raise ValueError(f"direction must be one of {DIRECTIONS}, got {direction!r}")
    step = rate_step(rate, dt)
    return rate_limited(z, math.inf, step, y0) if direction == "falling" else rate_limited(z, step, math.inf, y0)


def lag(y: np.ndarray, dt: float, theta: tuple[float, ...], y_c: float, y_s: float,
        z0: float | None = None) -> np.ndarray:
    """Direction-dependent lag: ``tau_rise`` while rising, ``tau_fall exp(k w)`` while falling.

    ``w = (z - y_c) / y_s`` (clipped to [-2, 2]) lets the falling time constant depend on
    the level (log-linearly; ``k = 0``: constant). Starts from ``z0`` (default ``y[0]``).
    """
    tau_up, tau_dn = theta[0], theta[1]
    k = theta[2] if len(theta) > 2 else 0.0
    z = float(y[0]) if z0 is None else float(z0)
    if k == 0.0:
        return asymmetric_lag(y, dt, tau_up, tau_dn, z)
    return exp_level_lag(y, dt, tau_up, tau_dn, k, y_c, y_s, z)


class LagStage:
    """A direction-dependent lag carrying its output; ``run_fn(x, z0)`` is the law."""

    def __init__(self, run_fn) -> None:
        self.run_fn = run_fn
        self.z = 0.0

    def reset(self, x0: float) -> None:
        """Settled at ``x0``."""
        self.z = float(x0)

    def run(self, x: np.ndarray, u: np.ndarray | None = None) -> np.ndarray:
        """Output for the next samples."""
        x = np.asarray(x, float)
        if x.size == 0:
            return x.copy()
        y = self.run_fn(x, self.z)
        self.z = float(y[-1])
        return y


class SpeedStage(LagStage):
    """A one-directional speed limit (:func:`speed_limit`) carrying its output."""

    def __init__(self, rate: float, dt_s: float, direction: str) -> None:
        super().__init__(lambda x, z0: speed_limit(x, rate, dt_s, direction, z0))


def _fit_asym(pipe: FitContext, effects: dict[str, EffectFit]) -> EffectFit | None:
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
    # or the lag on the voltage, before the dynamics: the same grid of starts, refined
    best_in, c_in = None, np.inf
    # (the faster direction is not always instant: an amplifier's charging lag is short, not none, and left at
    # zero a delay then takes its place)
    for k in (0.15, 0.5, 1.5, 4.0):
        for r in (0.0, 0.1):
            for slow_down in (True, False):
                th = (r * k * tdom, k * tdom) if slow_down else (k * tdom, r * k * tdom)
                fit = EffectFit("asymmetric_dynamics", INPUT, th)
                c = _sse(pipe, _with(effects, fit))
                if c < c_in:
                    best_in, c_in = fit, c
    if best_in is not None:
        lag_in = _refine(pipe, effects, best_in, np.array([0.0, 0.0]), np.array([hi, hi]), max_nfev=15,
                         x_scale=np.array([0.1 * tdom, 0.1 * tdom]))
        c = _sse(pipe, _with(effects, lag_in))
        slow_t, fast_t = max(lag_in.theta[:2]), min(lag_in.theta[:2])
        if slow_t < INPUT_ASYMMETRY * fast_t:
            # near-equal time constants are a plain low-pass of the voltage, a linear change a delay or a load
            # names (held back maps seed 42 and m22: 2.6 / 2.6 ms and 2.8 / 3.1 ms beside a sensor curve and a load)
            c = np.inf
        # the lag of the voltage replaces the output's forms only where the held-out blocks prefer it at the
        # acceptance's own score: on training it also takes a plain lag and a short delay after it (multi2.py
        # seed 21 #26: an RC drive then a 1.3 ms delay and a 3 ms lag, fitted as one 8.6 / 27.6 ms input lag)
        if c < best_cost and _held_out_prefers(pipe, _with(effects, best), _with(effects, lag_in)):
            best, best_cost = lag_in, c
    return best



class AsymmetricFamily(EffectFamily):
    """The ``asymmetric_dynamics`` family (see the module's docstring)."""

    name = "asymmetric_dynamics"
    slot = "output"
    variants = ("output", "rate_limit", INPUT)
    warm_start = True
    truth_class = AsymmetricDynamics

    def param_names(self, fit: EffectFit) -> tuple[str, ...]:
        """``("speed_limit",)`` or ``("tau_rising_s", "tau_falling_s", "falling_tau_level_slope")``."""
        if fit.variant.startswith("rate_limit"):
            return ("speed_limit",)
        return ("tau_rising_s", "tau_falling_s", "falling_tau_level_slope")[:len(fit.theta)]

    def stage(self, fit: EffectFit, scales: Scales, dt_s: float) -> LagStage:
        """The lag (normalised by ``scales.y_c``/``y_s``; on the input by ``u_c``/``u_s``) or the speed limit."""
        if fit.variant.startswith("rate_limit"):
            return SpeedStage(fit.theta[0], dt_s, fit.variant.split(":")[1])
        if fit.variant == INPUT:
            th, uc, us = fit.theta, scales.u_c, scales.u_s
            return LagStage(lambda x, z0: lag(x, dt_s, th, uc, us, z0))
        th, yc, ys = fit.theta, scales.y_c, scales.y_s
        return LagStage(lambda x, z0: lag(x, dt_s, th, yc, ys, z0))

    def truth_stage(self, effect: Effect, dt_s: float) -> LagStage:
        """The truth form's lag (linear level law)."""
        assert isinstance(effect, AsymmetricDynamics)
        a = effect
        return LagStage(lambda x, z0: asymmetric_lag(x, dt_s, a.tau_activate_s, a.tau_relax_s, z0,
                                                     level_dependence=a.stroke_dependence, level_ref=a.stroke_ref_mm))

    def fit(self, ctx: FitContext, effects: dict[str, EffectFit]) -> EffectFit | None:
        """Lag from a small grid, refined; or a speed limit in one direction, whichever fits better."""
        return _fit_asym(ctx, effects)

    def bounds(self, ctx: FitContext, fit: EffectFit) -> tuple[np.ndarray, np.ndarray]:
        """Speed > 0; time constants in [0, 20 t_dom], level slope in [-3, 3] (none on the input)."""
        if fit.variant.startswith("rate_limit"):
            return np.array([1e-12]), np.array([np.inf])
        tdom = max(ctx.t_dom, 2 * ctx.prep.dt_s)
        n = len(fit.theta)
        return np.array([0.0, 0.0, -3.0])[:n], np.array([20.0 * tdom, 20.0 * tdom, 3.0])[:n]

    def form_limits(self, ctx: FitContext, fit: EffectFit) -> tuple[np.ndarray, np.ndarray]:
        """The upper time constants and the slope's range (a time constant of zero is a direction without a
        lag, an ordinary value; a speed limit's bound only keeps it positive)."""
        lo, hi = self.bounds(ctx, fit)
        lo = np.full(lo.shape, -np.inf)
        if fit.variant.startswith("rate_limit"):
            hi = np.full(hi.shape, np.inf)
        elif lo.size > 2:
            lo[2] = -3.0
        return lo, hi

    def describe(self, ctx: FitContext, fit: EffectFit, units: tuple[str, str],
                 effects: dict[str, EffectFit]) -> dict:
        """Time constants (s) and level slope, or the direction and speed limit (output unit per second)."""
        th, uo = fit.theta, units[1]
        out: dict = {"variant": fit.variant}
        if fit.variant.startswith("rate_limit"):
            out["direction"] = fit.variant.split(":")[1]
            out["speed_limit"] = th[0]
            out["unit"] = f"{uo}/s" if uo else "output units/s"
            out["form"] = (f"the output follows at once, but while {out['direction']} moves at most "
                           f"speed_limit per second")
            return out
        out["tau_rising_s"] = th[0] if th[0] >= 1e-6 else 0.0
        out["tau_falling_s"] = th[1] if th[1] >= 1e-6 else 0.0
        if fit.variant == INPUT:
            out["form"] = ("lag of the input (before the dynamics): tau_rising while it rises, tau_falling while "
                           "it falls")
            return out
        out["falling_tau_level_slope"] = th[2]
        out["form"] = "lag: tau_rising while rising, tau_falling*exp(k*w) while falling, w = (y - c)/s"
        return out


FAMILY = AsymmetricFamily()
