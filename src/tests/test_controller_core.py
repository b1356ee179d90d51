"""hasel.controller: every controller decision of FAULTS.md, without ROS (times in ns)."""
from __future__ import annotations

import math

import numpy as np
import pytest

from hasel.controller import ControllerCore, ReferenceSchedule
from hasel.faults import ERROR, OK
from hasel.pid import DualModePid

TICK = 5_000_000  # one 200 Hz period, ns


def settled(ref_mm: float = 4.0, z_mm: float = 3.9, ticks: int = 50) -> ControllerCore:
    """A core that has tracked ``ref_mm`` with feedback around ``z_mm`` for ``ticks`` ticks."""
    core = ControllerCore()
    core.references.set(0, ref_mm)
    for k in range(ticks):
        core.on_sample(k * TICK, z_mm + 0.001 * (k % 3))
    return core


def test_reference_schedule_takes_effect_at_its_stamp_and_a_later_value_replaces():
    s = ReferenceSchedule()
    s.set(100 * TICK, 4.0)
    s.set(0, 2.0)
    s.set(100 * TICK, 6.0)  # same time: replaces
    assert len(s) == 2
    assert math.isnan(s.at(-1))
    assert s.at(100 * TICK - 1) == 2.0 and s.at(100 * TICK) == 6.0 and s(0.5) == 6.0


def test_no_reference_yet_commands_zero_and_is_alive():
    step = ControllerCore().on_sample(0, 3.0)
    assert step.command_kv == 0.0 and step.fresh and step.pid is None


def test_mode_switches_between_c_plus_and_c_minus_with_the_sign_of_the_error():
    core = ControllerCore()
    core.references.set(0, 4.0)
    assert core.on_sample(0, 3.0).pid.mode == 1  # e = +1 mm: activation, C+
    assert core.on_sample(TICK, 3.5).pid.mode == 1
    out = core.on_sample(2 * TICK, 4.5).pid  # e = -0.5 mm: relaxation, C-
    assert out.mode == -1
    kp_minus = core.pid.config.minus.kp
    assert out.p_kv == pytest.approx(kp_minus * -0.5, rel=1e-12)


def test_single_sample_spike_is_rejected_counted_and_holds_the_last_command():
    core = settled()
    last = core.last_output_kv
    i_before = core.pid.i_kv
    step = core.on_sample(50 * TICK, 3.9 + 8.0)  # +8 mm in 5 ms: impossible for the actuator
    assert step.command_kv == last and step.pid is None and not step.fresh
    assert core.rejected == 1 and core.pid.i_kv == i_before
    assert core.on_sample(51 * TICK, 3.9).fresh  # the next good sample is used


@pytest.mark.parametrize("bad", [math.nan, math.inf, -math.inf, 40.0, -7.0])
def test_non_finite_and_out_of_range_samples_are_rejected(bad):
    core = settled()
    step = core.on_sample(50 * TICK, bad)
    assert step.command_kv == core.last_output_kv and not step.fresh and core.rejected == 1


def test_dropout_goes_stale_after_three_periods_holds_and_resumes_without_a_derivative_kick():
    core = settled()  # last sample at tick 49
    i_held = core.pid.i_kv
    assert core.poll(52 * TICK) is None  # three periods old: not yet stale
    notice = core.poll(53 * TICK)  # older than three periods
    assert notice.level == ERROR and "stale" in notice.message and core.stale
    assert notice.values["integrator_kv"] == i_held
    assert core.poll(54 * TICK) is None  # reported once
    # a rejected sample while stale sends nothing
    assert core.on_sample(60 * TICK, math.nan).command_kv is None
    step = core.on_sample(61 * TICK, 3.95)
    assert [n.level for n in step.notices] == [OK] and not core.stale
    assert step.pid.d_kv == 0.0  # no derivative kick
    assert step.pid.i_kv != i_held or step.pid.error_mm == 0.0  # integrating again from the held value
    assert step.command_kv == step.pid.output_kv


def test_rejected_samples_are_not_fresh_so_four_periods_of_them_are_stale():
    core = settled()
    held = [core.on_sample(k * TICK, math.nan).command_kv for k in (50, 51, 52)]
    assert held == [core.last_output_kv] * 3
    step = core.on_sample(53 * TICK, math.nan)  # the stale check at the sample's own time comes first
    assert step.command_kv is None and core.stale and [n.level for n in step.notices] == [ERROR]


def test_stuck_sensor_latches_until_the_value_changes():
    core = ControllerCore()
    core.references.set(0, 2.0)
    for k in range(30):
        core.on_sample(k * TICK, 2.0 + 0.01 * math.sin(k))
    core.references.set(30 * TICK, 6.0)  # the command climbs while the sensor is frozen at 1.99
    steps = [core.on_sample(k * TICK, 1.99) for k in range(30, 80)]
    stuck_at = next(i for i, s in enumerate(steps) if s.notices)
    assert steps[stuck_at].notices[0].level == ERROR and "stuck" in steps[stuck_at].notices[0].message
    assert steps[stuck_at].command_kv is None and core.stale
    assert all(s.command_kv is None for s in steps[stuck_at:])  # 0 kV follows from the watchdog
    # the value moves again: the fault clears and control resumes without a kick
    back = core.on_sample(80 * TICK, 2.05)
    assert [n.level for n in back.notices] == [OK] and back.pid.d_kv == 0.0 and back.command_kv > 0.0


def test_unreachable_reference_saturates_at_nine_kv_without_winding_up():
    core = ControllerCore()
    core.references.set(0, 15.0)
    outs = [core.on_sample(k * TICK, 2.0 + 0.001 * k).pid for k in range(400)]
    assert max(o.output_kv for o in outs) == 9.0 and all(0.0 <= o.output_kv <= 9.0 for o in outs)
    assert outs[-1].i_kv == pytest.approx(outs[100].i_kv, abs=1e-9)  # conditional integration held it


def test_commands_always_none_or_within_zero_to_nine_kv_for_random_sample_streams():
    rng = np.random.default_rng(3)
    for _ in range(40):
        core = ControllerCore(DualModePid())
        t = 0
        for _ in range(200):
            kind = rng.integers(6)
            if kind == 0:
                core.references.set(t, float(rng.uniform(-5, 20)))
            z = [math.nan, math.inf, float(rng.normal(3, 10)), 3.0, float(rng.uniform(0, 8)), 1e12][kind]
            t += int(rng.choice([TICK, 0, 3 * TICK, 7 * TICK, -2 * TICK]))  # repeats, gaps, clock jumps
            cmd = core.on_sample(t, z).command_kv
            assert cmd is None or 0.0 <= cmd <= 9.0
