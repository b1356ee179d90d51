"""The actuator a plant file describes, at the simulator's rate (10 kHz).

- No effect: :class:`hasel.plant.NominalActuator` with the file's P(s): the amplifier's
  filter and P(s) discretised exactly by zero-order hold, as for the paper's model.
- Truth forms: :class:`hasel.effects.TruthActuator` with the file's P(s) (the same
  chain and stages as ``--plant truth:...``).
- Fitted forms: :class:`FittedChain`, the diagnosis's chain (delay, input clip or slew
  limit, input lag, input map, hysteresis, map after the hysteresis, P(s) with load, internal map,
  asymmetric lag or speed limit, drift, output clip, sensor map) run by each family's own chunked stage
  (:meth:`hasel.effects.base.EffectFamily.stage`), driven by the applied voltage. A
  *measured* clip (the range of the sensor that recorded the data, e.g. a laser reading
  nothing below 0 mm) is not part of the actuator: the simulated sensors have their own
  range, and the true stroke is not clipped by a sensor.

The file's dead time delays the stroke (for the linear part, the same as delaying
P(s)'s input), through the time-delay family's stage.
"""
from __future__ import annotations

import copy
from types import SimpleNamespace

import numpy as np

from hasel.effects.asymmetric import INPUT as ASYM_INPUT
from hasel.effects.base import EffectFit, Stage
from hasel.effects.hysteresis import OUTPUT as OUTPUT_HYST
from hasel.lti import SosFilter, zoh_sos
from hasel.plant import ActuatorSamples, NominalActuator, NominalConfig, amplifier_filter_tf
from hasel.plantfile import PlantModel

__all__ = ["FileActuator", "FittedChain", "build_actuator"]


def _delay_stage(delay_s: float, dt_s: float) -> Stage:
    from hasel.effects.registry import FAMILIES

    return FAMILIES["time_delay"].stage(EffectFit("time_delay", "input", (float(delay_s),)), None, dt_s)  # type: ignore[arg-type]


def _rest(stage: Stage | None, x0: float) -> float:
    """Reset ``stage`` at rest with input ``x0``; its output at rest."""
    if stage is None:
        return x0
    stage.reset(x0)
    return float(stage.run(np.array([x0]))[0])


class FittedChain:
    """The diagnosis's generic chain on the file's P(s); obeys :class:`hasel.plant.Actuator`.

    Parameters
    ----------
    fits : dict of str to EffectFit
        The fitted effects by name.
    scales : dict
        Their normalisation (``u_c``, ``u_s``, ``y_c``, ``y_s``, ``thresholds``, ``tau_smooth_s``).
    config : NominalConfig
        P(s), rate and the amplifier's filter.
    """

    def __init__(self, fits: dict[str, EffectFit], scales: dict, config: NominalConfig) -> None:
        from hasel.effects.load import LinearStage
        from hasel.effects.registry import FAMILIES

        self.config = config
        self.rate_hz = float(config.rate_hz)
        dt = 1.0 / self.rate_hz
        num, den = np.asarray(config.num, float), np.asarray(config.den, float)
        sc = SimpleNamespace(**scales, num=num, den=den)

        def stage(name: str, *prefixes: str) -> Stage | None:
            f = fits.get(name)
            if f is None or (prefixes and not f.variant.startswith(prefixes)):
                return None
            return FAMILIES[name].stage(f, sc, dt)

        self.fits = dict(fits)
        self._delay = stage("time_delay")
        self._sat_in = stage("saturation", "input", "slew")
        self._map_in = stage("static_nonlinearity", "input")
        self._hyst = stage("hysteresis", "input")
        self._hyst_out = stage("hysteresis", OUTPUT_HYST)  # a memory of the stroke, after the dynamics
        self._map_hyst = stage("static_nonlinearity", "after_hysteresis")  # a map of the hysteresis output
        self._map_int = stage("static_nonlinearity", "internal")
        self._asym_in = stage("asymmetric_dynamics", ASYM_INPUT)  # the lag of the voltage, before the dynamics
        self._asym = None if self._asym_in is not None else stage("asymmetric_dynamics")
        self._drift = stage("charge_drift")
        self._sat_out = stage("saturation", "output")
        self._sensor = stage("sensor_nonlinearity")
        amp_num, amp_den = amplifier_filter_tf(config.amp_filter_hz)
        self._amp = SosFilter(zoh_sos(amp_num, amp_den, dt, output="end"))
        # the input-side stages sit between the amplifier and P(s): P(s) then sees the applied
        # voltage (trapezoidal mean over each sample); without them the command -> stroke path
        # is discretised exactly, as in NominalActuator
        self._split = any(s is not None for s in (self._delay, self._sat_in, self._asym_in, self._map_in, self._hyst,
                                                      self._map_hyst))
        if "load_mass" in fits:
            self._lin: Stage = FAMILIES["load_mass"].stage(fits["load_mass"], sc, dt)
            self._split = True
        elif self._split:
            self._lin = LinearStage(num, den, dt)
        else:
            self._lin = LinearStage(np.polymul(amp_num, num), np.polymul(amp_den, den), dt)
        self._v_prev = 0.0
        self.reset(0.0)

    def reset(self, command_kv: float = 0.0) -> None:
        """At rest with ``command_kv`` (kV) applied forever; the drift holds no charge."""
        c = float(command_kv)
        self._amp.reset(c)
        x = _rest(self._delay, c)
        x = self._x_sat0 = _rest(self._asym_in, _rest(self._sat_in, x))
        x = _rest(self._map_in, x)
        x = self._v_prev = _rest(self._map_hyst, _rest(self._hyst, x))
        y = _rest(self._lin, x if self._split else c)
        y = _rest(self._map_int, y)
        y = _rest(self._hyst_out, _rest(self._asym, y))
        if self._drift is not None:
            self._drift.reset(y)
        y = _rest(self._sat_out, y)
        _rest(self._sensor, y)

    def run(self, command_kv: np.ndarray) -> ActuatorSamples:
        """Advance by the samples of ``command_kv`` (kV, at ``rate_hz``)."""
        c = np.asarray(command_kv, float)
        if c.size == 0:
            return ActuatorSamples(np.zeros(0), np.zeros(0))
        applied = self._amp.run(c)
        x = applied
        for st in (self._delay, self._sat_in, self._asym_in):
            x = x if st is None else st.run(x)
        x_sat = x
        for st in (self._map_in, self._hyst, self._map_hyst):
            x = x if st is None else st.run(x)
        if self._split:
            x_mid = 0.5 * (np.concatenate([[self._v_prev], x[:-1]]) + x)
            self._v_prev = float(x[-1])
            y = self._lin.run(x_mid)
        else:
            y = self._lin.run(c)
        for st in (self._map_int, self._asym, self._hyst_out):
            y = y if st is None else st.run(y)
        if self._drift is not None:
            y = self._drift.run(y, x_sat)
        for st in (self._sat_out, self._sensor):
            y = y if st is None else st.run(y)
        return ActuatorSamples(applied_kv=applied, stroke_mm=y)


class FileActuator:
    """The actuator of a :class:`PlantModel`; obeys :class:`hasel.plant.Actuator`.

    Parameters
    ----------
    model : PlantModel
        The plant file's content (in kV -> mm).
    rate_hz : float, optional
        Simulation rate, Hz (the paper's 10 kHz by default).

    Attributes
    ----------
    strain_curve : callable or None
        The truth form's sensor curve (true stroke mm -> what the strain sensor sees), if any.
    """

    def __init__(self, model: PlantModel, rate_hz: float | None = None) -> None:
        from hasel.effects import TruthActuator, from_name

        self.model = model
        base = NominalConfig()
        cfg = NominalConfig(num=model.num, den=model.den, rate_hz=rate_hz or base.rate_hz,
                            amp_filter_hz=base.amp_filter_hz)
        self.rate_hz = float(cfg.rate_hz)
        if not model.effects:
            self.inner = NominalActuator(cfg)
        elif model.fitted:
            self.inner = FittedChain({e.name: e.fit() for e in model.effects}, model.scales, cfg)
        else:
            self.inner = TruthActuator([from_name(e.name, **e.params) for e in model.effects], cfg)
        self.strain_curve = getattr(self.inner, "strain_curve", None)
        self._delay = _delay_stage(model.delay_s, 1.0 / self.rate_hz) if model.delay_s > 0 else None
        self.reset(0.0)

    def describe(self) -> str:
        """One line for logs."""
        return f"model file {self.model.source or '(in memory)'}: {self.model.describe()}"

    def reset(self, command_kv: float = 0.0) -> None:
        """At rest with ``command_kv`` (kV) applied forever."""
        self.inner.reset(command_kv)
        if self._delay is not None:  # the delay line holds the stroke at rest
            probe = copy.deepcopy(self.inner)
            self._delay.reset(float(probe.run(np.array([float(command_kv)])).stroke_mm[0]))

    def _out(self, s: ActuatorSamples) -> ActuatorSamples:
        if self._delay is None:
            return s
        return ActuatorSamples(applied_kv=s.applied_kv, stroke_mm=self._delay.run(s.stroke_mm))

    def run(self, command_kv: np.ndarray) -> ActuatorSamples:
        """Advance by the samples of ``command_kv`` (kV, at ``rate_hz``)."""
        return self._out(self.inner.run(np.asarray(command_kv, float)))

    def run_held(self, command_kv: float, n: int) -> ActuatorSamples:
        """Advance by ``n`` samples of one held command (kV): the inner model's fast path if it has one."""
        held = getattr(self.inner, "run_held", None)
        return self._out(held(command_kv, n) if held is not None else self.inner.run(np.full(n, float(command_kv))))


def build_actuator(model: PlantModel, rate_hz: float | None = None) -> FileActuator:
    """The actuator of ``model`` (see :class:`FileActuator`)."""
    return FileActuator(model, rate_hz)
