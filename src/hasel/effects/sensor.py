"""``sensor_nonlinearity``: the sensor's calibration curve is not a line (acts on what is measured).

Forms
-----
- truth :class:`SensorNonlinearity`: ``z + bow sin(pi x) + skew (2x - 1)^3``,
  ``x = clip(z / span, -0.25, 1.25)``.
- generic ``output`` (``theta = (c_0 .. c_d)``): ``y + y_s sum_j c_j w^j``,
  ``w = (y - y_c) / y_s`` (held constant beyond the training range), the last stage
  before a measured clip.

Both memoryless (:class:`hasel.effects.static_map.MapStage`). Signature: a curve bends
the whole range and piles no samples on one value (a clip does:
:func:`hasel.effects.saturation.pile_up`).
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import ClassVar

import numpy as np

from hasel.effects.base import Effect, EffectFamily, EffectFit, FitContext, Scales
from hasel.effects.fitkit import STATIC_DEGREE, _poly_ls, monomials, poly_map
from hasel.effects.saturation import pile_up
from hasel.effects.static_map import MapStage, describe_poly
from hasel.validate import finite, positive

__all__ = ["SensorNonlinearity", "sensor_map", "bend_profile", "SensorFamily", "FAMILY"]


@dataclass(frozen=True)
class SensorNonlinearity(Effect):
    """The strain sensor's calibration curve is not a line.

    The sensor reads ``z + bow_mm sin(pi x) + skew_mm (2x - 1)^3`` for the true stroke
    ``z``, with ``x = clip(z / span_mm, -0.25, 1.25)``: a bow that is largest mid-span
    (the paper saw offsets at 2 and 4 mm after a line-of-best-fit calibration) and
    an asymmetric tilt. It acts on the measurement only, never on the true stroke.

    Attributes
    ----------
    bow_mm : float
        Deviation mid-span, mm (either sign).
    skew_mm : float
        Cubic tilt at the ends of the span, mm (either sign).
    span_mm : float
        Calibrated span, mm.
    """

    name: ClassVar[str] = "sensor_nonlinearity"
    bow_mm: float = 0.3
    skew_mm: float = 0.0
    span_mm: float = 9.0

    def __post_init__(self) -> None:
        finite("bow_mm", self.bow_mm)
        finite("skew_mm", self.skew_mm)
        positive("span_mm", self.span_mm)

    def apply(self, stroke_mm: np.ndarray) -> np.ndarray:
        """Stroke (mm) that the sensor reports for the true ``stroke_mm`` (mm)."""
        z = np.asarray(stroke_mm, float)
        x = np.clip(z / self.span_mm, -0.25, 1.25)
        return z + self.bow_mm * np.sin(np.pi * x) + self.skew_mm * (2.0 * x - 1.0) ** 3

    @classmethod
    def sample_params(cls, rng: np.random.Generator) -> "SensorNonlinearity":
        sign = 1.0 if rng.random() < 0.5 else -1.0
        return cls(bow_mm=float(sign * rng.uniform(0.25, 0.6)), skew_mm=float(rng.uniform(-0.15, 0.15)),
                   span_mm=float(rng.uniform(8.0, 11.0)))


def sensor_map(theta, y: np.ndarray, y_c: float, y_s: float) -> np.ndarray:
    """The generic sensor curve ``y + y_s sum_j theta_j w^j``, ``w = (y - y_c) / y_s`` (clipped to [-1, 1])."""
    w = (y - y_c) / y_s
    return y + y_s * poly_map(theta, w)


def _fit_sensor(pipe: FitContext, effects: dict[str, EffectFit]) -> EffectFit | None:
    def basis(ri, st):
        w = (st["y_sat"] - pipe.y_c) / pipe.y_s
        return [pipe.y_s * m for m in monomials(w, STATIC_DEGREE + 1)]

    th = _poly_ls(pipe, effects, basis)
    return EffectFit("sensor_nonlinearity", "output", tuple(map(float, th)))



def bend_profile(theta, n: int = 201) -> dict:
    """Where a fitted polynomial map bends: shares of its curvature (``|p''|``) in the top and bottom
    quarters of the normalised range ``w`` in [-1, 1] (each 0.25 for an even bend).

    A one-sided flattening (a limit approached smoothly: a soft stroke limit, an end stop)
    puts most of its curvature at one end; a calibration curve (a bow, a square law)
    spreads it over the range.
    """
    w = np.linspace(-1.0, 1.0, n)
    c = np.polynomial.polynomial.polyder(np.asarray(theta, float), 2) if len(theta) > 2 else np.zeros(1)
    k = np.abs(np.polynomial.polynomial.polyval(w, c))
    tot = float(k.sum())
    if tot <= 0:
        return {"upper_quarter_share": 0.25, "lower_quarter_share": 0.25, "one_sided": False}
    up, lo = float(k[w >= 0.5].sum() / tot), float(k[w <= -0.5].sum() / tot)
    return {"upper_quarter_share": up, "lower_quarter_share": lo, "one_sided": max(up, lo) > 0.6}


class SensorFamily(EffectFamily):
    """The ``sensor_nonlinearity`` family (see the module's docstring)."""

    name = "sensor_nonlinearity"
    slot = "output"
    variants = ("output",)
    truth_class = SensorNonlinearity

    def param_names(self, fit: EffectFit) -> tuple[str, ...]:
        """``("w^0", "w^1", ...)``: the polynomial's coefficients."""
        return tuple(f"w^{j}" for j in range(len(fit.theta)))

    def stage(self, fit: EffectFit, scales: Scales, dt_s: float) -> MapStage:
        """The curve, normalised by ``scales.y_c``/``y_s``."""
        return MapStage(lambda y: sensor_map(fit.theta, y, scales.y_c, scales.y_s))

    def truth_stage(self, effect: Effect, dt_s: float) -> MapStage:
        """The truth form's reading of the true stroke."""
        assert isinstance(effect, SensorNonlinearity)
        return MapStage(effect.apply)

    def fit(self, ctx: FitContext, effects: dict[str, EffectFit]) -> EffectFit | None:
        """Polynomial by least squares on the output before the sensor (degree by cross-validation)."""
        return _fit_sensor(ctx, effects)

    def describe(self, ctx: FitContext, fit: EffectFit, units: tuple[str, str],
                 effects: dict[str, EffectFit]) -> dict:
        """Coefficients, normalisation and the curve's deviation on 9 points (output unit)."""
        return describe_poly(ctx, fit, units)

    def signature(self, ctx: FitContext, fit: EffectFit, effects: dict[str, EffectFit]) -> dict:
        """Share of the measured samples piled on each extreme (a curve piles none), and where the fitted
        curve bends (:func:`bend_profile`: one-sided like a soft limit, or over the whole range)."""
        return {"pile_up": pile_up(np.concatenate([r.y for r in ctx.prep.records])),
                "bend": bend_profile(fit.theta)}


FAMILY = SensorFamily()
