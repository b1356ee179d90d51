"""The closed-loop node graph against the offline loop, step metrics, safety, watchdog."""
from __future__ import annotations

import math

import numpy as np
import pytest

from hasel.loop import LoopConfig, run_closed_loop, step_reference
from hasel.simulator import PlantSimulator
from hasel_sysid.graph import GraphConfig, NodeGraph
from hasel_sysid.steps import run_steps


@pytest.mark.parametrize("feedback", ["laser", "strain"])
def test_graph_equals_offline_loop_sample_for_sample(feedback):
    seq, hold, dur = [2.0, 4.0, 6.0, 4.0, 2.0], 0.1, 0.5
    with NodeGraph(GraphConfig(feedback=feedback, sequence_mm=seq, hold_s=hold, seed=11)) as g:
        g.run(dur, wall_timeout_s=60)
        s = g.collector.samples()
        applied = np.array(g.collector.applied)
    ref = run_closed_loop(PlantSimulator(seed=11), step_reference(seq, hold), dur, LoopConfig(feedback=feedback))
    n = ref.command_kv.size
    assert applied.shape[0] >= n
    # the ROS plumbing adds no error: identical commands and samples
    np.testing.assert_allclose(applied[:n, 2], ref.command_kv, rtol=0, atol=1e-12)
    np.testing.assert_allclose(applied[:n, 0], ref.t_s, rtol=0, atol=1e-9)
    np.testing.assert_allclose(s["true_stroke_mm"], ref.true_stroke_mm, rtol=0, atol=1e-12)
    np.testing.assert_allclose(s["elapsed_us"], ref.elapsed_us, rtol=0, atol=1e-12)
    np.testing.assert_allclose(s["t_s"], ref.sample_t_s, rtol=0, atol=1e-9)


def _clock_subscriptions(g: NodeGraph) -> int:
    return sum(s.topic_name == "/clock" for n in g.nodes for s in n.subscriptions)


def test_one_clock_subscription_drives_every_nodes_simulated_clock():
    with NodeGraph(GraphConfig(sequence_mm=[2.0], hold_s=1.0, seed=3)) as g:
        assert _clock_subscriptions(g) == 1
        g.run(0.2, wall_timeout_s=60)
        now_ns = g.plant.tick_stamp_ns()
        assert now_ns == 200_000_000
        for n in g.nodes:  # still on simulated time, each at the plant's last tick
            assert n.get_parameter("use_sim_time").value is True
            assert n.get_clock().now().nanoseconds == now_ns, n.get_name()
    with NodeGraph(GraphConfig(sequence_mm=[2.0], hold_s=1.0, seed=3, shared_clock=False)) as g:
        assert _clock_subscriptions(g) == len(g.nodes)  # rclpy's default: one per node


@pytest.mark.parametrize("feedback", ["laser", "strain"])
def test_steps_give_finite_metrics_for_all_four_steps(feedback):
    res = run_steps(feedback, [2.0, 4.0, 6.0, 4.0, 2.0], 0.5, quiet=True)
    assert [s["mode"] for s in res["steps"]] == ["activation", "activation", "relaxation", "relaxation"]
    for s in res["steps"]:
        assert all(s[k] is not None and math.isfinite(s[k]) for k in ("rise_s", "settling_s", "overshoot_pct"))
        assert 0.01 < s["rise_s"] < 0.2 and s["settling_s"] < 0.5
    assert 0.0 <= res["min_applied_kv"] and res["max_applied_kv"] <= 9.0


def test_unreachable_reference_saturates_at_nine_kv_and_never_above():
    res = run_steps("laser", [2.0, 15.0], 0.5, quiet=True)
    assert res["max_applied_kv"] == pytest.approx(9.0, abs=1e-9)
    s = res["_signals"]
    assert np.all(s["voltage_kv"] <= 9.0 + 1e-9)
    assert np.all(res["_signals"]["applied_tick"][:, 2] <= 9.0)


def test_watchdog_drives_zero_kv_within_three_periods_when_controller_stops():
    with NodeGraph(GraphConfig(feedback="laser", sequence_mm=[5.0], hold_s=10.0, seed=1,
                               plant_params={"lockstep_timeout_s": 0.02})) as g:
        g.run(0.3, wall_timeout_s=60)
        assert g.collector.applied[-1][2] > 1.0  # holding 5 mm takes a few kV
        g.executor.remove_node(g.controller)
        g.controller.destroy_node()
        g.nodes.remove(g.controller)
        t_stop = g.plant.now_s()
        g.plant.stop_at_s, g.plant.done = t_stop + 0.05, False
        while not g.plant.done:
            g.executor.spin_once(timeout_sec=0.05)
        for _ in range(10):
            g.executor.spin_once(timeout_sec=0.001)
        after = [(t, kv, reason) for t, _, kv, reason in g.collector.applied if t > t_stop - 1e-9]
    zero = [t for t, kv, reason in after if kv == 0.0 and reason == 4]  # REASON_WATCHDOG
    assert zero, after
    assert zero[0] - t_stop <= 3 * 0.005 + 0.005 + 1e-9  # stale after 3 periods, acted at the next tick
    # the actuator's voltage decays to zero once the watchdog acts
    assert all(kv == 0.0 for t, kv, _ in after if t >= zero[0])


def test_laser_loop_matches_an_independent_python_control_model():
    """The paper's loop on P(s), built independently with python-control (discrete C+
    by the paper's rules, ZOH plant, no amplifier filter, no noise), against the graph."""
    import control as ct
    from scipy import signal

    from hasel import paper
    from hasel.metrics import step_metrics

    num, den = paper.plant_tf()
    ts = 0.005
    kp, ki, kd = paper.C_PLUS
    c = ct.tf([kp], [1], ts) + ct.tf([ki * ts / 2, ki * ts / 2], [1, -1], ts) + ct.tf([kd / ts, -kd / ts], [1, 0], ts)
    pd = ct.c2d(ct.tf(num, den), ts, "zoh")
    t = np.arange(0, 1, ts)
    u = ct.step_response(ct.feedback(c, pd), t)[1]
    tf = np.arange(0, 1, 1e-4)
    _, y, _ = signal.lsim((num, den), 2 * np.repeat(u, 50)[:tf.size], tf, interp=False)
    ref = step_metrics(tf, 2 + y, 0.0, 1.0, 2.0, 4.0)
    ours = run_steps("laser", [2.0, 4.0], 1.0, quiet=True)["steps"][0]
    assert ours["rise_s"] == pytest.approx(ref.rise_s, rel=0.05)
    assert ours["settling_s"] == pytest.approx(ref.settling_s, rel=0.1)
    assert ours["overshoot_pct"] == pytest.approx(ref.overshoot_pct, abs=1.5)


def test_calibration_through_the_graph_recovers_the_sensor_line():
    from hasel.loop import default_calibration
    from hasel_sysid.calibrate import calibrate

    fit = calibrate([2.0, 3.0, 4.0, 5.0, 6.0, 7.0], 0.4, quiet=True)
    ideal = default_calibration()  # the simulated sensor's true line: 0.4 mm/us, -40 mm
    assert fit.calibration.slope_mm_per_us == pytest.approx(ideal.slope_mm_per_us, rel=2e-3)
    assert fit.calibration.offset_mm == pytest.approx(ideal.offset_mm, abs=0.1)
    assert fit.max_error_pct < 0.5
    np.testing.assert_allclose(fit.laser_mm, [2, 3, 4, 5, 6, 7], atol=0.02)  # the loop held each point
