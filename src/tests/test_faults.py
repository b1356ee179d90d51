"""hasel.faults: spike gate and stuck-sensor detection."""
from __future__ import annotations

import math

import numpy as np

from hasel.faults import PlausibilityGate, StuckDetector


def test_single_spikes_rejected_and_counted():
    g = PlausibilityGate()
    z = [2.0, 2.01, 9.0, 2.02, math.nan, 2.03, -7.0, 2.04, 40.0]
    assert [g.accept(x) for x in z] == [True, True, False, True, False, True, False, True, False]
    assert g.rejected == 4


def test_a_real_jump_is_accepted_after_a_few_samples():
    g = PlausibilityGate(max_step_mm=1.0, reanchor_after=3)
    g.accept(2.0)
    out = [g.accept(6.0) for _ in range(5)]
    assert out == [False, False, False, True, True]


def test_smooth_fast_motion_passes():
    g = PlausibilityGate()
    t = np.arange(0, 1, 0.005)
    z = 4 + 2 * np.sin(2 * np.pi * 5 * t)  # 63 mm/s peak: 0.31 mm per tick
    assert all(g.accept(float(x)) for x in z) and g.rejected == 0


def test_stuck_sensor_detected_only_when_command_moves():
    d = StuckDetector(window=10, min_command_change_kv=0.5)
    assert not any(d.update(3.0, 2.0) for _ in range(20))  # steady state: not stuck
    flags = [d.update(3.0, 2.0 + 0.1 * k) for k in range(10)]
    assert flags[-1]
    d.reset()
    assert not any(d.update(3.0 + 0.001 * k, 2.0 + 0.1 * k) for k in range(20))
