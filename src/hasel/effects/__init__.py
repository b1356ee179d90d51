"""Unmodelled effects of a HASEL actuator: one module per family, and the "truth" plant.

- :mod:`hasel.effects.base`: the protocol every family obeys
  (:class:`~hasel.effects.base.EffectFamily`: slot, forms, chunked stages, fit, bounds,
  describe, sample, signature) and :class:`~hasel.effects.base.EffectFit`.
- one module per family: :mod:`~hasel.effects.static_map`, :mod:`~hasel.effects.asymmetric`,
  :mod:`~hasel.effects.drift`, :mod:`~hasel.effects.saturation`, :mod:`~hasel.effects.delay`,
  :mod:`~hasel.effects.sensor`, :mod:`~hasel.effects.load`, :mod:`~hasel.effects.hysteresis`;
  each holds its truth dataclass, its generic (fitted) forms and their fits.
- :mod:`hasel.effects.registry`: the one place the families are registered.
- :mod:`hasel.effects.params`: the truth forms by name (:func:`from_name`,
  :func:`sample_effect`); :mod:`hasel.effects.truth`: :class:`TruthActuator`, the nominal
  chain plus any combination of them, run by the families' own stages.
- :mod:`hasel.effects.operators`: memory operators (play, Bouc-Wen, lags, delay, rate
  limits); :mod:`hasel.effects.fitkit`: the fits' shared least-squares tools;
  :mod:`hasel.effects.evidence`: frequency-domain evidence for the signature hooks.
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
