"""The node graph against the offline loop on fault paths, sample for sample.

Faults are injected into real messages by a relay node between two nodes of the graph
(the 555 reading before the driver, the feedback before the controller, the request
between controller and amplifier); :func:`hasel.loop.run_closed_loop` gets the same
rules through :class:`hasel.loop.LoopFaults`. Both run the same core objects, so the
plant must see the same voltage at every 10 kHz sample, and the amplifier's first output
of each tick (kV and reason) and the controller's stale/ok transitions must agree.

Gaps of exactly three periods are avoided on purpose: there a watchdog's timer and the
tick's first message fall on the same instant and the executor's order decides.
"""
from __future__ import annotations

import math
import time

import numpy as np
from rclpy.parameter import Parameter

from hasel.amplifier import Reason
from hasel.loop import LoopConfig, LoopFaults, run_closed_loop, step_reference
from hasel.simulator import PlantSimulator
from hasel_control.controller_node import PidControllerNode
from hasel_driver.driver_node import StrainDriverNode
from hasel_driver.filter_node import LowPassNode
from hasel_msgs.msg import SensorTiming, Stroke, VoltageCommand
from hasel_ros.rosutil import from_stamp, topic_qos
from hasel_sysid.graph import GraphConfig, NodeGraph

PERIOD_S = 0.005
SIM = [Parameter("use_sim_time", value=True)]


def tick(t_s: float) -> int:
    """Loop tick of a time in s."""
    return int(round(t_s / PERIOD_S))


def relay(ctx, name, msg_type, src, dst, field, rule, qos_of):
    """A node that republishes ``src`` on ``dst`` with ``field`` passed through ``rule(t_s, value)``
    (None: the message is dropped)."""
    from rclpy.node import Node

    node = Node(name, context=ctx, parameter_overrides=SIM)
    pub = node.create_publisher(msg_type, dst, topic_qos(qos_of))

    def on_msg(msg) -> None:
        value = rule(from_stamp(msg.header.stamp), getattr(msg, field))
        if value is not None:
            setattr(msg, field, value)
            pub.publish(msg)

    node.create_subscription(msg_type, src, on_msg, topic_qos(qos_of))
    node.relay_pub = pub
    return node


def run_graph(feedback, faults: LoopFaults, seq, hold, dur, seed, amp_params=None):
    """The graph with the controller (and, for 555 faults, a driver and filter) behind relays."""
    made = {}
    fb_topic = "/laser/stroke" if feedback == "laser" else "/strain/stroke_filtered"
    remap = []
    extra = []
    if faults.timing is not None:  # a second driver and filter in /faulty, fed by the relay
        extra.append(lambda c: relay(c, "timing_relay", SensorTiming, "/sensor/timing", "/faulty/sensor/timing",
                                     "elapsed_us", faults.timing, "/sensor/timing"))
        extra.append(lambda c: StrainDriverNode(context=c, namespace="/faulty", parameter_overrides=SIM))
        extra.append(lambda c: LowPassNode(context=c, namespace="/faulty", parameter_overrides=SIM))
        fb_topic = "/faulty" + fb_topic
    if faults.feedback is not None:
        extra.append(lambda c, src=fb_topic: relay(c, "feedback_relay", Stroke, src, "/faulty/feedback",
                                                   "stroke_mm", faults.feedback, "/laser/stroke"))
        fb_topic = "/faulty/feedback"
    if faults.command is not None:
        extra.append(lambda c: relay(c, "command_relay", VoltageCommand, "/faulty/amp/command", "/amp/command",
                                     "requested_kv", faults.command, "/amp/command"))
        remap = ["--ros-args", "-r", "amp/command:=/faulty/amp/command"]

    def controller(c):
        made["ctl"] = PidControllerNode(context=c, cli_args=remap, parameter_overrides=SIM + [
            Parameter("feedback", value=feedback), Parameter("feedback_topic", value=fb_topic)])
        return made["ctl"]

    extra.append(controller)
    cfg = GraphConfig(feedback=feedback, sequence_mm=list(seq), hold_s=hold, seed=seed, with_controller=False,
                      amplifier_params=amp_params or {},
                      # long enough that a busy machine never makes the plant step on its own, short
                      # enough that the periods the DAC holds (three per fault) cost little
                      plant_params={"lockstep_timeout_s": 0.2})
    with NodeGraph(cfg, extra_nodes=extra) as g:
        ctl = made["ctl"]
        links = [n.relay_pub for n in g.nodes if hasattr(n, "relay_pub")]
        end = time.monotonic() + 20
        while not (ctl.cmd_pub.get_subscription_count() and len(ctl.references) == len(seq)
                   and all(p.get_subscription_count() for p in links)
                   and ctl.count_publishers(fb_topic)):
            assert time.monotonic() < end, "the fault relays did not connect"
            g.executor.spin_once(timeout_sec=0.02)
        g.run(dur, wall_timeout_s=120)
        samples = g.collector.samples()
        applied = list(g.collector.applied)
        states = list(g.collector.states)
    return samples, applied, states


def compare(feedback, faults, seq, hold, dur, seed, amp_params=None, limits=None):
    """Run graph and loop; assert they agree; return the loop's result for scenario checks."""
    s, applied, states = run_graph(feedback, faults, seq, hold, dur, seed, amp_params)
    cfg = LoopConfig(feedback=feedback) if limits is None else LoopConfig(feedback=feedback, limits=limits)
    ref = run_closed_loop(PlantSimulator(seed=seed), step_reference(seq, hold), dur, cfg, faults)
    # the voltage the plant held at every 10 kHz sample, and what it did with it
    n = ref.applied_kv.size
    assert s["t_s"].size == n
    np.testing.assert_allclose(s["t_s"], ref.sample_t_s, rtol=0, atol=1e-9)
    np.testing.assert_allclose(s["voltage_kv"], ref.applied_kv, rtol=0, atol=1e-12)
    np.testing.assert_allclose(s["true_stroke_mm"], ref.true_stroke_mm, rtol=0, atol=1e-12)
    np.testing.assert_allclose(s["elapsed_us"], ref.elapsed_us, rtol=0, atol=1e-12)
    # the amplifier's first output of each tick (the one the plant steps with)
    first = {}
    for t, _req, kv, reason in applied:
        first.setdefault(tick(t), (kv, reason))
    ticks = np.flatnonzero(ref.reason >= 0)
    assert sorted(k for k in first if k < ref.reason.size) == ticks.tolist()
    np.testing.assert_array_equal([first[k][0] for k in ticks], ref.command_kv[ticks])
    np.testing.assert_array_equal([first[k][1] for k in ticks], ref.reason[ticks])
    # the controller's stale/ok transitions (the state messages without a measurement)
    graph_changes = [(tick(from_stamp(st.header.stamp)), st.input_stale) for st in states
                     if math.isnan(st.measured_mm)]
    was = np.concatenate([[False], ref.stale[:-1]])
    loop_changes = [(int(k), bool(ref.stale[k])) for k in np.flatnonzero(ref.stale != was)]
    assert graph_changes == loop_changes
    return ref


def in_ticks(*spans):
    """A set of tick numbers from (first, last) spans."""
    return {k for a, b in spans for k in range(a, b + 1)}


def corrupt(lost=(), nan=(), change=None):
    """A fault rule by tick: lost messages, NaN values, and ``change[k](value)`` at other ticks."""
    change = change or {}

    def rule(t, value):
        k = tick(t)
        if k in lost:
            return None
        if k in nan:
            return math.nan
        return change[k](value) if k in change else value

    return rule


def test_nan_bursts_spikes_and_dropout_of_the_feedback_graph_equals_loop():
    rule = corrupt(lost=in_ticks((110, 129)), nan=in_ticks((60, 64)),
                   change={k: (lambda z: z + 8.0) for k in (80, 95)})  # spikes
    ref = compare("laser", LoopFaults(feedback=rule), [2.0, 4.0], 0.3, 0.9, seed=21)
    # the scenario did what it says: samples rejected and held, then stale and 0 kV, then resumed
    held = ref.requested_kv[[60, 61, 62, 80, 95]]  # rejected: the last command held
    assert np.all(np.isfinite(held)) and np.all(held == ref.requested_kv[[59, 59, 59, 79, 94]])
    # four periods without a valid sample: stale, no command (the DAC holds), back on the first good one
    assert ref.stale[63:65].all() and np.all(ref.reason[63:65] == -1) and not ref.stale[65]
    # the samples after the dropout jump (the actuator relaxed): rejected three times, then re-anchored
    assert not ref.stale[65:113].any() and ref.stale[113:133].all() and not ref.stale[133:].any()
    assert np.all(ref.reason[113:130] == Reason.WATCHDOG) and np.all(ref.command_kv[113:130] == 0.0)
    assert np.all(ref.reason[110:113] == -1)  # the DAC held the last command for three periods


def test_faulty_555_readings_with_strain_feedback_graph_equals_loop():
    bad = {50: 0.0, 51: -3.0, 70: math.inf}
    rule = corrupt(lost=in_ticks((90, 99)), nan=in_ticks((40, 43)),
                   change={k: (lambda _, v=v: v) for k, v in bad.items()})
    ref = compare("strain", LoopFaults(timing=rule), [2.0, 3.0], 0.3, 0.7, seed=5)
    assert np.all(np.isnan(ref.strain_mm[[40, 43, 50, 51, 70]]))
    assert np.all(np.isfinite(ref.filtered_mm[[44, 52, 71]]))  # the filter's state was never poisoned
    assert ref.stale[93:100].all() and not ref.stale[100:].any()


def test_stuck_sensor_then_recovery_graph_equals_loop():
    frozen = {}

    def rule(t, z):
        if 100 <= tick(t) < 160:
            return frozen.setdefault("z", z)  # the sensor freezes while the reference moves
        return z

    ref = compare("laser", LoopFaults(feedback=rule), [2.0, 5.0], 0.5, 1.0, seed=4)
    assert ref.stale[150:160].all() and np.all(ref.command_kv[150:160] == 0.0)
    assert not ref.stale[-20:].any() and abs(ref.laser_mm[-1] - 5.0) < 1.0  # it resumed


def test_commands_above_nine_kv_nonfinite_and_lost_graph_equals_loop():
    # requests corrupted above 9 kV, one NaN, and lost ones (the DAC holds, then the amplifier's watchdog)
    rule = corrupt(lost=in_ticks((80, 81), (90, 99)), nan={70},
                   change={k: (lambda kv: kv + 10.0) for k in range(60, 66)})
    ref = compare("laser", LoopFaults(command=rule), [2.0, 4.0], 0.25, 0.6, seed=8)
    assert np.all(ref.reason[60:66] == Reason.CLAMP_HIGH) and np.all(ref.command_kv[60:66] == 9.0)
    assert ref.reason[70] == Reason.NONFINITE and ref.command_kv[70] == 0.0
    assert np.all(ref.reason[80:82] == -1) and np.all(ref.reason[94:100] == Reason.WATCHDOG)
    assert ref.applied_kv.max() <= 9.0 + 1e-9


def test_request_above_a_lowered_ceiling_graph_equals_loop():
    from hasel.amplifier import HvLimits

    ref = compare("laser", LoopFaults(), [2.0, 8.0], 0.2, 0.5, seed=2, amp_params={"v_max_kv": 5.0},
                  limits=HvLimits(v_max_kv=5.0))
    assert (ref.reason == Reason.CLAMP_HIGH).any() and ref.command_kv.max() == 5.0
