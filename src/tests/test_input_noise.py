"""Measurement noise on the recorded voltage (errors in variables): counted in the floor, not named as an effect."""
from __future__ import annotations

import math

import numpy as np
import pytest

from hasel import paper
from hasel.diagnose import DiagnoseOptions, diagnose
from hasel.diagnose.inputnoise import input_noise
from hasel.diagnose.prep import LinearSim, estimate_noise

RATE = 200.0


def _prbs(rng: np.random.Generator, n: int, clock: int) -> np.ndarray:
    """Two-level PRBS, 2-4 kV, switching on a clock of ``clock`` samples (kV)."""
    return 3.0 + np.repeat(2.0 * rng.integers(0, 2, n // clock + 1) - 1.0, clock)[:n]


def _check(u_rec: np.ndarray, stroke: np.ndarray):
    num, den = paper.plant_tf()
    sim = LinearSim(num, den, RATE)
    imp = np.zeros(4097)
    imp[1] = 1.0
    r0 = stroke - sim.run(u_rec)
    return input_noise(u_rec, r0, sim.run(imp)[1:],
                       lambda s: estimate_noise(sim.run(s * np.random.default_rng(0).standard_normal(u_rec.size)),
                                                RATE, 20.0)[0])


@pytest.mark.parametrize("clock", [1, 4, 200])
def test_noise_on_the_recorded_voltage_is_found_and_its_share_is_one(clock):
    # the stroke is P(s) of the applied PRBS; the log records the voltage with 40 V rms of monitor noise
    rng = np.random.default_rng(clock)
    n = 10_000
    u = _prbs(rng, n, clock)
    num, den = paper.plant_tf()
    y = LinearSim(num, den, RATE).run(u) + 0.004 * rng.standard_normal(n)
    got = _check(u + 0.040 * rng.standard_normal(n), y)
    assert got.counted, got.reason
    assert got.sigma_u == pytest.approx(0.040, rel=0.1)
    assert got.share == pytest.approx(1.0, abs=0.2)
    # the propagated noise is what the residual holds beside the sensor's 4 um
    assert math.sqrt(got.residual_var) == pytest.approx(0.040 * math.sqrt(np.sum(
        LinearSim(num, den, RATE).run(np.r_[0.0, 1.0, np.zeros(4095)])[1:] ** 2)), rel=0.25)
    assert got.floor_add > 0.0


def test_noise_really_applied_is_not_counted():
    # the same noise, but in the voltage that drove the actuator (a dither): the stroke follows it, the
    # residual does not, so it is no measurement error
    rng = np.random.default_rng(7)
    n = 10_000
    u = _prbs(rng, n, 4) + 0.040 * rng.standard_normal(n)
    num, den = paper.plant_tf()
    got = _check(u, LinearSim(num, den, RATE).run(u) + 0.004 * rng.standard_normal(n))
    assert not got.counted
    assert got.floor_add == 0.0
    assert abs(got.share) < 0.3


def test_a_clean_chirp_has_nothing_to_count():
    t = np.arange(20_000) / RATE
    u = 4.0 + 2.0 * np.sin(2 * np.pi * (0.1 * t + 0.02 * t ** 2))
    num, den = paper.plant_tf()
    got = _check(u, LinearSim(num, den, RATE).run(u) + 0.004 * np.random.default_rng(3).standard_normal(t.size))
    assert not got.counted and got.floor_add == 0.0


def test_a_noisy_voltage_record_names_no_effect_but_says_why_the_floor_is_higher():
    # PRBS at 200 Hz, 37 V rms on the recorded voltage, exact model: a static map flattened on the two levels
    # removes part of the noise the simulation carries and passes a held-out test; counted as noise it is not named
    rng = np.random.default_rng(11)
    n = 9000
    u = _prbs(rng, n, 3)
    num, den = paper.plant_tf()
    y = LinearSim(num, den, RATE).run(u) + 0.005 * rng.standard_normal(n)
    t = np.arange(n) / RATE
    v = diagnose(t, u + 0.037 * rng.standard_normal(n), y, model={"num": list(num), "den": list(den)})
    inp = v.noise["input_noise"]
    assert inp["counted"] and inp["sigma_u"] == pytest.approx(0.037, rel=0.15)
    assert v.names == []
    # without the check the same log's floor is the sensor's alone
    off = diagnose(t, u + 0.037 * np.random.default_rng(11).standard_normal(n), y,
                   model={"num": list(num), "den": list(den)}, options=DiagnoseOptions(input_noise_check=False))
    assert v.noise_floor_nrmse > 1.3 * off.noise_floor_nrmse
