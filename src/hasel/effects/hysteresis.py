"""``hysteresis``: rate-independent memory of the input (the zipping front).

Forms
-----
- truth :class:`Hysteresis`: a Bouc-Wen element ``h`` on the effective voltage; the
  actuator sees ``v - (half_width_kv / h_sat_kv) h`` (:class:`BoucWenStage`).
- generic ``input`` (``theta = (w_1 .. w_5, c)``): Prandtl-Ishlinskii,
  ``x + sum_j w_j (play_rj(x) - x)``, ``w_j >= 0``, the five half-widths ``r_j`` fixed
  fractions (:data:`HYST_THRESHOLDS`) of the input's range, the plays starting at
  ``x_0 + c r_j`` (``c`` in [-1, 1]: the branch the log starts on)
  (:class:`PlayStage`).

- generic ``output`` (the same ``theta``): the same Prandtl-Ishlinskii law on the *stroke* after the
  linear dynamics (and after an asymmetric lag), its half-widths the same fractions of the model output's
  range (:func:`output_thresholds`): a memory of the mechanism or of the sensor's mount (friction of the
  measured point, backlash, a stick-slip), which a step of the voltage passes through the dynamics first.
  Fitted beside ``input`` (weights by non-negative least squares on the plays of the model output) and
  taken in its place when its training error is lower and the held-out blocks prefer it
  (:func:`hasel.effects.heldout.held_out_prefers`). Why: on one amplitude a loop of the stroke and a loop
  of the voltage seen through P(s) differ in phase across the band; fitted as an input loop, an output
  one left 0.5 of the gap (``forms3.py`` seed 1 #11, stick-slip) or gave way to a load form that slowed
  the real poles (#33, an output Prandtl-Ishlinskii loop; session 32's h-real).

All carry their memory between chunks exactly (a play operator's recursion is a
clamp, and a composition of clamps is a clamp: bit for bit).
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import ClassVar

import numpy as np

from hasel.effects.base import SLOT_ORDER, Effect, EffectFamily, EffectFit, FitContext, Scales
from hasel.effects.fitkit import _downstream_nonlinear, _fit_or_none, _fit_scalar, _ls, _refine, prefer_rival
from hasel.effects.operators import BoucWen, monotone_runs, play
from hasel.validate import in_range, positive

__all__ = ["Hysteresis", "HYST_THRESHOLDS", "OUTPUT", "output_thresholds", "input_loop", "is_output_loop", "PlayStage", "BoucWenStage", "branch", "play_support", "HysteresisFamily", "FAMILY"]

#: Play-operator half-widths as fractions of the input's range (1st-99th percentile).
HYST_THRESHOLDS = (0.01, 0.03, 0.07, 0.15, 0.3)
#: variant of the loop of the stroke (after the dynamics)
OUTPUT = "output"


def input_loop(effects: dict) -> bool:
    """Whether ``effects`` (name to :class:`EffectFit`) hold a hysteresis of the input (not of the output): what a
    map of the hysteresis output, between it and the dynamics, needs."""
    f = effects.get("hysteresis")
    return f is not None and f.variant != OUTPUT


def is_output_loop(f) -> bool:
    """Whether the fit ``f`` (an :class:`EffectFit`) is a loop of the stroke: a map of the output level with
    memory, which the diagnosis's slow-only test treats as it treats the maps."""
    return f.name == "hysteresis" and f.variant == OUTPUT


def output_thresholds(y_s: float) -> tuple[float, ...]:
    """The ``output`` variant's play half-widths (output unit): :data:`HYST_THRESHOLDS` of the model output's
    range ``2 y_s`` (``y_s`` its half-range, as the input's thresholds are of ``2 u_s``)."""
    return tuple(2.0 * float(y_s) * f for f in HYST_THRESHOLDS)


@dataclass(frozen=True)
class Hysteresis(Effect):
    """Rate-independent memory of the zipping front (a Bouc-Wen element).

    A Bouc-Wen state ``h`` (kV) with ``dh = dv - beta |dv| h - gamma dv |h|``
    saturates at ``+-h_sat_kv`` (``beta + gamma = 1 / h_sat_kv``) after a reversal of
    the applied voltage; the actuator sees ``v - (half_width_kv / h_sat_kv) h``, so the
    stroke lags on the way up and leads on the way down by up to ``half_width_kv``
    (the loop is ``2 half_width_kv`` wide in voltage), independently of the rate.

    Attributes
    ----------
    half_width_kv : float
        Half the loop's width, kV (at most ``0.95 h_sat_kv``: the branches stay monotone).
    h_sat_kv : float
        Voltage scale of the transition after a reversal, kV.
    shape : float
        ``gamma / beta`` in (-1, 1): loop shape (0: symmetric rounding).
    """

    name: ClassVar[str] = "hysteresis"
    half_width_kv: float = 0.25
    h_sat_kv: float = 0.5
    shape: float = 0.0

    def __post_init__(self) -> None:
        positive("h_sat_kv", self.h_sat_kv)
        in_range("half_width_kv", self.half_width_kv, 0.0, 0.95 * self.h_sat_kv)
        in_range("shape", self.shape, -0.9, 0.9)

    @property
    def beta_gamma(self) -> tuple[float, float]:
        """Bouc-Wen ``(beta, gamma)`` in 1/kV."""
        beta = 1.0 / (self.h_sat_kv * (1.0 + self.shape))
        return beta, self.shape * beta

    @classmethod
    def sample_params(cls, rng: np.random.Generator) -> "Hysteresis":
        h_sat = float(rng.uniform(0.3, 0.9))
        return cls(half_width_kv=float(h_sat * rng.uniform(0.35, 0.9)), h_sat_kv=h_sat,
                   shape=float(rng.uniform(-0.5, 0.5)))


class BoucWenStage:
    """The truth form: ``v - k h`` with ``h`` a Bouc-Wen state (``k = half_width / h_sat``)."""

    def __init__(self, hyst: Hysteresis) -> None:
        self.bw = BoucWen(*hyst.beta_gamma)
        self.k = hyst.half_width_kv / hyst.h_sat_kv

    def reset(self, x0: float) -> None:
        """At rest at ``x0`` with no memory (``h = 0``)."""
        self.bw.reset(float(x0), 0.0)

    def run(self, x: np.ndarray, u: np.ndarray | None = None) -> np.ndarray:
        """Effective voltage for the next samples ``x``."""
        x = np.asarray(x, float)
        return x - self.k * self.bw.run(x)


def pi_output(x: np.ndarray, weights, plays) -> np.ndarray:
    """Prandtl-Ishlinskii output ``x + sum_j w_j (p_j - x)`` for play outputs ``plays``."""
    return x + sum(w * (p - x) for w, p in zip(weights, plays))


class PlayStage:
    """The generic form on thresholds ``radii`` (input unit), chunk by chunk."""

    def __init__(self, weights, radii, c: float = 0.0) -> None:
        self.w = tuple(float(v) for v in weights)
        self.r = tuple(float(v) for v in radii)
        self.c = float(c)
        self.y = [0.0] * len(self.r)

    def reset(self, x0: float) -> None:
        """Plays at ``x0 + c r_j`` (the starting branch)."""
        self.y = [float(x0) + self.c * r for r in self.r]

    def run(self, x: np.ndarray, u: np.ndarray | None = None) -> np.ndarray:
        """Output for the next samples ``x``."""
        x = np.asarray(x, float)
        if x.size == 0:
            return x.copy()
        ps = [play(x, r, y0) for r, y0 in zip(self.r, self.y)]
        self.y = [float(p[-1]) for p in ps]
        return pi_output(x, self.w, ps)


def branch(fit: EffectFit) -> float:
    """The starting branch ``c`` of a hysteresis fit (0 for fits without one)."""
    return float(fit.theta[len(HYST_THRESHOLDS)]) if len(fit.theta) > len(HYST_THRESHOLDS) else 0.0


_branch = branch


def _reversals(pipe: FitContext, u: np.ndarray) -> int:
    """Turning points of the input, ignoring wiggles smaller than a tenth of its range (1-99 %)."""
    return int(monotone_runs(play(u, 0.1 * pipe.u_s, float(u[0]))).size - 1)


def _fit_hysteresis(pipe: FitContext, effects: dict[str, EffectFit]) -> EffectFit | None:
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
        lo, hi = FAMILY.bounds(pipe, fit)
        fit = _refine(pipe, effects, fit, lo, hi, max_nfev=25)
    return fit


def _fit_output(pipe: FitContext, effects: dict[str, EffectFit]) -> EffectFit | None:
    """The ``output`` variant: weights by non-negative least squares on the plays of the model output before
    the hysteresis (``y_asym``), per starting branch of the input variant's grid, the branch refined; ``None``
    without two reversals of that output (a tenth of its range)."""
    base = {k: v for k, v in effects.items() if k != "hysteresis"}
    radii = output_thresholds(pipe.y_s)
    outs = [pipe.stages(base, ri)["y_asym"] for ri in range(len(pipe.prep.records))]
    if min(int(monotone_runs(play(y, 0.1 * pipe.y_s, float(y[0]))).size - 1)
           for y, r in zip(outs, pipe.prep.records) if r.train.any()) < 2:
        return None

    def at(c: float) -> EffectFit:
        def basis(ri, st):
            y = st["y_asym"]
            return [play(y, r, float(y[0]) + c * r) - y for r in radii]

        th = _ls(pipe, base, basis, nonneg=True)
        return EffectFit("hysteresis", OUTPUT, tuple(map(float, th)) + (float(c),))

    fit = _fit_scalar(pipe, base, at, np.array([-1.0, -0.5, 0.0, 0.5, 1.0]), maxiter=6)
    if fit is not None and _downstream_nonlinear(base, SLOT_ORDER["hysteresis:output"]):
        lo, hi = FAMILY.bounds(pipe, fit)
        fit = _refine(pipe, base, fit, lo, hi, max_nfev=25)
    return fit


def _fit_sides(pipe: FitContext, effects: dict[str, EffectFit]) -> EffectFit | None:
    """The input variant, or the output one in its place when its training error is lower and the held-out
    blocks prefer it (both have the same parameters)."""
    return prefer_rival(pipe, effects, _fit_hysteresis(pipe, effects), _fit_or_none(_fit_output, pipe, effects))



class HysteresisFamily(EffectFamily):
    """The ``hysteresis`` family (see the module's docstring)."""

    name = "hysteresis"
    slot = "input"
    variants = ("input", OUTPUT)
    truth_class = Hysteresis

    def param_names(self, fit: EffectFit) -> tuple[str, ...]:
        """``("w_1", ..., "w_5", "branch")``."""
        names = tuple(f"w_{j + 1}" for j in range(min(len(fit.theta), len(HYST_THRESHOLDS))))
        return names + (("branch",) if len(fit.theta) > len(HYST_THRESHOLDS) else ())

    def stage(self, fit: EffectFit, scales: Scales, dt_s: float) -> PlayStage:
        """Plays on ``scales.thresholds`` (``output``: :func:`output_thresholds` of ``scales.y_s``), starting on the
        fitted branch."""
        radii = output_thresholds(scales.y_s) if fit.variant == OUTPUT else scales.thresholds
        return PlayStage(fit.theta[:len(HYST_THRESHOLDS)], radii, branch(fit))

    def truth_stage(self, effect: Effect, dt_s: float) -> BoucWenStage:
        """The Bouc-Wen element."""
        assert isinstance(effect, Hysteresis)
        return BoucWenStage(effect)

    def fit(self, ctx: FitContext, effects: dict[str, EffectFit]) -> EffectFit | None:
        """Non-negative weights by least squares per starting branch, the branch refined; ``None`` without
        two reversals of the input; the loop of the output in its place where it fits better
        (:func:`_fit_sides`)."""
        return _fit_sides(ctx, effects)

    def bounds(self, ctx: FitContext, fit: EffectFit) -> tuple[np.ndarray, np.ndarray]:
        """Weights >= 0, branch in [-1, 1]."""
        n = fit.n_params
        lo, hi = np.zeros(n), np.full(n, np.inf)
        if n > len(HYST_THRESHOLDS):
            lo[len(HYST_THRESHOLDS)], hi[len(HYST_THRESHOLDS)] = -1.0, 1.0
        return lo, hi

    def form_limits(self, ctx: FitContext, fit: EffectFit) -> tuple[np.ndarray, np.ndarray]:
        """None: a weight of zero is an unused play, a branch of -1 or 1 a start on a branch (ordinary values)."""
        inf = np.full(fit.n_params, np.inf)
        return -inf, inf

    def describe(self, ctx: FitContext, fit: EffectFit, units: tuple[str, str],
                 effects: dict[str, EffectFit]) -> dict:
        """Thresholds, weights, the loop's half-width (input unit; ``output``: output unit) and the starting
        branch."""
        th = fit.theta
        out = fit.variant == OUTPUT
        radii = output_thresholds(ctx.y_s) if out else ctx.thresholds
        return {"variant": fit.variant, "thresholds": list(radii), "weights": list(th[:len(HYST_THRESHOLDS)]),
                "unit": units[1] if out else units[0],
                "loop_half_width": float(sum(w * r for w, r in zip(th, radii))),
                "initial_branch": branch(fit),
                "initial_branch_note": "plays start at x0 + c*r: -1 rising branch, 0 centred, 1 falling branch"}

    def signature(self, ctx: FitContext, fit: EffectFit, effects: dict[str, EffectFit]) -> dict:
        """What the training input could show of each play (:func:`play_support`; ``output``: the measured output
        on the output's thresholds)."""
        if fit.variant == OUTPUT:
            y = np.concatenate([r.y[r.train] for r in ctx.prep.records if r.train.any()])
            return {"plays": play_support(y, output_thresholds(ctx.y_s), fit.theta[:len(HYST_THRESHOLDS)])}
        u = np.concatenate([r.u[r.train] for r in ctx.prep.records if r.train.any()])
        return {"plays": play_support(u, ctx.thresholds, fit.theta[:len(HYST_THRESHOLDS)])}


def play_support(u: np.ndarray, radii, weights) -> dict:
    """Which plays the input ``u`` identifies: a play of half-width ``r`` only changes state on a
    reversal of more than ``2 r``; its weight is unsupported (and may not carry to another log, e.g.
    voltage steps of other sizes) without at least two such reversals.

    Returns ``{"reversals_over_2r": [...], "unsupported_weight_share": float, "largest_reversal": float}``
    (the share of the summed weights on plays with fewer than two such reversals).
    """
    u = np.asarray(u, float)
    r_min = 0.5 * min(radii) if len(radii) else 0.0
    path = play(u, r_min, float(u[0])) if u.size else u  # reversals larger than the smallest play's width
    st = monotone_runs(path)
    ends = np.concatenate([st[1:], [path.size - 1]]) if path.size else st
    amps = np.abs(path[ends] - path[st]) if path.size else np.zeros(0)
    counts = [int(np.sum(amps > 2.0 * r)) for r in radii]
    w = np.asarray(weights, float)
    tot = float(w.sum())
    bad = float(sum(wi for wi, c in zip(w, counts) if c < 2))
    return {"reversals_over_2r": counts, "unsupported_weight_share": bad / tot if tot > 0 else 0.0,
            "largest_reversal": float(amps.max()) if amps.size else 0.0}


FAMILY = HysteresisFamily()
