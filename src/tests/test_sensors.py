"""The simulated sensors: the 555 strain read-out (sampling, hold, noise) and the laser's ADC."""
from __future__ import annotations

import math

import numpy as np
import pytest

from hasel.sensors import LaserConfig, LaserSensor, StrainConfig, StrainSensor

RATE_HZ = 10_000.0


def _sensor(seed: int = 0, **kw) -> StrainSensor:
    return StrainSensor(StrainConfig(**kw), RATE_HZ, np.random.default_rng(seed))


@pytest.mark.parametrize("trigger_hz", [4500.0, 4321.987])
def test_readings_are_taken_at_4_5_khz_and_held_until_the_next(trigger_hz):
    # a ramp of stroke, no noise: each reading is the ideal pulse width of the stroke at
    # the first simulator sample at or after its trigger instant j / 4500 s. 10 kHz and
    # 4.5 kHz are in the ratio 20/9 (a repeating pattern of samples); 4321.987 Hz is not
    # (trigger times are computed instead): both must follow the definition.
    n = 10_000
    z = np.linspace(0.0, 9.0, n)
    c = StrainConfig(noise_us=0.0, noise_us_per_kv=0.0, tick_us=1e-9,  # fine timer: every reading differs
                     trigger_hz=trigger_hz)
    sensor = StrainSensor(c, RATE_HZ, np.random.default_rng(0))
    assert (sensor._pattern is not None) == (trigger_hz == 4500.0)
    out = np.concatenate([sensor.measure(z[a:a + 50], np.zeros(50)) for a in range(0, n, 50)])  # 200 Hz blocks
    last = int(n * c.trigger_hz / RATE_HZ) + 2
    trig_idx = np.array([math.ceil(j * RATE_HZ / c.trigger_hz - 1e-9) for j in range(last)])
    trig_idx = trig_idx[trig_idx < n]
    changes = np.flatnonzero(np.diff(out)) + 1
    assert np.array_equal(changes, trig_idx[1:])  # a new value exactly where a trigger lands
    ideal = c.rest_pulse_us * (1.0 + c.stretch_per_mm * z[trig_idx])
    np.testing.assert_allclose(out[trig_idx], ideal, rtol=0, atol=c.tick_us / 2 + 1e-12)  # timer resolution
    # the MCU's timer resolution: readings are whole ticks
    coarse = _sensor(noise_us=0.0, noise_us_per_kv=0.0).measure(z, np.zeros(n))
    ticks = coarse / StrainConfig().tick_us
    np.testing.assert_allclose(ticks, np.round(ticks), rtol=0, atol=1e-6)


def test_blocks_of_any_size_give_the_same_readings_as_one_block():
    n = 3000
    rng = np.random.default_rng(4)
    z, v = rng.uniform(0, 8, n), rng.uniform(0, 8, n)
    whole = _sensor(seed=9).measure(z, v)
    s = _sensor(seed=9)
    cuts = [0, 1, 50, 51, 173, 1000, 2999, n]
    parts = [s.measure(z[a:b], v[a:b]) for a, b in zip(cuts, cuts[1:])]
    np.testing.assert_array_equal(np.concatenate(parts), whole)
    assert s.measure(np.empty(0), np.empty(0)).size == 0


@pytest.mark.parametrize("kv", [0.0, 8.0])
def test_reading_noise_grows_with_the_applied_voltage(kv):
    c = StrainConfig(noise_us=0.1, noise_us_per_kv=0.05)
    n = 200_000
    out = _sensor(seed=1, noise_us=c.noise_us, noise_us_per_kv=c.noise_us_per_kv).measure(np.zeros(n), np.full(n, kv))
    readings = out[np.flatnonzero(np.diff(out, prepend=np.nan))]  # one value per reading (ties are rare)
    want = c.noise_us + c.noise_us_per_kv * kv
    assert np.std(readings) == pytest.approx(math.sqrt(want**2 + c.tick_us**2 / 12), rel=0.05)
    assert np.mean(readings) == pytest.approx(c.rest_pulse_us, abs=4 * want / math.sqrt(readings.size) + 1e-3)


def test_laser_quantises_to_the_adc_and_clips_at_full_scale():
    c = LaserConfig(noise_mm=0.0)
    laser = LaserSensor(c, np.random.default_rng(0))
    z = np.array([-1.0, 0.0, 1.234567, 5.0, 100.0])
    out = laser.measure(z)
    lsb = c.full_scale_v * c.mm_per_v / 2**c.adc_bits
    assert laser.lsb_mm == pytest.approx(lsb)
    assert out[0] == 0.0 and out[-1] == pytest.approx((2**c.adc_bits - 1) * lsb)
    np.testing.assert_allclose(out[1:4], np.round(z[1:4] / lsb) * lsb, rtol=0, atol=1e-12)
