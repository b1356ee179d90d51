"""The eight unmodelled effects: parameter dataclasses, a registry and random draws.

Each effect is a frozen dataclass of physical parameters (units in the field names)
with defaults motivated by the paper, validated on construction. The registry maps
exactly the names of VERDICT.json (``shared/interfaces.md``) to the classes:

================== ===========================================================
name               what it models (where it acts in the truth chain)
================== ===========================================================
static_nonlinearity the stroke-voltage map is not a line: electrostatic
                   (~ v^2) or saturating; acts on the applied voltage
asymmetric_dynamics relaxation slower and more damped than activation; acts on
                   the stroke
charge_drift       slow gain and offset change driven by the history of the
                   applied voltage (charge retention)
saturation         amplifier voltage limit or full-stroke limit
time_delay         latency between command and actuation
sensor_nonlinearity the strain sensor's calibration curve is not a line; acts on
                   the measured stroke, not the true one
load_mass          an added mass: resonance lower and less damped
hysteresis         rate-independent memory of the zipping (Bouc-Wen)
================== ===========================================================

``sample_params(rng)`` draws a random instance for blind cases; the ranges are
chosen so that the effect is visible above a laser's noise in the project's
identification protocol (chirps around DC offsets), as a real rig's would be.
"""
from __future__ import annotations

from dataclasses import dataclass, fields
from typing import Any, ClassVar

import numpy as np

from hasel.errors import BadInputError
from hasel.validate import finite, in_range, positive

__all__ = [
    "EFFECT_NAMES", "Effect", "StaticNonlinearity", "AsymmetricDynamics", "ChargeDrift", "Saturation",
    "TimeDelay", "SensorNonlinearity", "LoadMass", "Hysteresis", "EFFECT_CLASSES", "from_name",
    "sample_effect",
]

#: The effect names, in the order of ``shared/interfaces.md``.
EFFECT_NAMES = ("static_nonlinearity", "asymmetric_dynamics", "charge_drift", "saturation",
                "time_delay", "sensor_nonlinearity", "load_mass", "hysteresis")


class Effect:
    """Base of the effect dataclasses: a ``name`` and a dict view of the parameters."""

    name: ClassVar[str] = ""

    def params(self) -> dict[str, Any]:
        """The parameters as a plain dict (JSON-ready)."""
        return {f.name: getattr(self, f.name) for f in fields(self)}  # type: ignore[arg-type]

    @classmethod
    def sample_params(cls, rng: np.random.Generator) -> "Effect":  # pragma: no cover - overridden
        """A random instance for a blind case."""
        raise NotImplementedError


def _choice(rng: np.random.Generator, options: tuple[str, ...]) -> str:
    return options[int(rng.integers(len(options)))]


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
        kind = _choice(rng, ("electrostatic", "saturating"))
        strength = rng.uniform(0.25, 0.6) if kind == "electrostatic" else rng.uniform(0.8, 1.6)
        return cls(kind=kind, strength=float(strength), v_ref_kv=float(rng.uniform(4.0, 5.5)))


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


@dataclass(frozen=True)
class ChargeDrift(Effect):
    """Slow gain and offset change driven by the history of the applied voltage.

    Charge accumulates in the dielectric as ``q``, a first-order low-pass of the
    applied voltage with time constant ``tau_s`` (kV), from none at rest. The stroke becomes
    ``z (1 - gain_loss_per_kv q) + offset_mm_per_kv q``: trapped charge screens the
    field (less gain) and holds the pouches partly zipped (an offset). The paper
    found < 5 % change over any 180 s at 0-9 kV; the defaults give about 4 % at 7 kV.

    Attributes
    ----------
    tau_s : float
        Charging time constant, s.
    gain_loss_per_kv : float
        Relative gain lost per kV of accumulated charge, 1/kV.
    offset_mm_per_kv : float
        Stroke offset per kV of accumulated charge, mm/kV (either sign).
    """

    name: ClassVar[str] = "charge_drift"
    tau_s: float = 120.0
    gain_loss_per_kv: float = 0.004
    offset_mm_per_kv: float = 0.02

    def __post_init__(self) -> None:
        positive("tau_s", self.tau_s)
        in_range("gain_loss_per_kv", self.gain_loss_per_kv, -0.2, 0.2)
        in_range("offset_mm_per_kv", self.offset_mm_per_kv, -2.0, 2.0)

    @classmethod
    def sample_params(cls, rng: np.random.Generator) -> "ChargeDrift":
        sign = 1.0 if rng.random() < 0.7 else -1.0
        return cls(tau_s=float(rng.uniform(20.0, 150.0)), gain_loss_per_kv=float(rng.uniform(0.006, 0.025)),
                   offset_mm_per_kv=float(sign * rng.uniform(0.02, 0.08)))


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


@dataclass(frozen=True)
class TimeDelay(Effect):
    """Latency between the command and the actuator (loop, DAC, amplifier).

    Attributes
    ----------
    delay_s : float
        Pure delay, s (rounded to the simulator's sample period).
    """

    name: ClassVar[str] = "time_delay"
    delay_s: float = 0.01

    def __post_init__(self) -> None:
        in_range("delay_s", self.delay_s, 0.0, 10.0)

    @classmethod
    def sample_params(cls, rng: np.random.Generator) -> "TimeDelay":
        return cls(delay_s=float(rng.uniform(0.003, 0.025)))


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


@dataclass(frozen=True)
class LoadMass(Effect):
    """An added mass on the actuator (the paper's 25.5 g test load).

    The mass multiplies the inertia of the actuator's mechanical modes, the complex
    pole pairs of P(s): ``s^2 + 2 zeta w s + w^2`` becomes ``(1 + mu) s^2 + 2 zeta w s +
    w^2``, i.e. the resonance falls by ``sqrt(1 + mu)`` and so does its damping
    ratio, with ``mu = mass_g / (actuator_mass_g * moving_fraction)``.
    Its weight also compresses the actuator: a static offset ``-sag_mm``.

    Attributes
    ----------
    mass_g : float
        Added mass, g.
    actuator_mass_g : float
        Actuator mass, g (39.4 g in the paper).
    moving_fraction : float
        Share of the actuator's mass that moves with the stroke.
    sag_mm : float
        Static compression under the load's weight, mm.
    """

    name: ClassVar[str] = "load_mass"
    mass_g: float = 25.5
    actuator_mass_g: float = 39.4
    moving_fraction: float = 1.0
    sag_mm: float = 0.0

    def __post_init__(self) -> None:
        in_range("mass_g", self.mass_g, 0.0, 1e4)
        positive("actuator_mass_g", self.actuator_mass_g)
        in_range("moving_fraction", self.moving_fraction, 1e-3, 1.0)
        finite("sag_mm", self.sag_mm)

    @property
    def mass_ratio(self) -> float:
        """``mu``: added mass over the moving mass."""
        return self.mass_g / (self.actuator_mass_g * self.moving_fraction)

    def loaded_den(self, den: np.ndarray) -> np.ndarray:
        """The denominator of P(s) (descending powers of s) with the added inertia."""
        from hasel.effects.operators import scale_resonances

        return scale_resonances(den, 1.0 + self.mass_ratio)

    @classmethod
    def sample_params(cls, rng: np.random.Generator) -> "LoadMass":
        return cls(mass_g=float(rng.uniform(20.0, 80.0)), moving_fraction=float(rng.uniform(0.5, 1.0)))


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


#: name -> class, exactly the names of :data:`EFFECT_NAMES`.
EFFECT_CLASSES: dict[str, type[Effect]] = {
    cls.name: cls for cls in (StaticNonlinearity, AsymmetricDynamics, ChargeDrift, Saturation, TimeDelay,
                              SensorNonlinearity, LoadMass, Hysteresis)
}


def from_name(name: str, **params: Any) -> Effect:
    """The effect called ``name`` with ``params`` (defaults for the rest).

    Parameters
    ----------
    name : str
        One of :data:`EFFECT_NAMES`.
    **params
        Fields of that effect's dataclass (units in their names).

    Returns
    -------
    Effect

    Raises
    ------
    BadInputError
        For an unknown name or parameter, or a parameter out of range.

    Examples
    --------
    >>> from_name("time_delay", delay_s=0.005).delay_s
    0.005
    """
    cls = EFFECT_CLASSES.get(name)
    if cls is None:
        raise BadInputError(f"unknown effect {name!r}; expected one of {', '.join(EFFECT_NAMES)}")
    known = {f.name for f in fields(cls)}  # type: ignore[arg-type]
    extra = sorted(set(params) - known)
    if extra:
        raise BadInputError(f"{name} has no parameter {', '.join(extra)}; it has {', '.join(sorted(known))}")
    return cls(**params)  # type: ignore[call-arg]


def sample_effect(name: str, rng: np.random.Generator) -> Effect:
    """A random instance of the effect called ``name`` (see each class's ``sample_params``)."""
    cls = EFFECT_CLASSES.get(name)
    if cls is None:
        raise BadInputError(f"unknown effect {name!r}; expected one of {', '.join(EFFECT_NAMES)}")
    return cls.sample_params(rng)
