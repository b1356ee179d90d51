"""``hasel diagnose`` progress and estimate: a status line on a terminal, cleared before an
error; nothing in a script (the one-line error promise); lines with ``--progress``; ``--jobs``."""
from __future__ import annotations

import json
import os
import subprocess
import sys

import numpy as np
import pytest

from hasel.diagnose.prep import LinearSim


def _files(tmp_path, usable: bool = False):
    rate = 200.0
    t = np.arange(4000) / rate
    u = np.repeat(np.random.default_rng(1).uniform(0, 2, 40), 100)
    y = LinearSim([2.0], [0.1, 1.0], rate).run(u)
    data = tmp_path / "log.csv"
    data.write_text("t_s,voltage_kv,stroke_mm\n" + "\n".join(f"{a},{b},{c}" for a, b, c in zip(t, u, y)) + "\n")
    model = tmp_path / "model.json"
    m = {"num": [2.0], "den": [0.1, 1.0]}
    if not usable:
        m.update({"usable": False, "reasons": ["fit 12 %"]})
    model.write_text(json.dumps(m))
    return data, model


def _run(args, **kw):
    return subprocess.run([sys.executable, "-m", "hasel.cli", "diagnose", *map(str, args)], text=True, **kw)


def test_in_a_script_a_failure_is_the_only_line_on_stderr(tmp_path):
    data, model = _files(tmp_path)
    p = _run([data, "--model", model, "--json", tmp_path / "v.json"], capture_output=True)
    assert p.returncode == 1
    assert p.stderr.strip().splitlines() == [p.stderr.strip()]  # no "loading ..." before it
    assert p.stderr.startswith("hasel diagnose: failed:")


def test_progress_lines_with_the_estimate_when_asked(tmp_path):
    data, model = _files(tmp_path, usable=True)
    p = _run([data, "--model", model, "--progress", "--jobs", "1"], capture_output=True)
    assert p.returncode == 0, p.stderr
    lines = p.stderr.strip().splitlines()
    est = [ln for ln in lines if "estimate: about" in ln]
    assert len(est) == 1 and lines.index(est[0]) < next(i for i, ln in enumerate(lines) if "nominal NRMSE" in ln)
    assert float(est[0].split("about")[1].split()[0]) > 0


def test_on_a_terminal_the_status_line_is_cleared_before_the_error(tmp_path):
    pty = pytest.importorskip("pty")
    data, model = _files(tmp_path)
    master, slave = pty.openpty()
    try:
        p = subprocess.Popen([sys.executable, "-m", "hasel.cli", "diagnose", str(data), "--model", str(model)],
                             stderr=slave, stdout=subprocess.DEVNULL, text=True)
        os.close(slave)
        slave = -1
        chunks = []
        while True:
            try:
                b = os.read(master, 4096)
            except OSError:  # the terminal closed with the process
                break
            if not b:
                break
            chunks.append(b)
        p.wait(timeout=120)
    finally:
        os.close(master)
        if slave >= 0:
            os.close(slave)
    screen = b"".join(chunks).decode()
    assert p.returncode == 1
    assert "\rhasel diagnose: loading" in screen  # the status line was shown...
    last = screen.rsplit("\r\x1b[K", 1)
    assert len(last) == 2 and last[1].replace("\r\n", "\n").strip().startswith("hasel diagnose: failed:")
    assert "\n" not in last[1].strip()  # ...and cleared: the error is the one line left


def test_jobs_below_one_is_bad_input(tmp_path):
    data, model = _files(tmp_path, usable=True)
    p = _run([data, "--model", model, "--jobs", "0"], capture_output=True)
    assert p.returncode == 2 and p.stderr.strip() == "hasel diagnose: error: --jobs must be >= 1, got 0"
