"""Crashes of separate processes in a running wall-clock loop: the actuator ends at 0 kV,
the controller notices stale input, and control resumes after a restart."""
from __future__ import annotations

import os
import signal
import subprocess
import time
from pathlib import Path

import pytest
import rclpy
from diagnostic_msgs.msg import DiagnosticArray
from rclpy.context import Context
from rclpy.executors import SingleThreadedExecutor
from rclpy.qos import QoSProfile, ReliabilityPolicy

from children import default_sigint
from hasel_ros.rosutil import from_stamp
from hasel_msgs.msg import ControllerState, VoltageCommand

pytestmark = pytest.mark.wallclock  # asserts on wall-clock timing: run alone (Makefile)

INSTALL = Path(__file__).resolve().parents[1] / "install"
EXES = {
    "plant": ("sim_plant", "plant", ["-p", "clock_mode:=wall"]),
    "driver": ("hasel_driver", "strain_driver", []),
    "filter": ("hasel_driver", "lowpass_filter", []),
    "controller": ("hasel_control", "pid_controller", ["-p", "feedback:=strain"]),
    "amplifier": ("hasel_control", "hv_amplifier", []),
    "reference": ("hasel_control", "reference_generator", ["-p", "sequence_mm:=[3.0]", "-p", "hold_s:=1000.0"]),
}


def start(name: str, logs: Path) -> subprocess.Popen:
    """Start one node; its stderr goes to a file in ``logs`` (a pipe nobody reads fills up, 64 KiB of
    warnings later, and blocks the node: starved mid-test, deaf to SIGINT at teardown)."""
    pkg, exe, params = EXES[name]
    with open(logs / f"{name}.log", "ab") as err:
        return subprocess.Popen([str(INSTALL / pkg / "lib" / pkg / exe), "--ros-args", *params],
                                stdout=subprocess.DEVNULL, stderr=err, env=dict(os.environ),
                                preexec_fn=default_sigint)  # teardown's SIGINT must reach them


class Probe:
    def __init__(self) -> None:
        self.ctx = Context()
        rclpy.init(context=self.ctx)
        self.node = rclpy.create_node("crash_probe", context=self.ctx)
        self.applied: list[tuple[float, float, int]] = []  # (stamp s, applied kV, reason) in publication order
        self.states: list[ControllerState] = []
        self.diags: list[str] = []
        self.values: list[dict[str, str]] = []  # each diagnostic's key/values, beside its message
        self.diag_stamps: list[float] = []  # and its stamp, s (the amplifier's clock for its own trips)
        # a deep reader queue: on a loaded machine the probe may lag, and nothing may be lost
        deep = QoSProfile(depth=5000, reliability=ReliabilityPolicy.RELIABLE)
        self.node.create_subscription(VoltageCommand, "/amp/applied", lambda m: self.applied.append(
            (from_stamp(m.header.stamp), m.applied_kv, m.reason)), deep)
        self.node.create_subscription(ControllerState, "/controller/state", self.states.append, deep)
        self.node.create_subscription(DiagnosticArray, "/diagnostics", self._on_diag, deep)
        self.ex = SingleThreadedExecutor(context=self.ctx)
        self.ex.add_node(self.node)

    def _on_diag(self, msg: DiagnosticArray) -> None:
        for st in msg.status:
            self.diags.append(st.message)
            self.values.append({kv.key: kv.value for kv in st.values})
            self.diag_stamps.append(from_stamp(msg.header.stamp))

    def spin(self, seconds: float) -> None:
        end = time.monotonic() + seconds
        while time.monotonic() < end:
            self.ex.spin_once(timeout_sec=0.01)

    def wait(self, cond, timeout: float, what: str) -> None:
        end = time.monotonic() + timeout
        while not cond():
            if time.monotonic() > end:
                raise AssertionError(f"timed out waiting for {what}; {self.describe()}")
            self.ex.spin_once(timeout_sec=0.01)

    def describe(self) -> str:
        """What the probe has seen and knows of the graph (for a timeout's message)."""
        n = self.node
        pubs = {t: n.count_publishers(t) for t in ("/diagnostics", "/controller/state", "/amp/applied")}
        last = self.states[-1] if self.states else None
        return (f"publishers seen {pubs}; diagnostics {self.diags[-5:]}; {len(self.states)} states, last "
                f"stale={getattr(last, 'input_stale', None)} stamp={from_stamp(last.header.stamp) if last else None}; "
                f"{len(self.applied)} applied, last {self.applied[-1] if self.applied else None}; "
                f"probe clock {time.time():.3f}")

    def close(self) -> None:
        self.ex.shutdown()
        self.node.destroy_node()
        rclpy.try_shutdown(context=self.ctx)


@pytest.fixture
def loop(tmp_path):
    procs = {name: start(name, tmp_path) for name in EXES}
    probe = Probe()
    yield procs, probe, tmp_path
    probe.close()
    for p in procs.values():
        if p.poll() is None:
            p.send_signal(signal.SIGINT)
    for p in procs.values():
        try:
            p.wait(timeout=10)
        except subprocess.TimeoutExpired:
            p.kill()


def running(probe: Probe, since: float = 0.0) -> bool:
    recent = [kv for t, kv, r in probe.applied[-20:] if r == 0 and t > since]
    return len(recent) >= 10 and min(recent) > 0.5


def test_controller_crash_gives_zero_kv_and_restart_resumes(loop):
    procs, probe, logs = loop
    probe.wait(lambda: running(probe), 60, "the loop to run")
    # the amplifier stamps its own trips with its clock, the wall clock of this machine: a trip stamped after the
    # kill is the kill's (a loaded machine may trip and resume before it, and the probe may receive that late)
    t_kill = time.time()
    procs["controller"].send_signal(signal.SIGKILL)
    procs["controller"].wait()

    def trip() -> int | None:  # index of the amplifier's first 0 kV after the kill
        return next((i for i, (t, _, r) in enumerate(probe.applied) if r == VoltageCommand.REASON_WATCHDOG
                     and t > t_kill), None)

    def trip_diag() -> int | None:
        return next((i for i, (d, t) in enumerate(zip(probe.diags, probe.diag_stamps)) if "limited: watchdog" in d
                     and t > t_kill), None)

    probe.wait(lambda: trip() is not None, 10, "the amplifier's watchdog")
    probe.wait(lambda: trip_diag() is not None, 10, "the watchdog's diagnostic")
    # stale after three periods; the watchdog acts at its next period (plus scheduling jitter).
    # Measured on the amplifier's clock from its last command's arrival (stamp gaps would add the chain's
    # latency). An age of about 1 s was seen twice (a loaded machine in session 16, an idle one right after
    # the parallel tests in session 39) and not reproduced since; the message keeps what the probe saw around
    # the trip, to tell a late watchdog timer from a lost notice next time.
    age = float(probe.values[trip_diag()]["command_age_s"])
    i = trip()
    amp_diags = [(d, round(t, 4), v) for d, t, v in zip(probe.diags, probe.diag_stamps, probe.values)
                 if "limited" in d or "dropped" in d]
    assert 3 * 0.005 < age <= 5 * 0.005 + 0.01, (
        f"watchdog age {age} s; kill at {t_kill:.4f}; applied around the trip {probe.applied[max(0, i - 6):i + 4]}; "
        f"amplifier diagnostics {amp_diags[-6:]}")
    probe.spin(0.1)
    # nothing after the trip but 0 kV: requests of the dead controller still queued at the amplifier (it may be
    # starved on a loaded machine, and handles its timer first) were measured before the trip and are dropped
    # (test_amplifier_node reproduces that case; the command stamped 26 ms after a trip in one session-16 run was
    # more likely applied after an earlier trip of a loaded machine, which the old test took for the kill's)
    after = probe.applied[i:]
    assert all(kv == 0.0 for _, kv, _ in after), after[:5]
    t_restart = probe.applied[-1][0]
    procs["controller"] = start("controller", logs)
    probe.wait(lambda: running(probe, t_restart), 60, "control to resume after the restart")


@pytest.mark.parametrize("victim", ["driver", "plant"])
def test_losing_the_sensor_path_is_noticed_and_ends_at_zero_kv(loop, victim):
    procs, probe, _ = loop
    # the probe must be matched by the controller before the kill: a fault said to no reader
    # is lost (discovery on a loaded machine took > 20 s once), though it is restated each second
    probe.wait(lambda: running(probe) and probe.states, 60, "the loop to run and the controller's state")
    procs[victim].send_signal(signal.SIGKILL)
    procs[victim].wait()
    probe.wait(lambda: any("stale" in d for d in probe.diags), 10, "the controller to report stale input")
    probe.wait(lambda: probe.applied and probe.applied[-1][1] == 0.0, 10, "0 kV")
    # the stale state follows the diagnostic on another topic: no order between topics
    probe.wait(lambda: any(s.input_stale for s in probe.states), 5, "a controller state marked stale")
