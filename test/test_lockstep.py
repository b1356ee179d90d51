"""The plant's lockstep guard: it steps on its own when the amplifier is silent, but a stall
of its own process is not silence (real rclpy; the plant alone, no amplifier)."""
from __future__ import annotations

import time

import pytest
import rclpy
from rclpy.executors import SingleThreadedExecutor
from rclpy.parameter import Parameter

from sim_plant.plant_node import PlantNode

pytestmark = pytest.mark.wallclock  # asserts on wall-clock timing: run alone (Makefile)


def spin_until(ex, cond, timeout_s: float) -> None:
    end = time.monotonic() + timeout_s
    while not cond():
        assert time.monotonic() < end, "timed out"
        ex.spin_once(timeout_sec=0.005)


def test_a_silent_amplifier_is_stepped_over_but_a_stall_of_the_plant_is_not():
    ctx = rclpy.Context()
    rclpy.init(context=ctx)
    try:
        plant = PlantNode(context=ctx, parameter_overrides=[Parameter("lockstep_timeout_s", value=0.02),
                                                            Parameter("autostart", value=False)])
        ex = SingleThreadedExecutor(context=ctx)
        ex.add_node(plant)
        plant.start()
        # nobody answers: the plant steps anyway, about every 0.02 s of wall time
        spin_until(ex, lambda: plant.sim.tick >= 3, 10.0)
        tick = plant.sim.tick
        time.sleep(0.3)  # the process stalls for 15 timeouts (as under a loaded machine)
        plant.on_lockstep_watch()  # the first call after the stall: a queued answer would come next
        assert plant.sim.tick == tick
        t0 = time.monotonic()
        spin_until(ex, lambda: plant.sim.tick > tick, 10.0)
        # the silence the watch itself sees still counts: one more step, a timeout later at most
        assert plant.sim.tick == tick + 1 and time.monotonic() - t0 < 0.02 + 0.2
        plant.destroy_node()
    finally:
        rclpy.try_shutdown(context=ctx)
