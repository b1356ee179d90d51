"""Sensor models: the laser displacement sensor and the capacitive strain sensor with its LMC555.

Laser (ground truth): 3 mm/V analog output read by a 12-bit ADC over 0-3.3 V, so the
stroke is quantised in steps of 3.3*3/4096 = 2.4 um, plus a small vibration noise.

Strain sensor: capacitance proportional to stretch, C = lambda C0 (paper eq. 13), with
the stretch growing linearly with stroke. An LMC555 in monostable mode, triggered at
4.5 kHz, turns C into a pulse of width 1.1 R C; the MCU times it with edge interrupts
(the "elapsed time", microseconds), so a reading exists every 1/4.5 kHz and the MCU
reports the latest one. Because the sensor sits in the actuator's field, its noise
grows with the applied voltage (paper section V.B); the timer's clock quantises it.
"""
from __future__ import annotations

from dataclasses import dataclass

import math
from fractions import Fraction

import numpy as np

from hasel import paper
from hasel.validate import positive

__all__ = ["LaserConfig", "LaserSensor", "StrainConfig", "StrainSensor"]


@dataclass(frozen=True)
class LaserConfig:
    """Laser displacement sensor and its ADC.

    Attributes: ``mm_per_v`` output scale (mm/V); ``adc_bits``; ``full_scale_v`` ADC
    range (V); ``noise_mm`` standard deviation of vibration noise (mm).
    """

    mm_per_v: float = paper.LASER_MM_PER_V
    adc_bits: int = paper.ADC_BITS
    full_scale_v: float = paper.ADC_FULL_SCALE_V
    noise_mm: float = 0.003


class LaserSensor:
    """Stroke (mm) -> laser reading (mm) as the 12-bit ADC sees it."""

    def __init__(self, config: LaserConfig, rng: np.random.Generator) -> None:
        self.config = config
        self.rng = rng
        self.lsb_mm = config.full_scale_v * config.mm_per_v / (2**config.adc_bits)
        self.max_code = 2**config.adc_bits - 1

    def measure(self, stroke_mm: np.ndarray) -> np.ndarray:
        """Quantised, noisy readings (mm) of the true strokes ``stroke_mm`` (mm)."""
        w = self.rng.standard_normal(np.size(stroke_mm))
        w *= self.config.noise_mm
        w += stroke_mm
        w /= self.lsb_mm
        np.rint(w, out=w)  # the ADC's code (rint rounds half to even, as np.round does)
        np.maximum(w, 0.0, out=w)  # clip to the ADC's codes (two ufuncs: cheaper than np.clip here)
        np.minimum(w, self.max_code, out=w)
        w *= self.lsb_mm
        return w


@dataclass(frozen=True)
class StrainConfig:
    """Capacitive strain sensor and LMC555 read-out.

    Attributes
    ----------
    rest_pulse_us : float
        Pulse width 1.1 R C0 at zero stroke, us.
    stretch_per_mm : float
        Sensor stretch per mm of stroke (lambda = 1 + stretch_per_mm * z).
    trigger_hz : float
        555 trigger rate, Hz (4.5 kHz).
    tick_us : float
        Resolution of the MCU's edge timer, us.
    noise_us : float
        Noise of a reading at 0 kV, us (standard deviation).
    noise_us_per_kv : float
        Extra noise per kV applied (field coupling into the sensor), us/kV.
    """

    rest_pulse_us: float = 100.0
    stretch_per_mm: float = 0.025
    trigger_hz: float = paper.TIMER_TRIGGER_HZ
    tick_us: float = 1.0 / 60.0
    noise_us: float = 0.01
    noise_us_per_kv: float = 0.012

    @property
    def us_per_mm(self) -> float:
        """Ideal sensitivity of the reading, us per mm."""
        return self.rest_pulse_us * self.stretch_per_mm


class StrainSensor:
    """True stroke (mm) and applied voltage (kV) at the simulator's rate -> 555 elapsed times (us).

    Readings are taken at the trigger instants (4.5 kHz) and held until the next one,
    so the output at each simulator sample is the latest reading the MCU has.
    """

    def __init__(self, config: StrainConfig, rate_hz: float, rng: np.random.Generator) -> None:
        self.config = config
        self.rng = rng
        self.dt = 1.0 / positive("rate_hz", rate_hz)
        self.trigger_period = 1.0 / positive("trigger_hz", config.trigger_hz)
        self._t = 0.0          # time of the next simulator sample, s
        self._next_trigger = 0.0
        self._last_us = config.rest_pulse_us
        self._ramps: dict[tuple[int, float], np.ndarray] = {}
        self._pattern = self._landing_pattern(rate_hz, config.trigger_hz)
        self._i = 0  # index of the next simulator sample (exact, for the periodic pattern)
        self._blocks: dict[tuple[int, int], tuple[np.ndarray, np.ndarray]] = {}

    def ideal_us(self, stroke_mm: np.ndarray) -> np.ndarray:
        """Noise-free pulse width (us) for strokes in mm: 1.1 R C0 (1 + k z)."""
        c = self.config
        return c.rest_pulse_us * (1.0 + c.stretch_per_mm * np.asarray(stroke_mm, float))

    @staticmethod
    def _landing_pattern(rate_hz: float, trigger_hz: float) -> tuple[int, np.ndarray] | None:
        """Where triggers land when the rates are in a small whole ratio (10 kHz / 4.5 kHz = 20/9).

        Trigger j is read at the first sample at or after j / trigger_hz, sample
        ceil(j * rate / trigger). With rate / trigger = p / q that index is
        (j // q) * p + land[j % q]: the pattern repeats every q triggers and p samples,
        exactly, for as long as the simulation runs. Returns (p, land) or None
        (no small ratio: the general path computes trigger times instead).
        """
        ratio = Fraction(rate_hz / trigger_hz).limit_denominator(1000)
        if ratio <= 0 or abs(float(ratio) - rate_hz / trigger_hz) > 1e-12 * (rate_hz / trigger_hz):
            return None
        p, q = ratio.numerator, ratio.denominator
        land = np.array([math.ceil(j * p / q - 1e-9) for j in range(q)])
        return p, land

    def _block(self, i0: int, n: int) -> tuple[np.ndarray, np.ndarray]:
        """For samples [i0, i0 + n): the sample (from i0) of each trigger, and the samples each reading holds."""
        p, land = self._pattern
        key = (i0 % p, n)
        hit = self._blocks.get(key)
        if hit is None:
            r = key[0]
            cycles = -(-(r + n) // p) + 1
            at = (np.arange(cycles)[:, None] * p + land[None, :]).ravel()  # from the pattern's start before i0
            idx = at[(at >= r) & (at < r + n)] - r
            counts = np.diff(idx, append=n)
            hit = self._blocks[key] = (idx, counts)
        return hit

    def measure(self, stroke_mm: np.ndarray, applied_kv: np.ndarray) -> np.ndarray:
        """Latest elapsed time (us) at each simulator sample of ``stroke_mm``/``applied_kv``."""
        z = np.asarray(stroke_mm, float)
        v = np.asarray(applied_kv, float)
        n = z.size
        if n == 0:
            return np.empty(0)
        if self._pattern is not None:  # the trigger samples from the periodic pattern
            idx, counts = self._block(self._i, n)
            self._i += n
            return self._hold_readings(z, v, idx, counts)
        t = self._t + self._ramp(n, self.dt)
        self._t = float(t[-1] + self.dt)
        # trigger instants inside this block and the sample index where each lands
        k = max(0, math.floor((float(t[-1]) - self._next_trigger) / self.trigger_period + 1e-9) + 1)
        if not k:
            return np.full(n, self._last_us)
        trig = self._next_trigger + self._ramp(k, self.trigger_period)
        self._next_trigger = float(trig[-1] + self.trigger_period)
        idx = np.minimum(np.searchsorted(t, trig - 1e-12), n - 1)
        return self._hold_readings(z, v, idx, np.diff(idx, append=n))

    def _hold_readings(self, z: np.ndarray, v: np.ndarray, idx: np.ndarray, counts: np.ndarray) -> np.ndarray:
        """Readings taken at the samples ``idx`` of the block, each held for ``counts`` samples (us)."""
        n = z.size
        if not idx.size:
            return np.full(n, self._last_us)
        c = self.config
        sigma = np.abs(v[idx])
        sigma *= c.noise_us_per_kv
        sigma += c.noise_us
        reading = c.rest_pulse_us * (1.0 + c.stretch_per_mm * z[idx]) + sigma * self.rng.standard_normal(idx.size)
        reading /= c.tick_us
        np.rint(reading, out=reading)  # whole ticks of the MCU's timer
        reading *= c.tick_us
        # hold each reading from its sample until the next reading (a later one on the
        # same sample wins: it has a count of 0)
        out = np.empty(n)
        first = int(idx[0])
        out[:first] = self._last_us
        out[first:] = np.repeat(reading, counts)
        self._last_us = float(reading[-1])
        return out

    def _ramp(self, n: int, step: float) -> np.ndarray:
        """``step * arange(n)``, cached (the simulator asks for the same few sizes every period)."""
        key = (n, step)
        r = self._ramps.get(key)
        if r is None:
            r = self._ramps[key] = step * np.arange(n)
            r.flags.writeable = False
        return r
