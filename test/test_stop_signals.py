"""SIGINT, SIGTERM and SIGHUP stop every file-writing command alike: the experiment
stops, the files are closed (mcap's own reader opens them, summary and footer there),
nothing above 9 kV was recorded, and the exit code is 128 + the signal number. Also
when the command runs in the background of a script (SIGINT ignored there)."""
from __future__ import annotations

import os
import signal
import subprocess
import time
from pathlib import Path

import numpy as np
import pytest
from mcap.reader import make_reader
from mcap_ros2.decoder import DecoderFactory

from children import default_sigint

ROOT = Path(__file__).resolve().parents[1]
HASEL = str(ROOT / ".venv" / "bin" / "hasel")


def _env() -> dict[str, str]:
    return {k: v for k, v in os.environ.items() if k != "HASEL_ROS_ENV_READY"}


def recorded_kv(path: Path) -> tuple[int, float]:
    """Messages in a complete MCAP file (mcap's reader, summary required) and the highest
    applied voltage recorded anywhere in it, kV."""
    with path.open("rb") as f:
        reader = make_reader(f, decoder_factories=[DecoderFactory()])
        assert reader.get_summary() is not None, "no summary: the file was not closed"
        n, top = 0, 0.0
        for _, ch, _, m in reader.iter_decoded_messages():
            n += 1
            if ch.topic == "/amp/applied":
                top = max(top, m.applied_kv)
            elif ch.topic in ("/plant/batch", "/amp/applied_batch") and len(m.voltage_kv):
                top = max(top, float(np.nanmax(np.asarray(m.voltage_kv))))
    return n, top


def _wait_for(path: Path, proc: subprocess.Popen, min_bytes: int = 1, timeout_s: float = 60.0) -> None:
    """Wait until the command has been recording for a while (its file has data)."""
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        assert proc.poll() is None, proc.communicate()
        if path.exists() and path.stat().st_size >= min_bytes:
            return
        time.sleep(0.1)
    raise AssertionError(f"{path} got no data in {timeout_s} s")


COMMANDS = {
    "steps": ["steps", "--sequence", "2,4,6,4,2", "--hold", "10", "--record", "{out}"],
    "chirp": ["chirp", "--offsets", "3,5", "--out", "{out}"],
}


@pytest.mark.parametrize("sig,command", [("SIGTERM", "steps"), ("SIGINT", "steps"), ("SIGHUP", "steps"),
                                         ("SIGTERM", "chirp"), ("SIGHUP", "chirp")])
def test_a_signal_mid_run_closes_the_file_and_exits_128_plus_the_signal(tmp_path, sig, command):
    out = tmp_path / "run.mcap"
    proc = subprocess.Popen([HASEL, *[a.format(out=out) for a in COMMANDS[command]]], env=_env(), preexec_fn=default_sigint,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        _wait_for(out, proc, min_bytes=200_000)  # a few chunks written: mid-run
        proc.send_signal(getattr(signal, sig))
        _, err = proc.communicate(timeout=60)
    finally:
        proc.kill()
    assert proc.returncode == 128 + getattr(signal, sig), err
    assert "Traceback" not in err
    assert f"stopped by {sig}" in err.splitlines()[-1]
    n, top = recorded_kv(out)
    assert n > 100
    assert 0.0 < top <= 9.0
    assert not list(tmp_path.glob(".*part*")), "a temporary file was left behind"


def test_in_the_background_of_a_script_sigint_is_ignored_and_sigterm_stops_cleanly(tmp_path):
    out = tmp_path / "bg.mcap"
    pidfile, rcfile = tmp_path / "pid", tmp_path / "rc"
    # a non-interactive shell starts background jobs with SIGINT ignored
    script = (f"{HASEL} steps --sequence 2,4,6,4,2 --hold 10 --record {out} >/dev/null 2>{tmp_path}/err & "
              f"echo $! > {pidfile}; wait $!; echo $? > {rcfile}")
    shell = subprocess.Popen(["bash", "-c", script], env=_env())
    try:
        deadline = time.monotonic() + 30
        while not (pidfile.exists() and pidfile.read_text().strip()) and time.monotonic() < deadline:
            time.sleep(0.05)
        pid = int(pidfile.read_text())
        _wait_for(out, shell, min_bytes=200_000)
        os.kill(pid, signal.SIGINT)  # ignored, as the shell meant
        time.sleep(1.0)
        assert shell.poll() is None and not rcfile.exists(), "SIGINT stopped a background job"
        os.kill(pid, signal.SIGTERM)
        shell.wait(timeout=60)
    finally:
        shell.kill()
    assert int(rcfile.read_text()) == 128 + signal.SIGTERM
    assert "Traceback" not in (tmp_path / "err").read_text()
    n, top = recorded_kv(out)
    assert n > 100 and top <= 9.0


def test_hasel_record_stopped_by_sighup_leaves_a_complete_file(tmp_path):
    out = tmp_path / "rec.mcap"
    proc = subprocess.Popen([HASEL, "record", "-o", str(out), "--topics", "/nothing_here"], env=_env(), preexec_fn=default_sigint,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        _wait_for(out, proc)  # the header is on disk: the recorder runs
        time.sleep(0.5)
        proc.send_signal(signal.SIGHUP)
        stdout, err = proc.communicate(timeout=30)
    finally:
        proc.kill()
    assert proc.returncode == 128 + signal.SIGHUP, err
    assert "stopped by SIGHUP" in stdout and "Traceback" not in err
    n, _ = recorded_kv(out)
    assert n == 0


NODE_EXE = ROOT / "install" / "hasel_control" / "lib" / "hasel_control" / "hv_amplifier"


@pytest.mark.parametrize("sig", ["SIGTERM", "SIGINT", "SIGHUP"])
def test_a_node_stopped_by_a_signal_commands_0_kv_and_exits_128_plus_the_signal(sig):
    """The amplifier node run as ``ros2 run`` runs it: a stop signal ends it with its last 0 kV
    command published (reason SHUTDOWN) and exit code 128 + the signal, like the commands."""
    import rclpy
    from rclpy.context import Context

    from hasel_msgs.msg import VoltageCommand
    from hasel_ros.rosutil import topic_qos

    ctx = Context()
    rclpy.init(context=ctx)
    node = rclpy.create_node("stop_probe", context=ctx)
    got: list = []
    node.create_subscription(VoltageCommand, "/amp/applied", got.append, topic_qos("/amp/applied"))
    pub = node.create_publisher(VoltageCommand, "/amp/command", topic_qos("/amp/command"))
    from rclpy.executors import SingleThreadedExecutor

    ex = SingleThreadedExecutor(context=ctx)
    ex.add_node(node)
    proc = subprocess.Popen([str(NODE_EXE)], env=dict(os.environ),
                            preexec_fn=default_sigint, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        deadline = time.monotonic() + 60
        while not any(m.applied_kv > 1.0 for m in got) and time.monotonic() < deadline:
            assert proc.poll() is None, proc.communicate()
            pub.publish(VoltageCommand(requested_kv=3.0))  # the node holds 3 kV
            ex.spin_once(timeout_sec=0.05)
        assert got and got[-1].applied_kv == pytest.approx(3.0), "the amplifier never applied 3 kV"
        proc.send_signal(getattr(signal, sig))
        end = time.monotonic() + 30
        while proc.poll() is None and time.monotonic() < end:
            ex.spin_once(timeout_sec=0.05)
        for _ in range(20):  # what was on its way
            ex.spin_once(timeout_sec=0.05)
        _, err = proc.communicate(timeout=30)
    finally:
        proc.kill()
        node.destroy_node()
        rclpy.try_shutdown(context=ctx)
    assert proc.returncode == 128 + getattr(signal, sig), err
    assert "Traceback" not in err and f"stopped by {sig}" in err.splitlines()[-1]
    last = got[-1]
    assert last.applied_kv == 0.0 and last.reason == VoltageCommand.REASON_SHUTDOWN


def test_hasel_demo_stopped_during_its_diagnosis_exits_128_plus_the_signal(tmp_path):
    """The demo runs ``hasel diagnose`` (forked fitting processes) inside its own process: SIGTERM
    there stops the demo itself with 143 and one "stopped" line, not a "failed" stage or a hang;
    the logs it recorded before are complete files at <= 9 kV."""
    out = tmp_path / "demo"
    log = tmp_path / "stdout.txt"
    with log.open("w") as fh:
        proc = subprocess.Popen([HASEL, "demo", "--quick", "--out", str(out)], stdout=fh,
                                stderr=subprocess.PIPE, text=True, env=_env(), preexec_fn=default_sigint)
    try:
        deadline = time.monotonic() + 400.0
        while "$ hasel diagnose" not in log.read_text():
            assert proc.poll() is None, proc.communicate()
            assert time.monotonic() < deadline, "the demo never reached its diagnosis"
            time.sleep(0.2)
        time.sleep(0.5)  # inside the diagnosis stage (its fits now take only a few seconds in --quick)
        proc.send_signal(signal.SIGTERM)
        _, err = proc.communicate(timeout=60)
    finally:
        if proc.poll() is None:
            proc.kill()
    assert proc.returncode == 128 + signal.SIGTERM, err
    assert "hasel demo: stopped by SIGTERM" in err and "failed" not in err, err
    for name in ("truth_chirp.mcap", "truth_heldout.mcap"):
        n, top = recorded_kv(out / name)
        assert n > 1000 and 0.0 < top <= 9.0, (name, n, top)
