"""``saturation``: a hard limit of the voltage, of its rate, or of the stroke.

Forms
-----
- truth :class:`Saturation`: ``"amplifier"`` clips the command to ``+-limit_kv`` before
  the output filter (:class:`ClipStage`, both ends); ``"stroke"`` bends the stroke over
  into ``limit_mm`` with a smooth knee (:class:`SoftLimitStage`).
- generic ``input:upper|lower`` / ``output:upper|lower`` (``theta = (limit,)``): a clip of
  the input or of the output; ``output:both`` (``(lower, upper)``): hard end stops of the stroke on both sides
  (:func:`_fit_both`); ``measured:upper|lower|both`` (``(limit,)`` or
  ``(lower, upper)``): the measured range where the output piles up, applied last;
  ``slew`` (``(S,)``): the input moves at most ``S`` per second (:class:`SlewStage`); ``output:slew``
  (``(S,)``): the stroke moves at most ``S`` per second either way (the liquid cannot flow faster through the
  zipping front; the same stage on the output);
  ``output:stop_upper|stop_lower`` (``(knee, room, gain, offset)``): a smooth end stop of the
  stroke (:func:`stop_map`): up to ``knee`` a line, beyond it the output approaches
  ``knee + room`` (``knee - room`` for the lower end) on that line.

Signature: a clip piles samples on one value (:func:`pile_up`); a curve bends the whole
range without any pile-up; an end stop leaves most of the range straight and flattens one end.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import ClassVar

import numpy as np

from hasel.effects.base import SLOT_ORDER, Effect, EffectFamily, EffectFit, FitContext, Scales
from hasel.effects.fitkit import (_downstream_nonlinear, _fit_scalar, _ls, _refine, _sse, _with, bic_prefers,
                                  fit_log_scalar, rate_grid)
from hasel.effects.operators import rate_limited, rate_step
from hasel.errors import BadInputError
from hasel.validate import positive

__all__ = ["OUTPUT_SLEW", "Saturation", "ClipStage", "SlewStage", "SoftLimitStage", "clip", "slew_limit", "measured_clip",
           "pile_up", "end_stop", "stop_map", "is_stop", "stop_limit", "STOP_KNEE_MIN_QUANTILE", "SaturationFamily", "FAMILY"]


#: Variant of a speed limit of the output (both directions; the asymmetric family's ``rate_limit`` is one way).
OUTPUT_SLEW = "output:slew"


def _is_slew(fit: EffectFit) -> bool:
    return fit.variant in ("slew", OUTPUT_SLEW)


def _choice(rng: np.random.Generator, options: tuple[str, ...]) -> str:
    return options[int(rng.integers(len(options)))]


@dataclass(frozen=True)
class Saturation(Effect):
    """A hard limit: the amplifier's output voltage or the actuator's full stroke.

    Attributes
    ----------
    kind : {"amplifier", "stroke"}
        ``"amplifier"``: the command is clipped to ``[-limit_kv, limit_kv]`` before the
        output filter. ``"stroke"``: the stroke bends over into ``limit_mm`` with a
        smooth knee of width ``knee_mm`` (the pouches fully zipped).
    limit_kv : float
        Amplifier limit, kV.
    limit_mm : float
        Full stroke, mm.
    knee_mm : float
        Width of the stroke limit's knee, mm.
    """

    name: ClassVar[str] = "saturation"
    kind: str = "amplifier"
    limit_kv: float = 6.0
    limit_mm: float = 8.0
    knee_mm: float = 0.05

    def __post_init__(self) -> None:
        if self.kind not in ("amplifier", "stroke"):
            raise BadInputError(f"saturation kind must be 'amplifier' or 'stroke', got {self.kind!r}")
        positive("limit_kv", self.limit_kv)
        positive("limit_mm", self.limit_mm)
        positive("knee_mm", self.knee_mm)

    def clip_stroke(self, z_mm: np.ndarray) -> np.ndarray:
        """Stroke (mm) after the smooth full-stroke limit."""
        z = np.asarray(z_mm, float)
        w = self.knee_mm
        return z - w * np.logaddexp(0.0, (z - self.limit_mm) / w)

    @classmethod
    def sample_params(cls, rng: np.random.Generator) -> "Saturation":
        kind = _choice(rng, ("amplifier", "stroke"))
        return cls(kind=kind, limit_kv=float(rng.uniform(5.2, 6.3)), limit_mm=float(rng.uniform(6.5, 8.0)),
                   knee_mm=float(rng.uniform(0.02, 0.15)))


#: the fitted end stop's knee lies at or beyond this quantile of the output (upper end; 1 - it for
#: the lower): an end stop engages near the end of the travel and leaves the rest straight, where a
#: sensor's calibration curve bends the whole range (without the bound a stop with its knee at the
#: bottom is an exponential curve over the whole range)
STOP_KNEE_MIN_QUANTILE = 0.5
#: an end stop flattens within the data: its slope at the output's last 0.5 % is at most this share of
#: the line's (a bend milder than that is any curvature, or with a large room a mere gain and offset)
STOP_MAX_END_SLOPE = 0.5
#: an end stop's room is at least this share of the output's range (a sharper one is the hard clip)
STOP_MIN_ROOM_SHARE = 0.02
# The three limits were set on the tuning sets only (bench/tune_diag/RESULT-h-stop.md): the true stops there
# flatten to 0.01-0.08 of the line's slope, the stops that were a gain and offset stayed at 0.95-0.99.


def end_stop(x: np.ndarray, knee: float, room: float, upper: bool = True) -> np.ndarray:
    """``x`` through a smooth one-sided end stop (same units as ``x``).

    Up to ``knee`` the output is ``x``; beyond it the output approaches ``knee + room``
    (upper end; ``knee - room`` for the lower) as ``knee + room (1 - exp(-(x - knee) / room))``:
    slope 1 at the knee (no kink), ever flatter after it, the stiffening of an end stop.
    ``room`` > 0 (the travel left beyond the knee).
    """
    x = np.asarray(x, float)
    r = max(float(room), 1e-12)
    d = (x - knee) if upper else (knee - x)
    bent = r * -np.expm1(-np.maximum(d, 0.0) / r)
    out = np.where(d > 0, bent, d)
    return knee + out if upper else knee - out


def is_stop(f: EffectFit) -> bool:
    """Whether ``f`` is a fitted smooth end stop (variant ``output:stop_upper|stop_lower``)."""
    return f.name == "saturation" and "stop_" in f.variant


def stop_limit(f: EffectFit) -> float:
    """The output value the fitted end stop ``f`` approaches, ``offset + gain (knee +- room)`` (output units)."""
    knee, room, gain, offset = f.theta
    return offset + gain * (knee + room if f.variant.endswith("upper") else knee - room)


def clip(x: np.ndarray, f: EffectFit) -> np.ndarray:
    """``x`` clipped as the generic fit ``f`` says (variant ending ``upper``, ``lower`` or ``both``;
    ``stop_upper``/``stop_lower``: the smooth end stop :func:`end_stop` of ``theta = (knee, room)``)."""
    if is_stop(f):
        return stop_map(x, f)
    if f.variant.endswith("both"):
        return np.clip(x, f.theta[0], f.theta[1])
    return np.minimum(x, f.theta[0]) if f.variant.endswith("upper") else np.maximum(x, f.theta[0])


def slew_limit(x: np.ndarray, rate: float, dt: float, x0: float | None = None) -> np.ndarray:
    """``x`` followed at a speed of at most ``rate`` (units of ``x`` per second).

    Parameters
    ----------
    x : ndarray, shape (n,)
        The command, sampled every ``dt`` seconds.
    rate : float
        Slew limit, units of ``x`` per second (> 0; ``inf``: no limit).
    dt : float
        Sample interval, s.
    x0 : float, optional
        State before the first sample (default ``x[0]``: settled).

    Returns
    -------
    ndarray, shape (n,)
        ``y_k = y_{k-1} + clip(x_k - y_{k-1}, -rate dt, rate dt)``.
    """
    step = rate_step(rate, dt)
    return rate_limited(x, step, step, x0)


class ClipStage:
    """A memoryless clip (the generic fit ``f``'s ends); :meth:`run` needs no state."""

    def __init__(self, f: EffectFit) -> None:
        self.f = f

    def reset(self, x0: float) -> None:
        """Nothing to remember."""

    def run(self, x: np.ndarray, u: np.ndarray | None = None) -> np.ndarray:
        """``x`` clipped."""
        return clip(np.asarray(x, float), self.f)


class SoftLimitStage:
    """The truth form's smooth full-stroke limit (memoryless)."""

    def __init__(self, sat: Saturation) -> None:
        self.sat = sat

    def reset(self, x0: float) -> None:
        """Nothing to remember."""

    def run(self, x: np.ndarray, u: np.ndarray | None = None) -> np.ndarray:
        """Stroke (mm) after the limit."""
        return self.sat.clip_stroke(x)


class SlewStage:
    """A slew-rate limit of ``rate`` (units per second) at ``dt_s``, carrying the last output."""

    def __init__(self, rate: float, dt_s: float) -> None:
        self.rate, self.dt_s = float(rate), float(dt_s)
        self.y: float | None = None

    def reset(self, x0: float) -> None:
        """Settled at ``x0``."""
        self.y = float(x0)

    def run(self, x: np.ndarray, u: np.ndarray | None = None) -> np.ndarray:
        """The next samples, rate-limited."""
        x = np.asarray(x, float)
        if x.size == 0:
            return x.copy()
        y = slew_limit(x, self.rate, self.dt_s, self.y)
        self.y = float(y[-1])
        return y


def measured_clip(clips: dict[str, float]) -> EffectFit | None:
    """The clip of the measured range at ``clips`` (``{"upper"|"lower": value}``), as a saturation
    acting last in the chain (variant ``measured:upper|lower|both``), or ``None`` for no ends."""
    if not clips:
        return None
    if len(clips) == 2:
        return EffectFit("saturation", "measured:both", (float(clips["lower"]), float(clips["upper"])))
    (end, v), = clips.items()
    return EffectFit("saturation", f"measured:{end}", (float(v),))


def pile_up(y: np.ndarray, tol_share: float = 1e-4) -> dict:
    """How many samples sit on each extreme of ``y`` (within ``tol_share`` of its range).

    A clip piles samples on one value; a curve (a sensor's, a map's) bends the range
    without piling: a share of a few per cent at an end is a clip's signature, of a few
    samples none. Returns ``{"upper": share, "lower": share}`` (shares of all samples).
    """
    y = np.asarray(y, float)
    if y.size == 0:
        return {"upper": 0.0, "lower": 0.0}
    lo, hi = float(y.min()), float(y.max())
    tol = tol_share * max(hi - lo, 1e-300)
    return {"upper": float(np.mean(y >= hi - tol)), "lower": float(np.mean(y <= lo + tol))}


class SaturationFamily(EffectFamily):
    """The ``saturation`` family (see the module's docstring)."""

    name = "saturation"
    slot = "input"
    variants = ("input", "output", "measured", "slew")
    truth_class = Saturation

    def param_names(self, fit: EffectFit) -> tuple[str, ...]:
        """``("slew_rate",)``, ``("lower", "upper")`` or ``("limit",)``."""
        if _is_slew(fit):
            return ("slew_rate",)
        if is_stop(fit):
            return ("knee", "room", "gain", "offset")
        if fit.variant.endswith("both"):
            return ("lower", "upper")
        return (fit.variant.split(":")[-1],)

    def stage(self, fit: EffectFit, scales: Scales, dt_s: float) -> ClipStage | SlewStage:
        """A :class:`SlewStage` for ``slew`` and ``output:slew``, else a :class:`ClipStage`."""
        return SlewStage(fit.theta[0], dt_s) if _is_slew(fit) else ClipStage(fit)

    def truth_stage(self, effect: Effect, dt_s: float) -> ClipStage | SoftLimitStage:
        """Amplifier: a clip of the command to ``+-limit_kv``; stroke: the smooth limit."""
        assert isinstance(effect, Saturation)
        if effect.kind == "amplifier":
            return ClipStage(EffectFit("saturation", "input:both", (-effect.limit_kv, effect.limit_kv)))
        return SoftLimitStage(effect)

    def fit(self, ctx: FitContext, effects: dict[str, EffectFit]) -> EffectFit | None:
        """Best of a clip at either end of the input or the output (grids on their quantiles), a smooth end stop,
        and a slew limit of the input or of the output."""
        return _fit_saturation(ctx, effects)

    def bounds(self, ctx: FitContext, fit: EffectFit) -> tuple[np.ndarray, np.ndarray]:
        """A slew limit is positive; a clip's limits are free."""
        if _is_slew(fit):
            return np.array([1e-12]), np.array([np.inf])
        if is_stop(fit):
            return np.array([-np.inf, 1e-12, 0.0, -np.inf]), np.array([np.inf, np.inf, np.inf, np.inf])
        return super().bounds(ctx, fit)

    def describe(self, ctx: FitContext, fit: EffectFit, units: tuple[str, str],
                 effects: dict[str, EffectFit]) -> dict:
        """Side, limits and unit (or the slew rate in input units per second)."""
        ui, uo = units
        th = fit.theta
        out: dict = {"variant": fit.variant}
        if _is_slew(fit):
            side = "input" if fit.variant == "slew" else "output"
            out["acts_on"] = side
            out["slew_rate_limit"] = th[0]
            u = ui if side == "input" else uo
            out["unit"] = f"{u}/s" if u else f"{side} units/s"
            out["form"] = (f"x_k = x_(k-1) + clip(u_k - x_(k-1), -S dt, S dt): the {side} moves at most S per second"
                           " (either way)")
            return out
        side, end = fit.variant.split(":")
        out["acts_on"] = "output" if side == "measured" else side
        out["unit"] = ui if side == "input" else uo
        if end.startswith("stop_"):
            up = end == "stop_upper"
            out["end"] = "upper" if up else "lower"
            out["knee"], out["room"], out["gain"], out["offset"] = th
            out["limit"] = stop_limit(fit)
            out["form"] = ("y = offset + gain s(z), s(z) = z up to the knee, then knee + room (1 - exp(-(z - knee)/room)):"
                           " a smooth end stop that the output approaches (limit: offset + gain (knee + room))" if up else
                           "y = offset + gain s(z), s(z) = z down to the knee, then knee - room (1 - exp(-(knee - z)/"
                           "room)): a smooth end stop that the output approaches (limit: offset + gain (knee - room))")
            return out
        if end == "both":
            out["lower"], out["upper"] = th[0], th[1]
        else:
            out["upper" if end == "upper" else "lower"] = th[0]
        if side == "measured":
            out["measured_range"] = True
            out["note"] = "the measured output piles up on these values: applied last, to what is measured"
        return out

    def signature(self, ctx: FitContext, fit: EffectFit, effects: dict[str, EffectFit]) -> dict:
        """Share of the measured samples piled on each extreme (:func:`pile_up`)."""
        return {"pile_up": pile_up(np.concatenate([r.y for r in ctx.prep.records]))}


def _fit_saturation(pipe: FitContext, effects: dict[str, EffectFit]) -> EffectFit | None:
    best, best_cost = None, np.inf
    st = [pipe.stages(effects, ri) for ri in range(len(pipe.prep.records))]
    xs = np.concatenate([s["x_sat"] for s in st])
    ys = np.concatenate([s["y_drift"] for s in st])
    qs = np.array([0.6, 0.75, 0.85, 0.92, 0.96, 0.98, 0.99, 0.995])
    ends: dict[str, EffectFit] = {}
    for side, sig in (("input", xs), ("output", ys)):
        for end in ("upper", "lower"):
            variant = f"{side}:{end}"
            grid = np.unique(np.quantile(sig, qs if end == "upper" else 1.0 - qs))
            fit = _fit_scalar(pipe, effects, lambda v, variant=variant: EffectFit("saturation", variant, (v,)), grid)
            if fit is None:
                continue
            if side == "output":
                ends[end] = fit
            c = _sse(pipe, _with(effects, fit))
            if c < best_cost:
                best, best_cost = fit, c
    if best is not None and best.variant in ("output:upper", "output:lower") and len(ends) == 2:
        both = _fit_both(pipe, effects, ends, ys, qs)
        if both is not None:
            n = pipe.residuals(_with(effects, best), "train").size
            c = _sse(pipe, _with(effects, both))
            if bic_prefers(n, best_cost, c, 1):
                best, best_cost = both, c
    stop = _fit_stop(pipe, effects, ys)
    if stop is not None:
        c = _sse(pipe, _with(effects, stop))
        if c < best_cost:
            best, best_cost = stop, c
    # a slew-rate limit of the input, or of the stroke: the gap only where the signal moves faster than the limit
    for variant, sig in (("slew", st[0]["x_delay"]), (OUTPUT_SLEW, st[0]["y_drift"])):
        grid = rate_grid(sig, pipe.prep.dt_s)
        rate, c = fit_log_scalar(lambda v, variant=variant: _sse(pipe, _with(effects, EffectFit("saturation", variant,
                                                                                                  (v,)))), grid)
        if c < best_cost:
            best, best_cost = EffectFit("saturation", variant, (rate,)), c
    return best



def _fit_both(pipe: FitContext, effects: dict[str, EffectFit], ends: dict[str, EffectFit], ys: np.ndarray,
              qs: np.ndarray) -> EffectFit | None:
    """A clip of the output at both ends (``output:both``, ``theta = (lower, upper)``, output units): each end
    searched on its quantile grid with the other held, twice, from the one-sided fits ``ends``; None when the
    ends cross. Taken over the best one-sided output clip when the training BIC prefers its one more parameter.

    Why: hard end stops of the stroke on both sides, with sensor noise after them, pile no measured samples on one
    value (``measured:both`` needs that), and a one-sided clip leaves the other end (``bench/tune_diag/forms3.py``
    seed 1, ``zstop2``: the lower stop named, the upper left, 18x the floor)."""
    lo, hi = float(ends["lower"].theta[0]), float(ends["upper"].theta[0])
    if not lo < hi:
        return None
    g_up, g_lo = np.unique(np.quantile(ys, qs)), np.unique(np.quantile(ys, 1.0 - qs))
    for _ in range(2):
        f = _fit_scalar(pipe, effects, lambda v, lo=lo: EffectFit("saturation", "output:both", (lo, max(v, lo))),
                        g_up[g_up > lo])
        hi = float(f.theta[1]) if f is not None else hi
        f = _fit_scalar(pipe, effects, lambda v, hi=hi: EffectFit("saturation", "output:both", (min(v, hi), hi)),
                        g_lo[g_lo < hi])
        lo = float(f.theta[0]) if f is not None else lo
    return EffectFit("saturation", "output:both", (lo, hi)) if lo < hi else None


def stop_map(y: np.ndarray, f: EffectFit) -> np.ndarray:
    """The fitted end stop ``f`` (``theta = (knee, room, gain, offset)``) on the output ``y``:
    ``offset + gain * end_stop(y, knee, room)`` (output units). The gain and offset let the stop sit
    on a recalibrated line, as a sensor curve's lowest terms do, so that the two compete on the shape
    of the bend alone."""
    return f.theta[3] + f.theta[2] * end_stop(y, f.theta[0], f.theta[1], f.variant.endswith("upper"))


def _stop_deep(f: EffectFit, y_end: float) -> bool:
    """Whether the stop ``f`` flattens within the data: its slope at ``y_end`` (the output's 0.5 % from
    the stop's end) is at most :data:`STOP_MAX_END_SLOPE` of the line's."""
    knee, room = f.theta[0], f.theta[1]
    d = (y_end - knee) if f.variant.endswith("upper") else (knee - y_end)
    return d > 0 and math.exp(-d / room) <= STOP_MAX_END_SLOPE


def _fit_stop(pipe: FitContext, effects: dict[str, EffectFit], ys: np.ndarray) -> EffectFit | None:
    """The best smooth end stop of the output ``ys`` (either end): a grid of knees (quantiles from
    :data:`STOP_KNEE_MIN_QUANTILE` on) and rooms (shares of the range), the gain and offset by least
    squares at each, then least squares on all four within those knees. Only stops that flatten
    within the data (:func:`_stop_deep`) and are smooth (room at least :data:`STOP_MIN_ROOM_SHARE` of the
    range: a sharper one is the hard clip) are offered."""
    span = float(np.ptp(ys))
    if not np.isfinite(span) or span <= 0:
        return None
    q0 = STOP_KNEE_MIN_QUANTILE
    exact = not _downstream_nonlinear(effects, SLOT_ORDER["saturation:output"])
    ends = {"upper": float(np.quantile(ys, 0.995)), "lower": float(np.quantile(ys, 0.005))}
    best, best_cost = None, np.inf
    for end in ("upper", "lower"):
        qs = np.linspace(q0, 0.97, 6)
        knees = np.quantile(ys, qs if end == "upper" else 1.0 - qs)
        variant = f"output:stop_{end}"
        for k in knees:
            for r in span * np.array([0.03, 0.08, 0.2, 0.5]):
                f = EffectFit("saturation", variant, (float(k), float(r), 1.0, 0.0))
                if not _stop_deep(f, ends[end]):
                    continue
                if exact:  # the gain and offset are linear in the output: least squares on the stop's output
                    def basis(ri, st, f=f):
                        z = end_stop(st["y_drift"], f.theta[0], f.theta[1], end == "upper")
                        return [np.ones_like(z), z]
                    w = _ls(pipe, _with(effects, f), basis)
                    f = EffectFit("saturation", variant, (float(k), float(r), 1.0 + float(w[1]), float(w[0])))
                c = _sse(pipe, _with(effects, f))
                if c < best_cost:
                    best, best_cost = f, c
    if best is None:
        return None
    up = best.variant.endswith("upper")
    lim = float(np.quantile(ys, q0 if up else 1.0 - q0))
    lo = np.array([lim if up else float(ys.min()) - span, STOP_MIN_ROOM_SHARE * span, 0.2, -np.inf])
    hi = np.array([float(ys.max()) + span if up else lim, 2.0 * span, 5.0, np.inf])
    refined = _refine(pipe, effects, best, lo, hi, max_nfev=40)
    return refined if _stop_deep(refined, ends["upper" if up else "lower"]) else best


FAMILY = SaturationFamily()
