"""The "truth" actuator: the nominal chain plus any combination of unmodelled effects.

Signal chain, at the simulator's rate (10 kHz), each stage present only if its effect is:

    command kV -> [time_delay] -> [saturation: amplifier limit] -> amplifier filter
    (applied_kv) -> [static_nonlinearity] -> [hysteresis] -> P(s) [load_mass: heavier
    resonances] -> [asymmetric_dynamics] -> [charge_drift] -> [saturation: full stroke]
    -> [load_mass: sag] -> stroke_mm

and ``sensor_nonlinearity`` maps the true stroke to what the strain sensor reports
(:attr:`TruthActuator.strain_curve`, for :class:`hasel.simulator.PlantSimulator`'s
``strain_curve``). Without effects between the amplifier and P(s) the command ->
stroke path is discretised exactly by zero-order hold, as in
:class:`hasel.plant.NominalActuator`, so with no effect at all both agree to
rounding; otherwise P(s) is driven by the trapezoidal mean of the effective
voltage over each sample.

Every stage keeps its state between calls, so the model can be stepped in blocks
(a 200 Hz loop's 50 samples) or run on a whole record at once with the same result.
"""
from __future__ import annotations

from collections.abc import Callable, Iterable

import numpy as np

from hasel.effects.base import Effect, Stage
from hasel.effects.drift import DriftStage
from hasel.effects.load import LoadMass
from hasel.effects.registry import FAMILIES
from hasel.effects.saturation import Saturation
from hasel.effects.sensor import SensorNonlinearity
from hasel.errors import BadInputError
from hasel.lti import SosFilter, zoh_sos
from hasel.plant import ActuatorSamples, NominalConfig, amplifier_filter_tf

__all__ = ["TruthActuator"]


class TruthActuator:
    """Nominal actuator plus unmodelled effects; obeys :class:`hasel.plant.Actuator`.

    Parameters
    ----------
    effects : iterable of Effect
        At most one of each name (see :mod:`hasel.effects.params`).
    config : NominalConfig, optional
        The nominal chain (the paper's P(s), 500 Hz filter, 10 kHz by default).

    Attributes
    ----------
    rate_hz : float
        Simulation rate, Hz.
    effects : dict of str to Effect
        The effects by name.
    strain_curve : callable or None
        True stroke (mm) -> stroke the strain sensor reports (mm); ``None`` without
        ``sensor_nonlinearity``.

    Examples
    --------
    >>> import numpy as np
    >>> from hasel.effects import TruthActuator, from_name
    >>> act = TruthActuator([from_name("time_delay", delay_s=0.01)])
    >>> act.reset(0.0)
    >>> out = act.run(np.full(1000, 2.0))
    >>> float(out.stroke_mm[99]) == 0.0   # nothing moves before 10 ms
    True
    """

    def __init__(self, effects: Iterable[Effect] = (), config: NominalConfig | None = None) -> None:
        self.config = config or NominalConfig()
        self.rate_hz = float(self.config.rate_hz)
        self.dt_s = 1.0 / self.rate_hz
        self.effects: dict[str, Effect] = {}
        for e in effects:
            if not isinstance(e, Effect):
                raise BadInputError(f"effects must be Effect instances (hasel.effects.from_name), got {e!r}")
            if e.name in self.effects:
                raise BadInputError(f"effect {e.name} given twice")
            self.effects[e.name] = e
        eff = self.effects
        sat: Saturation | None = eff.get("saturation")  # type: ignore[assignment]
        self._sensor: SensorNonlinearity | None = eff.get("sensor_nonlinearity")  # type: ignore[assignment]
        self._load: LoadMass | None = eff.get("load_mass")  # type: ignore[assignment]

        def stage(name: str, when: bool = True) -> Stage | None:
            # every effect runs its family's own chunked stage (the code the diagnosis fits)
            e = eff.get(name)
            return FAMILIES[name].truth_stage(e, self.dt_s) if e is not None and when else None

        self._delay = stage("time_delay")
        self._sat_amp = stage("saturation", sat is not None and sat.kind == "amplifier")
        self._static = stage("static_nonlinearity")
        self._hyst = stage("hysteresis")
        self._asym = stage("asymmetric_dynamics")
        self._drift: DriftStage | None = stage("charge_drift")  # type: ignore[assignment]
        self._sat_stroke = stage("saturation", sat is not None and sat.kind == "stroke")
        self._sag = stage("load_mass")
        num = np.asarray(self.config.num, float)
        den = np.asarray(self.config.den, float)
        if self._load is not None:
            den = self._load.loaded_den(den)
        amp_num, amp_den = amplifier_filter_tf(self.config.amp_filter_hz)
        self._amp = SosFilter(zoh_sos(amp_num, amp_den, self.dt_s, output="end"))
        self._split = self._static is not None or self._hyst is not None
        if self._split:
            self._plant = SosFilter(zoh_sos(num, den, self.dt_s, output="end"))
        else:
            self._plant = SosFilter(zoh_sos(np.polymul(amp_num, num), np.polymul(amp_den, den), self.dt_s,
                                            output="end"))
        self._p0 = float(num[-1] / den[-1])
        self._v_prev = 0.0
        self.strain_curve: Callable[[np.ndarray], np.ndarray] | None = (
            self._sensor.apply if self._sensor is not None else None)
        self.reset(0.0)

    # -- helpers -------------------------------------------------------------------------
    def _clip_cmd(self, u: np.ndarray) -> np.ndarray:
        return u if self._sat_amp is None else self._sat_amp.run(u)

    def _veff(self, applied: np.ndarray) -> np.ndarray:
        v = applied if self._static is None else self._static.run(applied)
        return v if self._hyst is None else self._hyst.run(v)

    def measure_mm(self, stroke_mm: np.ndarray) -> np.ndarray:
        """Stroke (mm) the strain sensor reports for the true ``stroke_mm`` (identity without a sensor effect)."""
        return np.asarray(stroke_mm, float) if self._sensor is None else self._sensor.apply(stroke_mm)

    # -- Actuator protocol -------------------------------------------------------------------
    def reset(self, command_kv: float = 0.0) -> None:
        """At rest with ``command_kv`` (kV) applied forever and no trapped charge."""
        u0 = float(command_kv)
        if self._delay is not None:
            self._delay.reset(u0)
        c0 = float(self._clip_cmd(np.array([u0]))[0])
        self._amp.reset(c0)
        v0 = c0 if self._static is None else float(self._static.run(np.array([c0]))[0])
        if self._hyst is not None:
            self._hyst.reset(v0)
        self._v_prev = v0
        self._plant.reset(v0 if self._split else c0)
        if self._asym is not None:
            self._asym.reset(self._p0 * v0)
        if self._drift is not None:  # no trapped charge at rest (reversed by the -1 kV hold)
            self._drift.reset(0.0)

    def run(self, command_kv: np.ndarray) -> ActuatorSamples:
        """Advance by the samples of ``command_kv`` (kV, at ``rate_hz``)."""
        u = np.asarray(command_kv, dtype=float)
        if u.ndim != 1:
            raise BadInputError(f"command_kv must be 1-D, got shape {u.shape}")
        if u.size == 0:
            return ActuatorSamples(np.zeros(0), np.zeros(0))
        if self._delay is not None:
            u = self._delay.run(u)
        c = self._clip_cmd(u)
        applied = self._amp.run(c)
        if self._split:
            v = self._veff(applied)
            v_mid = 0.5 * (np.concatenate([[self._v_prev], v[:-1]]) + v)
            self._v_prev = float(v[-1])
            z = self._plant.run(v_mid)
        else:
            z = self._plant.run(c)
        if self._asym is not None:
            z = self._asym.run(z)
        if self._drift is not None:
            z = self._drift.run(z, applied)
        if self._sat_stroke is not None:
            z = self._sat_stroke.run(z)
        if self._sag is not None:
            z = self._sag.run(z)
        return ActuatorSamples(applied_kv=applied, stroke_mm=z)
