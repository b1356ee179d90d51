"""``static_nonlinearity``: the stroke-voltage map is not a line.

Forms
-----
- truth :class:`StaticNonlinearity`: the applied voltage is replaced by an effective
  one, ``"electrostatic"`` (a blend of linear and ``v |v|``) or ``"saturating"``
  (``tanh``), equal to the nominal line at ``v_ref_kv`` (memoryless).
- generic ``input`` (``theta = (a_0 .. a_d)``): ``x + s sum_j a_j z^j`` before the
  dynamics, ``z = (x - u_c) / u_s`` (held constant beyond the training range);
- generic ``internal`` (``(b_0 .. b_d)``): ``y + G1(s sum_j b_j w^j)`` after the
  dynamics, ``w = (y - y_c) / y_s``, ``G1 = G / G(0)`` (a stiffness-like force fed back
  through the dynamics: it needs the linear model, ``scales.num``/``scales.den``).

A map that is nearly a line (its curvature removes less than :data:`NEAR_LINEAR_SHARE`
of what it removes beyond its offset, and less than :data:`CURVE_LEFT_SHARE` of what its best line leaves)
is a linear correction, not a nonlinearity (:func:`linear_static`).
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import ClassVar

import numpy as np

from hasel.effects.base import SLOT_ORDER, Effect, EffectFamily, EffectFit, FitContext, Scales
from hasel.effects.fitkit import (STATIC_DEGREE, _downstream_nonlinear, _poly_ls, _refine, _sse, _with, monomials,
                                  poly_map)
from hasel.errors import BadInputError
from hasel.validate import in_range, positive

__all__ = ["StaticNonlinearity", "MapStage", "fit_variant", "map_sides", "InternalMapStage", "max_degree", "linear_static", "NEAR_LINEAR_SHARE", "CURVE_LEFT_SHARE",
           "StaticMapFamily", "FAMILY"]

#: A static map whose curvature (its deviation from its best line) removes less than this share
#: of what the map removes beyond its offset is a linear correction (a gain, a changed dynamic):
#: only its offset is kept.
NEAR_LINEAR_SHARE = 0.1
#: ... unless the curvature removes at least this share of what the best line leaves (the map is then a
#: nonlinearity whatever the size of its slope). Without it an input map with a large gain change (a power
#: law, ``bench/tune_diag/maps.py`` seed 41) kept only its offset while a sensor curve, which keeps its
#: slope, took its place: a line cannot be placed on either side of the dynamics, only the curvature can.
#: On linear changes (the loads and delays of ``loads.py`` seed 3 and ``cases.py`` seed 7, fitted alone) the
#: curvature removed at most 0.092 of what the line left; on the input maps beside a drift or a load whose
#: map had been cut to its offset, 0.17-0.99.
CURVE_LEFT_SHARE = 0.25
#: A side of the dynamics is told apart when the runner-up side leaves this many times the best's
#: remaining error: set on the tuning corpus (``python -m hasel_bench.othersim``, seed 0), where the four
#: single-map cases (knee and power input maps, exponential and quadratic sensor curves) gave
#: 1.40-2.45 with the right side best, and the map-plus-another-effect pairs 1.03-1.14.
SIDES_SEPARABLE = 1.3


@dataclass(frozen=True)
class StaticNonlinearity(Effect):
    """The static stroke-voltage map is not a line.

    The applied voltage ``v`` (kV) is replaced by an effective voltage ``f(v)`` before
    the actuator's dynamics (electrostatic force ~ v^2 in a zipping actuator), with
    ``f(v_ref) = v_ref`` so that the map agrees with the nominal one at ``v_ref_kv``.

    Attributes
    ----------
    kind : {"electrostatic", "saturating"}
        ``"electrostatic"``: ``f(v) = (1 - s) v + s v |v| / v_ref`` (a blend of linear
        and quadratic; odd so that the map stays monotone through 0 kV).
        ``"saturating"``: ``f(v) = v_ref tanh(s v / v_ref) / tanh(s)``.
    strength : float
        ``s`` above, dimensionless (0: linear).
    v_ref_kv : float
        Voltage where the map meets the nominal line, kV.
    """

    name: ClassVar[str] = "static_nonlinearity"
    kind: str = "electrostatic"
    strength: float = 0.4
    v_ref_kv: float = 5.0

    def __post_init__(self) -> None:
        if self.kind not in ("electrostatic", "saturating"):
            raise BadInputError(f"static_nonlinearity kind must be 'electrostatic' or 'saturating', got {self.kind!r}")
        hi = 1.0 if self.kind == "electrostatic" else 5.0
        in_range("strength", self.strength, 0.0, hi)
        positive("v_ref_kv", self.v_ref_kv)

    def apply(self, v_kv: np.ndarray) -> np.ndarray:
        """Effective voltage (kV) for applied voltages ``v_kv`` (kV)."""
        v = np.asarray(v_kv, float)
        s, vr = self.strength, self.v_ref_kv
        if self.kind == "electrostatic":
            return (1.0 - s) * v + s * v * np.abs(v) / vr
        if s == 0.0:
            return v
        return vr * np.tanh(s * v / vr) / np.tanh(s)

    @classmethod
    def sample_params(cls, rng: np.random.Generator) -> "StaticNonlinearity":
        kind = ("electrostatic", "saturating")[int(rng.integers(2))]
        strength = rng.uniform(0.25, 0.6) if kind == "electrostatic" else rng.uniform(0.8, 1.6)
        return cls(kind=kind, strength=float(strength), v_ref_kv=float(rng.uniform(4.0, 5.5)))


def input_map(theta, x: np.ndarray, u_c: float, u_s: float) -> np.ndarray:
    """The generic input map ``x + u_s sum_j theta_j z^j``, ``z = (x - u_c) / u_s`` (clipped to [-1, 1])."""
    z = (x - u_c) / u_s
    return x + u_s * poly_map(theta, z)


class MapStage:
    """A memoryless map ``fn(x)`` as a stage (the truth form's effective voltage, a generic input map)."""

    def __init__(self, fn) -> None:
        self.fn = fn

    def reset(self, x0: float) -> None:
        """Nothing to remember."""

    def run(self, x: np.ndarray, u: np.ndarray | None = None) -> np.ndarray:
        """``fn(x)``."""
        return self.fn(np.asarray(x, float))


class InternalMapStage:
    """Generic internal map: ``y + G1(y_s poly(w))``, ``G1`` the unit-DC-gain linear model at ``dt_s``
    (zero-order hold), its state carried between chunks."""

    def __init__(self, theta, num, den, y_c: float, y_s: float, dt_s: float) -> None:
        from hasel.lti import SosFilter, zoh_sos

        num = np.asarray(num, float)
        den = np.asarray(den, float)
        g0 = float(np.polyval(num, 0.0) / np.polyval(den, 0.0))
        k = 1.0 / g0 if abs(g0) > 1e-12 else 1.0
        self.g1 = SosFilter(zoh_sos(k * num, den, dt_s, output="end"))
        self.theta, self.y_c, self.y_s = tuple(theta), float(y_c), float(y_s)

    def _force(self, y: np.ndarray) -> np.ndarray:
        return self.y_s * poly_map(self.theta, (y - self.y_c) / self.y_s)

    def reset(self, x0: float) -> None:
        """At rest with output ``x0``."""
        self.g1.reset(float(self._force(np.array([float(x0)]))[0]))

    def run(self, x: np.ndarray, u: np.ndarray | None = None) -> np.ndarray:
        """``x`` plus the map's force passed through ``G1``."""
        x = np.asarray(x, float)
        return x + self.g1.run(self._force(x))


def max_degree(u: np.ndarray, u_s: float) -> int:
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


def fit_variant(pipe: FitContext, effects: dict[str, EffectFit], variant: str) -> EffectFit:
    """The polynomial map ``variant`` (``"input"`` or ``"internal"``) fitted with ``effects`` fixed: least
    squares (degree by cross-validation), only its offset if it is nearly a line, refined where a
    nonlinear stage downstream keeps least squares from being exact."""
    slot = SLOT_ORDER[f"static_nonlinearity:{variant}"]
    base = {k: v for k, v in effects.items() if k != "static_nonlinearity"}
    basis = _static_basis(pipe, base, variant)
    th = _poly_ls(pipe, base, basis)
    if th.size > 1 and _nearly_linear(pipe, base, variant, basis, th):
        th = _poly_ls(pipe, base, basis, degrees=(0,))
    fit = EffectFit("static_nonlinearity", variant, tuple(map(float, th)))
    if _downstream_nonlinear(base, slot) or (variant == "input" and "hysteresis" in base):
        fit = _refine(pipe, base, fit, -np.inf, np.inf, max_nfev=25)
    return fit


def _fit_static(pipe: FitContext, effects: dict[str, EffectFit]) -> EffectFit | None:
    best, best_cost = None, np.inf
    base = {k: v for k, v in effects.items() if k != "static_nonlinearity"}
    for variant in ("input", "internal"):
        fit = fit_variant(pipe, effects, variant)
        c = _sse(pipe, _with(base, fit))
        if c < best_cost:
            best, best_cost = fit, c
    return best


def _static_basis(pipe: FitContext, effects: dict[str, EffectFit], variant: str):
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


def linear_static(pipe: FitContext, effects: dict[str, EffectFit]) -> bool:
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


def _nearly_linear(pipe: FitContext, base: dict[str, EffectFit], variant: str, basis, th: np.ndarray) -> bool:
    """Whether the map ``th`` is nearly a line: beyond its offset (the best constant map), its
    curvature (the part beyond the best line) removes less than :data:`NEAR_LINEAR_SHARE` of what
    the whole map removes, and less than :data:`CURVE_LEFT_SHARE` of what the best line leaves (sums of
    squares of the training residual); the rest is a slope, a linear correction."""
    def sse(t: np.ndarray) -> float:
        return _sse(pipe, _with(base, EffectFit("static_nonlinearity", variant, tuple(map(float, t)))))

    s_full = sse(th)
    beyond_offset = sse(_poly_ls(pipe, base, basis, degrees=(0,))) - s_full
    if beyond_offset <= 0:
        return False
    s_line = s_full if th.size <= 2 else sse(_poly_ls(pipe, base, basis, degrees=(1,)))
    curvature = s_line - s_full
    # a large gain change (a power law far from its reference voltage) makes any curvature a small share of
    # what the map removes, yet the curvature may remove most of what the line leaves: a nonlinearity
    return curvature < NEAR_LINEAR_SHARE * beyond_offset and curvature < CURVE_LEFT_SHARE * max(s_line, 0.0)



class StaticMapFamily(EffectFamily):
    """The ``static_nonlinearity`` family (see the module's docstring)."""

    name = "static_nonlinearity"
    slot = "input"
    variants = ("input", "internal")
    truth_class = StaticNonlinearity

    def param_names(self, fit: EffectFit) -> tuple[str, ...]:
        """``("z^0", "z^1", ...)``: the polynomial's coefficients."""
        return tuple(f"z^{j}" for j in range(len(fit.theta)))

    def stage(self, fit: EffectFit, scales: Scales, dt_s: float) -> MapStage | InternalMapStage:
        """The input map (memoryless), or the internal map through the linear model ``scales.num/den``."""
        if fit.variant == "input":
            return MapStage(lambda x: input_map(fit.theta, x, scales.u_c, scales.u_s))
        return InternalMapStage(fit.theta, getattr(scales, "num"), getattr(scales, "den"), scales.y_c, scales.y_s,
                                dt_s)

    def truth_stage(self, effect: Effect, dt_s: float) -> MapStage:
        """The effective voltage of the truth form."""
        assert isinstance(effect, StaticNonlinearity)
        return MapStage(effect.apply)

    def fit(self, ctx: FitContext, effects: dict[str, EffectFit]) -> EffectFit | None:
        """Input and internal polynomial maps by least squares (degree by cross-validation), the better kept."""
        return _fit_static(ctx, effects)

    def describe(self, ctx: FitContext, fit: EffectFit, units: tuple[str, str],
                 effects: dict[str, EffectFit]) -> dict:
        """Coefficients, normalisation, the curve's deviation on 9 points and the offset in output units."""
        out = describe_poly(ctx, fit, units)
        g0 = ctx.linear_of(effects or {}).dc_gain if fit.variant == "input" else 1.0
        out["output_offset_at_centre"] = float(g0 * (ctx.u_s if fit.variant == "input" else ctx.y_s) * fit.theta[0])
        out["output_offset_unit"] = units[1]
        return out

    def signature(self, ctx: FitContext, fit: EffectFit, effects: dict[str, EffectFit]) -> dict:
        """Which side of the dynamics the map acts on, as far as the data tell (:func:`map_sides`)."""
        return {"sides": map_sides(ctx, effects)}


def map_sides(ctx: FitContext, effects: dict[str, EffectFit]) -> dict:
    """How well a map explains the gap on each side of the dynamics: the training sum of squares with
    the input map, the internal map and the sensor curve (each alone beside ``effects``) over that
    without any, the best side, and the runner-up's ratio to it (near 1: the data cannot tell the
    sides apart; another amplitude or band would)."""
    from hasel.effects.registry import family

    base = {k: v for k, v in effects.items() if k not in ("static_nonlinearity", "sensor_nonlinearity")}
    s0 = _sse(ctx, base)
    cands = {v: fit_variant(ctx, base, v) for v in ("input", "internal")}
    sens = family("sensor_nonlinearity").fit(ctx, base)
    if sens is not None:
        cands["sensor"] = sens
    share = {k: _sse(ctx, _with(base, f)) / max(s0, 1e-300) for k, f in cands.items()}
    order = sorted(share, key=share.get)
    runner = share[order[1]] / max(share[order[0]], 1e-300) if len(order) > 1 else float("inf")
    return {"remaining_share": share, "best": order[0], "runner_up": order[1] if len(order) > 1 else None,
            "runner_up_over_best": runner, "separable": runner > SIDES_SEPARABLE}


def describe_poly(ctx: Scales, fit: EffectFit, units: tuple[str, str]) -> dict:
    """A polynomial map's description (static or sensor): coefficients, normalisation and curve."""
    ui, uo = units
    th = fit.theta
    side = "output" if fit.name == "sensor_nonlinearity" else ("input" if fit.variant == "input" else "output")
    c, s = (ctx.u_c, ctx.u_s) if side == "input" else (ctx.y_c, ctx.y_s)
    names = (tuple(f"z^{j}" for j in range(len(th))) if fit.name == "static_nonlinearity"
             else tuple(f"w^{j}" for j in range(len(th))))
    out: dict = {"variant": fit.variant, "coefficients": dict(zip(names, th))}
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
    return out


FAMILY = StaticMapFamily()
