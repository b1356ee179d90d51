"""One simulated rig: an actuator model with its laser and strain sensor, stepped per loop tick.

The control loop runs at 200 Hz; the actuator is simulated at 10 kHz. Each call to
:meth:`PlantSimulator.step` holds one amplifier command over one loop period (50
samples), returns those samples and leaves the sensors' latest readings, which are
what the MCU reads at the next tick. The ROS plant node and the offline loop both
drive this class, with the same seed, so they produce identical samples.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from hasel import paper
from hasel.errors import BadInputError
from hasel.plant import Actuator, NominalActuator
from hasel.sensors import LaserConfig, LaserSensor, StrainConfig, StrainSensor
from hasel.validate import positive

__all__ = ["PlantBlock", "Readings", "PlantSimulator"]


@dataclass(frozen=True)
class PlantBlock:
    """Samples of one loop period. Sample i is at ``t0_s + (i + 1) * dt_s``."""

    t0_s: float
    dt_s: float
    command_kv: float
    applied_kv: np.ndarray
    true_stroke_mm: np.ndarray
    laser_mm: np.ndarray
    elapsed_us: np.ndarray

    @property
    def times_s(self) -> np.ndarray:
        """Sample times, seconds."""
        return self.t0_s + self.dt_s * np.arange(1, self.applied_kv.size + 1)


@dataclass(frozen=True)
class Readings:
    """What the MCU reads at a tick: laser stroke (mm), 555 elapsed time (us), applied kV."""

    t_s: float
    laser_mm: float
    elapsed_us: float
    applied_kv: float
    true_stroke_mm: float


class PlantSimulator:
    """An actuator model plus sensors, advanced one loop period at a time.

    Parameters
    ----------
    actuator : Actuator, optional
        The plant model (nominal P(s) by default; a truth plant with effects plugs in).
    period_s : float
        Loop period, seconds (0.005).
    seed : int
        Seed of the sensors' noise.
    laser, strain : LaserConfig, StrainConfig
        Sensor parameters.
    strain_curve : callable, optional
        Maps true stroke (mm) to the stroke the strain sensor responds to (a sensor
        nonlinearity); identity by default.
    """

    def __init__(self, actuator: Actuator | None = None, *, period_s: float = paper.LOOP_PERIOD_S,
                 seed: int = 0, laser: LaserConfig | None = None, strain: StrainConfig | None = None,
                 strain_curve=None) -> None:
        self.actuator = actuator or NominalActuator()
        self.period_s = positive("period_s", period_s)
        n = self.period_s * self.actuator.rate_hz
        if abs(n - round(n)) > 1e-6:
            raise BadInputError(f"the loop period ({period_s} s) must be a whole number of "
                                f"simulator samples (rate {self.actuator.rate_hz} Hz)")
        self.samples_per_period = int(round(n))
        self.dt_s = 1.0 / self.actuator.rate_hz
        self.rng = np.random.default_rng(seed)
        self.laser = LaserSensor(laser or LaserConfig(), self.rng)
        self.strain = StrainSensor(strain or StrainConfig(), self.actuator.rate_hz, self.rng)
        self.strain_curve = strain_curve
        self.actuator.reset(0.0)
        self.tick = 0
        z0 = 0.0
        self._latest = Readings(0.0, float(np.round(z0 / self.laser.lsb_mm) * self.laser.lsb_mm),
                                float(self.strain.ideal_us(z0)), 0.0, z0)

    @property
    def t_s(self) -> float:
        """Time of the current tick, seconds."""
        return self.tick * self.period_s

    def latest(self) -> Readings:
        """The sensors' readings at the current tick."""
        return self._latest

    def step(self, command_kv: float | np.ndarray) -> PlantBlock:
        """Apply one period of amplifier input (kV) and advance one tick.

        ``command_kv`` is either one value held for the period (closed loop) or
        ``samples_per_period`` values at the simulator's rate (open-loop waveforms).
        """
        n = self.samples_per_period
        cmd = np.asarray(command_kv, dtype=float)
        if cmd.ndim == 0:
            last = float(cmd)
            held = getattr(self.actuator, "run_held", None)  # one held value: the actuator's fast path
            out = held(last, n) if held is not None else self.actuator.run(np.full(n, last))
        elif cmd.shape != (n,):
            raise BadInputError(f"a period needs {n} command samples, got {cmd.shape}")
        else:
            last = float(cmd[-1])
            out = self.actuator.run(cmd)
        z = out.stroke_mm
        laser = self.laser.measure(z)
        z_sensor = z if self.strain_curve is None else self.strain_curve(z)
        elapsed = self.strain.measure(z_sensor, out.applied_kv)
        block = PlantBlock(self.t_s, self.dt_s, last, out.applied_kv, z, laser, elapsed)
        self.tick += 1
        self._latest = Readings(self.t_s, float(laser[-1]), float(elapsed[-1]),
                                float(out.applied_kv[-1]), float(z[-1]))
        return block
