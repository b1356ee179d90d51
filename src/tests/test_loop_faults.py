"""hasel.loop with injected faults: what FAULTS.md promises, end to end on the simulated plant, without ROS."""
from __future__ import annotations

import math

import numpy as np

from hasel.amplifier import Reason
from hasel.loop import LoopConfig, LoopFaults, run_closed_loop, step_reference
from hasel.simulator import PlantSimulator


def tick(t_s: float) -> int:
    return int(round(t_s / 0.005))


def test_dropout_zero_kv_within_three_periods_and_control_resumes():
    res = run_closed_loop(PlantSimulator(seed=4), step_reference([4.0], 10.0), 1.2, LoopConfig(),
                          LoopFaults(feedback=lambda t, z: None if 120 <= tick(t) < 160 else z))
    assert np.all(res.reason[120:123] == -1)  # the DAC holds three periods
    assert res.command_kv[122] > 1.0
    assert np.all(res.reason[123:160] == Reason.WATCHDOG) and np.all(res.command_kv[123:160] == 0.0)
    assert res.stale[123:160].all() and not res.stale[165:].any()
    late = res.sample_t_s > 1.1
    assert np.max(np.abs(res.true_stroke_mm[late] - 4.0)) < 0.1  # tracking again


def test_stuck_sensor_ends_in_zero_kv():
    frozen = {}
    res = run_closed_loop(PlantSimulator(seed=4), step_reference([2.0, 5.0], 0.5), 1.0, LoopConfig(),
                          LoopFaults(feedback=lambda t, z: frozen.setdefault("z", z) if t >= 0.5 else z))
    assert res.stale[-1] and res.command_kv[-1] == 0.0 and res.reason[-1] == Reason.WATCHDOG
    assert res.applied_kv[-1] < 0.01


def test_nan_from_the_555_never_reaches_the_actuator_and_spikes_are_harmless():
    bad = {50, 51, 90, 130}
    res = run_closed_loop(PlantSimulator(seed=6), step_reference([3.0], 10.0), 1.0, LoopConfig(feedback="strain"),
                          LoopFaults(timing=lambda t, us: math.nan if tick(t) in bad else us))
    assert np.all(np.isnan(res.strain_mm[sorted(bad)])) and np.all(np.isfinite(res.command_kv))
    assert not res.stale.any()  # isolated bad readings: the last command held, never stale
    spikes = run_closed_loop(PlantSimulator(seed=6), step_reference([3.0], 10.0), 1.0, LoopConfig(),
                             LoopFaults(feedback=lambda t, z: z + 8.0 if tick(t) % 40 == 0 and t > 0.3 else z))
    late = spikes.sample_t_s > 0.8
    assert np.max(np.abs(spikes.true_stroke_mm[late] - 3.0)) < 0.05


def test_corrupted_requests_never_put_more_than_nine_kv_on_the_actuator():
    rng = np.random.default_rng(1)
    noise = rng.choice([0.0, 50.0, -50.0, math.nan, math.inf], size=400, p=[0.8, 0.05, 0.05, 0.05, 0.05])
    res = run_closed_loop(PlantSimulator(seed=1), step_reference([2.0, 7.0], 0.5), 1.5, LoopConfig(),
                          LoopFaults(command=lambda t, kv: kv + noise[tick(t) % 400]))
    assert res.applied_kv.max() <= 9.0 + 1e-9 and res.applied_kv.min() >= -1e-9
    assert (res.reason == Reason.CLAMP_HIGH).any() and (res.reason == Reason.NONFINITE).any()
