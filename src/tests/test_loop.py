"""hasel.loop and hasel.simulator: the offline closed loop on the nominal plant."""
from __future__ import annotations

import math

import numpy as np
import pytest

from hasel.calibration import fit_calibration
from hasel.loop import LoopConfig, default_calibration, run_closed_loop, step_reference
from hasel.metrics import steps_from_sequence
from hasel.simulator import PlantSimulator


@pytest.mark.parametrize("feedback", ["laser", "strain"])
def test_paper_step_sequence_tracks_with_finite_metrics(feedback):
    seq = [2.0, 4.0, 6.0, 4.0, 2.0]
    res = run_closed_loop(PlantSimulator(seed=2), step_reference(seq, 1.0), 5.0, LoopConfig(feedback=feedback))
    steps = steps_from_sequence(res.sample_t_s, res.true_stroke_mm, seq, 1.0)
    assert [s.mode for s in steps] == ["activation", "activation", "relaxation", "relaxation"]
    for s in steps:
        assert all(math.isfinite(v) for v in (s.rise_s, s.settling_s, s.overshoot_pct))
        assert 0.005 < s.rise_s < 0.3
    # integral action removes the steady-state error at the end of each hold
    for i, r in enumerate(seq):
        sel = (res.sample_t_s > i + 0.8) & (res.sample_t_s <= i + 1.0)
        assert np.mean(res.true_stroke_mm[sel]) == pytest.approx(r, abs=0.05)
    assert res.applied_kv.max() <= 9.0 and res.command_kv.min() >= 0.0


def test_same_seed_same_samples_and_different_seed_differs():
    a = run_closed_loop(PlantSimulator(seed=5), step_reference([2, 4], 0.2), 0.4, LoopConfig(feedback="strain"))
    b = run_closed_loop(PlantSimulator(seed=5), step_reference([2, 4], 0.2), 0.4, LoopConfig(feedback="strain"))
    c = run_closed_loop(PlantSimulator(seed=6), step_reference([2, 4], 0.2), 0.4, LoopConfig(feedback="strain"))
    np.testing.assert_array_equal(a.command_kv, b.command_kv)
    assert not np.array_equal(a.elapsed_us, c.elapsed_us)


def test_unreachable_reference_saturates_at_nine_kv():
    res = run_closed_loop(PlantSimulator(seed=1), step_reference([2.0, 12.0], 0.5), 2.0)
    assert res.command_kv.max() == 9.0
    assert res.applied_kv.max() <= 9.0 + 1e-9


def test_ideal_calibration_inverts_the_sensor():
    sim = PlantSimulator(seed=0)
    cal = default_calibration(sim.strain.config)
    z = np.linspace(0, 8, 9)
    np.testing.assert_allclose(cal(sim.strain.ideal_us(z)), z, atol=1e-12)
    fit = fit_calibration(sim.strain.ideal_us(z), z)
    np.testing.assert_allclose(fit.calibration.coeffs, cal.coeffs, rtol=1e-9)


def test_applied_voltage_never_leaves_command_range_for_random_commands():
    from hasel.plant import NominalActuator

    act = NominalActuator()
    act.reset(0.0)
    rng = np.random.default_rng(7)
    cmd = np.repeat(rng.choice([0.0, 9.0], size=400), rng.integers(1, 60, size=400).clip(1))[:20000]
    out = act.run(cmd)
    assert out.applied_kv.max() <= 9.0 + 1e-9 and out.applied_kv.min() >= -1e-9
