"""The eight unmodelled effects' truth forms by name: :func:`from_name` and random draws.

The dataclasses live in their families' modules (:mod:`hasel.effects.registry`); this
module keeps the names they were imported by.

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

from dataclasses import fields
from typing import Any

import numpy as np

from hasel.effects.asymmetric import AsymmetricDynamics
from hasel.effects.base import Effect
from hasel.effects.delay import TimeDelay
from hasel.effects.drift import ChargeDrift
from hasel.effects.hysteresis import Hysteresis
from hasel.effects.load import LoadMass
from hasel.effects.registry import FAMILIES, NAMES
from hasel.effects.saturation import Saturation
from hasel.effects.sensor import SensorNonlinearity
from hasel.effects.static_map import StaticNonlinearity
from hasel.errors import BadInputError

__all__ = [
    "EFFECT_NAMES", "Effect", "StaticNonlinearity", "AsymmetricDynamics", "ChargeDrift", "Saturation",
    "TimeDelay", "SensorNonlinearity", "LoadMass", "Hysteresis", "EFFECT_CLASSES", "from_name",
    "sample_effect",
]

#: The effect names, in the order of ``shared/interfaces.md`` (those of the registry).
EFFECT_NAMES = NAMES

#: name -> truth dataclass, exactly the names of :data:`EFFECT_NAMES` (from the registry).
EFFECT_CLASSES: dict[str, type[Effect]] = {name: fam.truth_class for name, fam in FAMILIES.items()}


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
    if name not in FAMILIES:
        raise BadInputError(f"unknown effect {name!r}; expected one of {', '.join(EFFECT_NAMES)}")
    return FAMILIES[name].sample(rng)
