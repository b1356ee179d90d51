"""Unmodelled effects of a HASEL actuator and the "truth" plant that combines them.

- :mod:`hasel.effects.params`: the eight effects as parameter dataclasses with
  physical units, :func:`from_name` (keyed by the names of VERDICT.json) and random
  draws for blind cases (:func:`sample_effect`, ``Effect.sample_params(rng)``).
- :mod:`hasel.effects.truth`: :class:`TruthActuator`, the nominal chain plus any
  combination of them, obeying :class:`hasel.plant.Actuator`.
- :mod:`hasel.effects.operators`: the memory operators (play, Bouc-Wen,
  direction-dependent lag, delay line) and :func:`scale_resonances`.
"""
from hasel.effects.params import (EFFECT_CLASSES, EFFECT_NAMES, AsymmetricDynamics, ChargeDrift, Effect,
                                  Hysteresis, LoadMass, Saturation, SensorNonlinearity, StaticNonlinearity,
                                  TimeDelay, from_name, sample_effect)
from hasel.effects.truth import TruthActuator

__all__ = [
    "EFFECT_NAMES", "EFFECT_CLASSES", "Effect", "StaticNonlinearity", "AsymmetricDynamics", "ChargeDrift",
    "Saturation", "TimeDelay", "SensorNonlinearity", "LoadMass", "Hysteresis", "from_name", "sample_effect",
    "TruthActuator",
]
