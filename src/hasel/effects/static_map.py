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
- generic ``after_hysteresis`` (``theta = (a_0 .. a_d)``): the input map's polynomial applied to the
  hysteresis output (``x_h + s sum_j a_j z^j``, ``z = (x_h - u_c) / u_s``), between the hysteresis and the
  dynamics: an actuator whose hysteretic strain is then bent by a static curve (the tuning simulator
  ``bench/hasel_bench/othersim.py`` applies its static map there). Offered only beside an accepted
  hysteresis, by the diagnosis's map-side check (:func:`fit_after_hysteresis`); its name stays
  ``static_nonlinearity`` (the verdict names families, not slots).
- generic ``after_hysteresis:knee`` (``theta = (a_0, a_1, threshold_kv, gain, width_kv)``): the map after the
  hysteresis as a line with one corner, ``x_h + s (a_0 + a_1 z) + dead_map((d, g, w), x_h)``
  (:func:`knee_map`): the slope changes by ``g`` beyond ``|x_h| = d``, the corner rounded over about ``w``. The
  tuning simulator's knees are piecewise linear, which a degree-5 polynomial follows poorly; the dead band's
  corner (:func:`dead_map`, reused) beside a line is that form. :func:`fit_after_hysteresis` fits both and
  keeps the one with the lower validation error.
- generic ``input:dead`` (``theta = (threshold_kv, gain, width_kv)``, input units): a dead band before the
  dynamics, ``g (w sp((x - d) / w) - w sp((-x - d) / w))``, ``sp(a) = log(1 + e^a)`` (:func:`dead_map`):
  nothing passes below the threshold ``d`` (a HASEL does not move until the field overcomes the film's
  stiffness), the rest passes with the gain ``g``, the corner rounded over about ``w``; odd, so a
  bipolar drive sees the same band on both sides. A polynomial in the voltage cannot follow the corner
  (its error beside the corner was taken by a load's gain and a sensor curve: ``bench/tune_diag/multi2.py``
  seed 21, ``m2_00``); it is fitted beside the polynomial and taken when it lowers the training BIC
  and the data see its flat zone at least as often as its corner (:func:`fit_input_side`,
  :func:`dead_visited`: else the form is a bend, a curve the polynomial describes).

A map that is nearly a line (its curvature removes less than :data:`NEAR_LINEAR_SHARE`
of what it removes beyond its offset, and less than :data:`CURVE_LEFT_SHARE` of what its best line leaves)
is a linear correction, not a nonlinearity (:func:`linear_static`).
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import ClassVar

import numpy as np
from scipy.special import expit

from hasel.effects.base import SLOT_ORDER, Effect, EffectFamily, EffectFit, FitContext, Scales
from hasel.effects.fitkit import (STATIC_DEGREE, _downstream_nonlinear, _poly_ls, _refine, _sse, _with, bic_prefers,
                                  monomials, poly_map, sumsq)
from hasel.effects.hysteresis import input_loop
from hasel.errors import BadInputError
from hasel.validate import in_range, positive

__all__ = ["AFTER_HYST", "AFTER_HYST_KNEE", "fit_after_hysteresis", "fit_knee_after_hysteresis", "knee_map",
           "is_after_hysteresis", "KNEE_GRID_QUANTILES", "StaticNonlinearity", "MapStage", "fit_variant", "fit_dead", "fit_input_side", "dead_map", "dead_slope", "dead_zone_shares", "dead_visited",
           "dead_flat_share", "apply_input",
           "DEAD", "DEAD_GRID_QUANTILES", "map_sides", "InternalMapStage", "max_degree", "describe_dead", "linear_static", "NEAR_LINEAR_SHARE", "CURVE_LEFT_SHARE",
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

#: The variant of the polynomial map acting on the hysteresis output (slot 3.5 of
#: :data:`hasel.effects.base.SLOT_ORDER`, between the hysteresis and the dynamics).
AFTER_HYST = "after_hysteresis"
#: The knee (corner) form of the map after the hysteresis (:func:`knee_map`).
AFTER_HYST_KNEE = AFTER_HYST + ":knee"
#: Starting corners of the knee after the hysteresis: these quantiles of the hysteresis output over the
#: training samples (a corner needs data on both sides; the tuning simulator's knees, 3-4.5 kV in a drive up
#: to about 5-6 kV, lie there). Set by the form, not tuned: evenly spaced deciles.
KNEE_GRID_QUANTILES = (0.1, 0.2, 0.3, 0.4, 0.5, 0.6, 0.7, 0.8, 0.9)
#: The dead-band form's variant (an input-side map: the chain's input slot).
DEAD = "input:dead"
#: Starting thresholds of the dead band: these quantiles of the map's input ``|x|`` over the training
#: samples (a threshold must have samples below it to be seen; the search's bound is the 0.6 quantile).
#: Set on ``bench/tune_diag/deadzones.py`` seed 1 and ``multi2.py`` seed 21 (thresholds 0.2-2 kV on
#: commands of 0-9 kV: between the 0.01 and 0.4 quantiles).
DEAD_GRID_QUANTILES = (0.005, 0.02, 0.05, 0.1, 0.15, 0.2, 0.27, 0.35, 0.45)
#: The corner's width ``w``: its start and its bounds, times the input's half-range ``u_s`` (a hard
#: corner, 0.03 kV in ``multi2.py``'s dead zone, is about 0.01 ``u_s``; a corner wider than a quarter of
#: the range is a curve, the polynomial's).
DEAD_WIDTH_START = 0.01
DEAD_WIDTH_BOUNDS = (1e-3, 0.25)
#: Bounds of the dead band's gain above the threshold (a factor on the nominal one).
DEAD_GAIN_BOUNDS = (0.1, 10.0)
#: Function evaluations of the dead band's refinement from the best start (threshold, gain, width).
DEAD_REFINE_NFEV = 10
#: The dead band's flat zone: the inputs where its slope is below this share of its gain ``g`` (the
#: band passes less than a tenth of a change there: below ``d - 2.2 w`` for a corner of width ``w``); its
#: corner: the slope between this share and ``1 -`` it (within ``d +- 2.2 w``). A conventional 10 %/90 %
#: split (as a rise time's), not tuned.
DEAD_FLAT_SLOPE = 0.1


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
    """The generic input map (also the map after the hysteresis) ``x + u_s sum_j theta_j z^j``, ``z = (x - u_c) / u_s`` (clipped to [-1, 1])."""
    z = (x - u_c) / u_s
    return x + u_s * poly_map(theta, z)


def dead_map(theta, x: np.ndarray) -> np.ndarray:
    """The dead band ``g (w sp((x - d) / w) - w sp((-x - d) / w))`` of the input ``x`` (input unit, e.g. kV),
    ``theta = (d, g, w)``: threshold ``d`` and corner width ``w`` in the input's unit, gain ``g``
    (dimensionless); ``sp(a) = log(1 + e^a)``. Odd and smooth: 0 at ``x = 0``, about ``g (|x| - d)`` with
    ``x``'s sign beyond the threshold, about 0 within it."""
    d, g, w = (float(v) for v in theta[:3])
    x = np.asarray(x, float)
    return g * w * (np.logaddexp(0.0, (x - d) / w) - np.logaddexp(0.0, (-x - d) / w))


def knee_map(theta, x: np.ndarray, u_c: float, u_s: float) -> np.ndarray:
    """The knee after the hysteresis ``x + u_s (a_0 + a_1 z) + dead_map((d, g, w), x)`` (input unit, e.g. kV),
    ``theta = (a_0, a_1, d, g, w)``, ``z = (x - u_c) / u_s``: a line whose slope changes by ``g`` beyond
    ``|x| = d`` (threshold ``d`` and corner width ``w`` in the input's unit, ``a_0``, ``a_1``, ``g``
    dimensionless)."""
    x = np.asarray(x, float)
    a0, a1 = float(theta[0]), float(theta[1])
    return x + u_s * (a0 + a1 * (x - u_c) / u_s) + dead_map(theta[2:5], x)


def is_after_hysteresis(variant: str) -> bool:
    """Whether ``variant`` is a map of the hysteresis output (the polynomial or the knee)."""
    return variant.split(":")[0] == AFTER_HYST


def dead_slope(theta, x: np.ndarray) -> np.ndarray:
    """The slope ``d dead_map / dx`` (dimensionless) of the dead band ``theta = (d, g, w)`` at the inputs
    ``x`` (input unit): ``g (s((x - d) / w) + s((-x - d) / w))``, ``s`` the logistic function."""
    d, g, w = (float(v) for v in theta[:3])
    x = np.asarray(x, float)
    return g * (expit((x - d) / w) + expit((-x - d) / w))


def dead_zone_shares(theta, x: np.ndarray) -> tuple[float, float]:
    """The shares (0-1) of the inputs ``x`` (input unit) in the dead band's flat zone (its slope below
    :data:`DEAD_FLAT_SLOPE` times its gain ``g``) and on its corner (the slope between that and
    ``(1 - DEAD_FLAT_SLOPE) g``; :func:`dead_slope`); (0, 0) for no samples."""
    x = np.asarray(x, float)
    if x.size == 0:
        return 0.0, 0.0
    g = abs(float(theta[1]))
    sl = np.abs(dead_slope(theta, x))
    flat = sl < DEAD_FLAT_SLOPE * g
    corner = ~flat & (sl < (1.0 - DEAD_FLAT_SLOPE) * g)
    return float(np.mean(flat)), float(np.mean(corner))


def dead_visited(theta, x: np.ndarray) -> bool:
    """Whether the inputs ``x`` (input unit) show the dead band ``theta`` as a threshold: some of them lie in
    its flat zone, and at least as many there as on its corner (:func:`dead_zone_shares`).

    A dead band differs from a smooth convex curve by its flat zone; where the data lie mostly on the
    corner, the fit describes a bend (with an offset), and its threshold and width are those of a curve,
    not of a band. The cascaded tanks' pump curve (``bench/tune_diag/datasets.py``: a level growing with
    the square of the pump voltage, driven 0.4-6.5 V) took the form with its width at the bound, 0 % of
    its input flat and 87 % on the corner. The rule has no tuned constant (flat against corner, both by
    :data:`DEAD_FLAT_SLOPE`); on the tuning sets (``deadzones.py`` seed 1, ``multi2.py`` seed 21) the
    named dead bands had flat shares of 1-35 % against corner shares of 0-12 %, the soft bands whose
    corner is as wide as the band (``dz_10``, ``dz_14``: flat 0 %) go to the polynomial (the base's names)."""
    flat, corner = dead_zone_shares(theta, x)
    return flat > 0.0 and flat >= corner


def dead_flat_share(theta, x: np.ndarray) -> float:
    """The share (0-1) of the inputs ``x`` (input unit) in the dead band's flat zone (:func:`dead_zone_shares`)."""
    return dead_zone_shares(theta, x)[0]


def apply_input(fit: EffectFit, x: np.ndarray, u_c: float, u_s: float) -> np.ndarray:
    """The effective input (input unit) of an input-side map ``fit``: the dead band (variant
    :data:`DEAD`) or the polynomial (variant ``"input"`` or :data:`AFTER_HYST`, normalised by ``u_c``, ``u_s``)."""
    if fit.variant == DEAD:
        return dead_map(fit.theta, x)
    if fit.variant == AFTER_HYST_KNEE:
        return knee_map(fit.theta, x, u_c, u_s)
    return input_map(fit.theta, x, u_c, u_s)


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
    if _downstream_nonlinear(base, slot) or (variant == "input" and input_loop(base)):
        fit = _refine(pipe, base, fit, -np.inf, np.inf, max_nfev=25)
    return fit


def _dead_starts(pipe: FitContext, base: dict[str, EffectFit], grid: np.ndarray, w: float) -> EffectFit:
    """The best of dead bands with thresholds ``grid`` and width ``w`` (input unit), each with its gain by
    least squares on the training residual (exact with nothing nonlinear between the map and the
    output, else a start); one pass over the records."""
    sim = pipe.linear_of(base)
    ab = np.zeros(grid.size)
    aa = np.zeros(grid.size)
    for ri, rec in enumerate(pipe.prep.records):
        m = rec.train
        if not m.any():
            continue
        st = pipe.stages(base, ri)
        b = (rec.y - st["y"] + sim.run(st["x_eff"]))[m]
        for k, d in enumerate(grid):
            a = sim.run(dead_map((float(d), 1.0, w), st["x_eff"]))[m]
            ab[k] += float(np.einsum("i,i->", a, b))
            aa[k] += float(np.einsum("i,i->", a, a))
    g = np.clip(np.where(aa > 0, ab / np.maximum(aa, 1e-300), 1.0), *DEAD_GAIN_BOUNDS)
    # ||b - g a||^2 - ||b||^2 at each threshold's gain
    cost = g * g * aa - 2.0 * g * ab
    k = int(np.argmin(cost))
    return EffectFit("static_nonlinearity", DEAD, (float(grid[k]), float(g[k]), float(w)))


def _map_inputs(pipe: FitContext, base: dict[str, EffectFit]) -> np.ndarray:
    """The input-side map's input (input unit) on the training samples of every record, ``base`` before it."""
    return np.concatenate([pipe.stages(base, ri)["x_map"][rec.train] for ri, rec in enumerate(pipe.prep.records)
                           if rec.train.any()] or [np.zeros(0)])


def fit_dead(pipe: FitContext, effects: dict[str, EffectFit]) -> EffectFit | None:
    """The dead band (:data:`DEAD`) fitted with ``effects`` fixed: thresholds at the quantiles
    :data:`DEAD_GRID_QUANTILES` of the map's input ``|x|`` (training samples), each with its gain by least
    squares and the width at :data:`DEAD_WIDTH_START`, the best refined (threshold, gain and width within
    :meth:`StaticMapFamily.bounds`). None when the input holds fewer than three levels (a step cannot
    place a corner)."""
    base = {k: v for k, v in effects.items() if k != "static_nonlinearity"}
    if getattr(pipe, "max_degree", STATIC_DEGREE) < 2:
        return None
    ax = np.abs(_map_inputs(pipe, base))
    if ax.size < 10:
        return None
    grid = np.unique(np.round(np.quantile(ax, DEAD_GRID_QUANTILES), 9))
    grid = grid[grid > 0]
    if grid.size == 0:
        return None
    f0 = _dead_starts(pipe, base, grid, DEAD_WIDTH_START * pipe.u_s)
    lo, hi = FAMILY.bounds(pipe, f0)
    hi = hi.copy()
    hi[0] = max(float(np.quantile(ax, 0.6)), float(grid[-1]))
    f0 = EffectFit("static_nonlinearity", DEAD, tuple(map(float, np.clip(f0.theta, lo, hi))))
    return _refine(pipe, base, f0, lo, hi, max_nfev=DEAD_REFINE_NFEV,
                   x_scale=np.array([0.02 * pipe.u_s, 0.05, 0.01 * pipe.u_s]))


def fit_input_side(pipe: FitContext, effects: dict[str, EffectFit]) -> EffectFit:
    """The input-side map with ``effects`` fixed: the polynomial (:func:`fit_variant`), or the dead band
    (:func:`fit_dead`) when it lowers the training BIC and is not nearly a line (:func:`linear_static`'s
    rule: a band the input never crosses is a gain and an offset, the load's and the polynomial's) and the
    data see its flat zone at least as often as its corner (:func:`dead_visited`: else the data see a bend,
    a curve the polynomial describes)."""
    base = {k: v for k, v in effects.items() if k != "static_nonlinearity"}
    poly = fit_variant(pipe, effects, "input")
    dead = fit_dead(pipe, effects)
    if dead is None or not dead_visited(dead.theta, _map_inputs(pipe, base)):
        return poly
    r = pipe.residuals(_with(base, dead), "train")
    s_d = sumsq(r)
    s_p = _sse(pipe, _with(base, poly))
    if (bic_prefers(r.size, s_p, s_d, dead.n_params - poly.n_params)
            and not _nearly_linear(pipe, base, "input", _static_basis(pipe, base, "input"), None, s_full=s_d)):
        return dead
    return poly


def fit_knee_after_hysteresis(pipe: FitContext, effects: dict[str, EffectFit]) -> EffectFit | None:
    """The knee after the hysteresis (:data:`AFTER_HYST_KNEE`, :func:`knee_map`) with ``effects`` fixed: corners
    at the quantiles :data:`KNEE_GRID_QUANTILES` of the hysteresis output (training samples), the width at
    :data:`DEAD_WIDTH_START` times ``u_s``, each with its offset, slope and change of slope by least squares on
    the training residual (exact with nothing nonlinear after the map, else a start); the best refined by
    nonlinear least squares (:data:`DEAD_REFINE_NFEV` evaluations, within :meth:`StaticMapFamily.bounds`).
    None without a hysteresis or where the input holds fewer than three levels."""
    if not input_loop(effects) or getattr(pipe, "max_degree", STATIC_DEGREE) < 2:
        return None
    base = {k: v for k, v in effects.items() if k != "static_nonlinearity"}
    recs = [(ri, rec) for ri, rec in enumerate(pipe.prep.records) if rec.train.any()]
    sts = {ri: pipe.stages(base, ri) for ri, _ in recs}
    xh = np.concatenate([sts[ri]["x_hyst"][rec.train] for ri, rec in recs] or [np.zeros(0)])
    if xh.size < 10:
        return None
    grid = np.unique(np.round(np.quantile(np.abs(xh), KNEE_GRID_QUANTILES), 9))
    grid = grid[grid > 0]
    if grid.size == 0:
        return None
    w = DEAD_WIDTH_START * pipe.u_s
    sim = pipe.linear_of(base)
    AA = np.zeros((grid.size, 3, 3))
    Ab = np.zeros((grid.size, 3))
    for ri, rec in recs:
        st, m = sts[ri], rec.train
        x = st["x_hyst"]
        b = (rec.y - st["y"])[m]
        c0 = sim.run(np.full(x.shape, pipe.u_s))[m]
        c1 = sim.run(x - pipe.u_c)[m]
        for k, d in enumerate(grid):
            B = np.column_stack([c0, c1, sim.run(dead_map((float(d), 1.0, w), x))[m]])
            AA[k] += B.T @ B
            Ab[k] += B.T @ b
    best, best_cost = None, np.inf
    for k, d in enumerate(grid):
        M = AA[k] + 1e-9 * float(np.trace(AA[k])) / 3.0 * np.eye(3)  # a ridge only against exact collinearity
        try:
            th = np.linalg.solve(M, Ab[k])
        except np.linalg.LinAlgError:
            continue
        cost = float(th @ AA[k] @ th - 2.0 * th @ Ab[k])  # ||b - B th||^2 - ||b||^2
        if cost < best_cost:
            best, best_cost = (float(th[0]), float(th[1]), float(d), float(th[2]), float(w)), cost
    if best is None:
        return None
    f0 = EffectFit("static_nonlinearity", AFTER_HYST_KNEE, best)
    lo, hi = FAMILY.bounds(pipe, f0)
    return _refine(pipe, base, f0, lo, hi, max_nfev=DEAD_REFINE_NFEV,
                   x_scale=np.array([0.01, 0.05, 0.02 * pipe.u_s, 0.05, 0.01 * pipe.u_s]))


def fit_after_hysteresis(pipe: FitContext, effects: dict[str, EffectFit], form: str | None = None) -> EffectFit | None:
    """The map of the hysteresis output with ``effects`` fixed (they must hold a hysteresis; None otherwise).
    ``form`` :data:`AFTER_HYST`: the polynomial, least squares on the responses to the monomials of the
    hysteresis output (degree by cross-validation, only the offset if nearly a line), refined where a nonlinear
    stage follows (:func:`fit_variant`); :data:`AFTER_HYST_KNEE`: the knee (:func:`fit_knee_after_hysteresis`);
    None: both, the one with the lower validation error kept (the samples the diagnosis compares sets on)."""
    if not input_loop(effects):
        return None
    if form == AFTER_HYST_KNEE:
        return fit_knee_after_hysteresis(pipe, effects)
    poly = fit_variant(pipe, effects, AFTER_HYST)
    if form is not None:
        return poly
    knee = fit_knee_after_hysteresis(pipe, effects)
    if knee is None:
        return poly
    base = {k: v for k, v in effects.items() if k != "static_nonlinearity"}
    s_p = sumsq(pipe.residuals(_with(base, poly), "valid"))
    s_k = sumsq(pipe.residuals(_with(base, knee), "valid"))
    return knee if s_k < s_p else poly


def _fit_static(pipe: FitContext, effects: dict[str, EffectFit]) -> EffectFit | None:
    best, best_cost = None, np.inf
    base = {k: v for k, v in effects.items() if k != "static_nonlinearity"}
    for variant in ("input", "internal"):
        fit = fit_input_side(pipe, effects) if variant == "input" else fit_variant(pipe, effects, variant)
        c = _sse(pipe, _with(base, fit))
        if c < best_cost:
            best, best_cost = fit, c
    return best


def _static_basis(pipe: FitContext, effects: dict[str, EffectFit], variant: str):
    """Least-squares basis of the static map ``variant``: the responses to its monomials."""
    def basis(ri, st):
        sim = pipe.linear_of(effects)
        if variant in ("input", AFTER_HYST):
            z = (st["x_map" if variant == "input" else "x_hyst"] - pipe.u_c) / pipe.u_s
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
    if f.variant in (DEAD, AFTER_HYST_KNEE):  # judged against its side's polynomial offset and line
        side = "input" if f.variant == DEAD else AFTER_HYST
        return _nearly_linear(pipe, base, side, _static_basis(pipe, base, side), None,
                              s_full=_sse(pipe, effects))
    return _nearly_linear(pipe, base, f.variant, _static_basis(pipe, base, f.variant), np.asarray(f.theta))


def _nearly_linear(pipe: FitContext, base: dict[str, EffectFit], variant: str, basis, th: np.ndarray | None,
                   s_full: float | None = None) -> bool:
    """Whether the map ``th`` is nearly a line: beyond its offset (the best constant map), its
    curvature (the part beyond the best line) removes less than :data:`NEAR_LINEAR_SHARE` of what
    the whole map removes, and less than :data:`CURVE_LEFT_SHARE` of what the best line leaves (sums of
    squares of the training residual); the rest is a slope, a linear correction. ``th`` None: another
    form of the map (the dead band) whose training sum of squares is ``s_full``, against the polynomial
    ``variant``'s offset and line."""
    def sse(t: np.ndarray) -> float:
        return _sse(pipe, _with(base, EffectFit("static_nonlinearity", variant, tuple(map(float, t)))))

    if s_full is None:
        s_full = sse(th)
    beyond_offset = sse(_poly_ls(pipe, base, basis, degrees=(0,))) - s_full
    if beyond_offset <= 0:
        return False
    s_line = s_full if th is not None and th.size <= 2 else sse(_poly_ls(pipe, base, basis, degrees=(1,)))
    curvature = s_line - s_full
    # a large gain change (a power law far from its reference voltage) makes any curvature a small share of
    # what the map removes, yet the curvature may remove most of what the line leaves: a nonlinearity
    return curvature < NEAR_LINEAR_SHARE * beyond_offset and curvature < CURVE_LEFT_SHARE * max(s_line, 0.0)



class StaticMapFamily(EffectFamily):
    """The ``static_nonlinearity`` family (see the module's docstring)."""

    name = "static_nonlinearity"
    slot = "input"
    variants = ("input", "internal", AFTER_HYST)
    truth_class = StaticNonlinearity

    def param_names(self, fit: EffectFit) -> tuple[str, ...]:
        """``("z^0", "z^1", ...)``: the polynomial's coefficients; the dead band's ``("threshold", "gain",
        "width")`` (input unit, factor, input unit)."""
        if fit.variant == DEAD:
            return ("threshold", "gain", "width")
        if fit.variant == AFTER_HYST_KNEE:
            return ("z^0", "z^1", "threshold", "gain", "width")
        return tuple(f"z^{j}" for j in range(len(fit.theta)))

    def bounds(self, ctx: FitContext, fit: EffectFit) -> tuple[np.ndarray, np.ndarray]:
        """The polynomials are free; the dead band's threshold lies in ``[0, u_c + u_s]`` (input unit), its
        gain in :data:`DEAD_GAIN_BOUNDS`, its width in :data:`DEAD_WIDTH_BOUNDS` times ``u_s``; the knee after the
        hysteresis has the same threshold and width bounds, its line and change of slope free."""
        if fit.variant == AFTER_HYST_KNEE:
            inf = np.inf
            return (np.array([-inf, -inf, 0.0, -inf, DEAD_WIDTH_BOUNDS[0] * ctx.u_s]),
                    np.array([inf, inf, max(ctx.u_c + ctx.u_s, 1e-12), inf, DEAD_WIDTH_BOUNDS[1] * ctx.u_s]))
        if fit.variant == DEAD:
            return (np.array([0.0, DEAD_GAIN_BOUNDS[0], DEAD_WIDTH_BOUNDS[0] * ctx.u_s]),
                    np.array([max(ctx.u_c + ctx.u_s, 1e-12), DEAD_GAIN_BOUNDS[1], DEAD_WIDTH_BOUNDS[1] * ctx.u_s]))
        return super().bounds(ctx, fit)

    def form_limits(self, ctx: FitContext, fit: EffectFit) -> tuple[np.ndarray, np.ndarray]:
        """:meth:`bounds`, except the dead band's narrowest width: a hard corner is an ordinary value."""
        lo, hi = self.bounds(ctx, fit)
        if fit.variant in (DEAD, AFTER_HYST_KNEE):
            lo = lo.copy()
            lo[2 if fit.variant == DEAD else 4] = -np.inf
        return lo, hi

    def stage(self, fit: EffectFit, scales: Scales, dt_s: float) -> MapStage | InternalMapStage:
        """The input map (memoryless: the polynomial or the dead band), or the internal map through the
        linear model ``scales.num/den``."""
        if fit.variant.split(":")[0] in ("input", AFTER_HYST):
            return MapStage(lambda x: apply_input(fit, x, scales.u_c, scales.u_s))
        return InternalMapStage(fit.theta, getattr(scales, "num"), getattr(scales, "den"), scales.y_c, scales.y_s,
                                dt_s)

    def truth_stage(self, effect: Effect, dt_s: float) -> MapStage:
        """The effective voltage of the truth form."""
        assert isinstance(effect, StaticNonlinearity)
        return MapStage(effect.apply)

    def fit(self, ctx: FitContext, effects: dict[str, EffectFit]) -> EffectFit | None:
        """Input and internal polynomial maps by least squares (degree by cross-validation), the input side's
        dead band in place of its polynomial when the BIC says so (:func:`fit_input_side`), the better of
        the two sides kept."""
        return _fit_static(ctx, effects)

    def describe(self, ctx: FitContext, fit: EffectFit, units: tuple[str, str],
                 effects: dict[str, EffectFit]) -> dict:
        """Coefficients, normalisation, the curve's deviation on 9 points and the offset in output units;
        for the dead band its threshold, gain and width with units."""
        if fit.variant == DEAD:
            return describe_dead(ctx, fit, units, effects)
        if fit.variant == AFTER_HYST_KNEE:
            return describe_knee(ctx, fit, units, effects)
        out = describe_poly(ctx, fit, units)
        ins = fit.variant in ("input", AFTER_HYST)
        g0 = ctx.linear_of(effects or {}).dc_gain if ins else 1.0
        out["output_offset_at_centre"] = float(g0 * (ctx.u_s if ins else ctx.y_s) * fit.theta[0])
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
    cands = {"input": fit_input_side(ctx, base), "internal": fit_variant(ctx, base, "internal")}
    sens = family("sensor_nonlinearity").fit(ctx, base)
    if sens is not None:
        cands["sensor"] = sens
    share = {k: _sse(ctx, _with(base, f)) / max(s0, 1e-300) for k, f in cands.items()}
    order = sorted(share, key=share.get)
    runner = share[order[1]] / max(share[order[0]], 1e-300) if len(order) > 1 else float("inf")
    return {"remaining_share": share, "best": order[0], "runner_up": order[1] if len(order) > 1 else None,
            "runner_up_over_best": runner, "separable": runner > SIDES_SEPARABLE}


def describe_dead(ctx: FitContext, fit: EffectFit, units: tuple[str, str], effects: dict[str, EffectFit]) -> dict:
    """A dead band's description: threshold and width (input unit), gain, the shares of the training input
    samples within the threshold and in its flat zone (:func:`dead_flat_share`), the effective input's deviation on 9 points and the output offset at
    the input's centre (output unit)."""
    ui, uo = units
    d, g, w = fit.theta[:3]
    c, s = ctx.u_c, ctx.u_s
    xs = np.linspace(c - s, c + s, 9)
    out: dict = {"variant": fit.variant, "threshold": float(d), "threshold_unit": ui, "gain": float(g),
                 "width": float(w), "width_unit": ui,
                 "form": "g*(w*sp((x - d)/w) - w*sp((-x - d)/w)), sp(a) = log(1 + exp(a)): nothing passes "
                         "below the threshold d, the rest with the gain g, the corner rounded over about w",
                 "curve": {"at": xs.tolist(), "deviation": (dead_map(fit.theta, xs) - xs).tolist()}}
    try:
        x = np.concatenate([r.u[r.train] for r in ctx.prep.records if r.train.any()])
        out["share_within_threshold"] = float(np.mean(np.abs(x) < d)) if x.size else None
        out["share_flat"] = dead_flat_share(fit.theta, x) if x.size else None
    except (AttributeError, ValueError):
        out["share_within_threshold"] = None
        out["share_flat"] = None
    g0 = ctx.linear_of(effects or {}).dc_gain
    out["output_offset_at_centre"] = float(g0 * (dead_map(fit.theta, np.array([c]))[0] - c))
    out["output_offset_unit"] = uo
    return out


def describe_knee(ctx: FitContext, fit: EffectFit, units: tuple[str, str], effects: dict[str, EffectFit]) -> dict:
    """The knee after the hysteresis's description: offset and slope change (dimensionless), threshold and
    width (input unit), the map's deviation on 9 points (input unit) and the output offset at the input's
    centre (output unit)."""
    ui, uo = units
    a0, a1, d, g, w = (float(v) for v in fit.theta[:5])
    c, s = ctx.u_c, ctx.u_s
    xs = np.linspace(c - s, c + s, 9)
    g0 = ctx.linear_of(effects or {}).dc_gain
    return {"variant": fit.variant, "coefficients": {"z^0": a0, "z^1": a1}, "threshold": d, "threshold_unit": ui,
            "slope_change": g, "width": w, "width_unit": ui,
            "form": "x_h + s*(a_0 + a_1 z) + g*(w*sp((x_h - d)/w) - w*sp((-x_h - d)/w)), z = (x_h - c)/s, "
                    "sp(a) = log(1 + exp(a)), x_h the hysteresis output: a line whose slope changes by g beyond "
                    "|x_h| = d (the map acts after the hysteresis, before the dynamics)",
            "normalisation": {"centre": c, "half_range": s, "unit": ui},
            "curve": {"at": xs.tolist(), "deviation": (knee_map(fit.theta, xs, c, s) - xs).tolist()},
            "output_offset_at_centre": float(g0 * (knee_map(fit.theta, np.array([c]), c, s)[0] - c)),
            "output_offset_unit": uo}


def describe_poly(ctx: Scales, fit: EffectFit, units: tuple[str, str]) -> dict:
    """A polynomial map's description (static or sensor): coefficients, normalisation and curve."""
    ui, uo = units
    th = fit.theta
    side = ("output" if fit.name == "sensor_nonlinearity" else
            ("input" if fit.variant in ("input", AFTER_HYST) else "output"))
    c, s = (ctx.u_c, ctx.u_s) if side == "input" else (ctx.y_c, ctx.y_s)
    names = (tuple(f"z^{j}" for j in range(len(th))) if fit.name == "static_nonlinearity"
             else tuple(f"w^{j}" for j in range(len(th))))
    out: dict = {"variant": fit.variant, "coefficients": dict(zip(names, th))}
    out["normalisation"] = {"centre": c, "half_range": s, "unit": ui if side == "input" else uo,
                            "form": ("x + s*sum_j a_j z^j, z = (x - c)/s"
                                     if fit.name == "static_nonlinearity" and fit.variant == "input" else
                                     "x_h + s*sum_j a_j z^j, z = (x_h - c)/s, x_h the hysteresis output (the map acts "
                                     "after the hysteresis, before the dynamics)"
                                     if fit.name == "static_nonlinearity" and fit.variant == AFTER_HYST else
                                     "y + G1(s*sum_j b_j w^j), w = (y - c)/s, G1 = G/G(0)"
                                     if fit.name == "static_nonlinearity" else
                                     "y + s*sum_j c_j w^j, w = (y - c)/s")}
    xs = np.linspace(c - s, c + s, 9)
    z = (xs - c) / s
    dev = s * poly_map(th, z)
    out["curve"] = {"at": xs.tolist(), "deviation": dev.tolist()}
    return out


FAMILY = StaticMapFamily()
