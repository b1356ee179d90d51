"""Every command rejects bad input with one clear line on stderr and exit code 2, no traceback."""
from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from hasel.cli import main as hasel_main

ROOT = Path(__file__).resolve().parents[1]
HASEL = str(ROOT / ".venv" / "bin" / "hasel")


@pytest.fixture(scope="module")
def files(tmp_path_factory):
    d = tmp_path_factory.mktemp("bad")
    t = np.arange(0, 2, 1e-3)
    good = np.column_stack([t, np.sin(2 * np.pi * 3 * t) + 2, np.cos(t)])
    np.savetxt(d / "nan.csv", np.where(t[:, None] > 1, np.nan, good), delimiter=",", header="t_s,voltage_kv,stroke_mm",
               comments="")
    back = good.copy()
    back[500, 0] = 0.1
    np.savetxt(d / "backwards.csv", back, delimiter=",", header="t_s,voltage_kv,stroke_mm", comments="")
    np.savetxt(d / "short.csv", good[:3], delimiter=",", header="t_s,voltage_kv,stroke_mm", comments="")
    flat = good.copy()
    flat[:, 1] = 2.0
    np.savetxt(d / "flat.csv", flat, delimiter=",", header="t_s,voltage_kv,stroke_mm", comments="")
    (d / "not.mcap").write_bytes(b"\x89MCAP0\r\n" + os.urandom(300))
    (d / "empty.csv").write_text("")
    (d / "model.json").write_text('{"num": [1.0]}')
    (d / "exists.mcap").write_bytes(b"")
    return d


CORE_CASES = [
    ["identify", "{d}/missing.csv"],
    ["identify", "{d}/nan.csv"],
    ["identify", "{d}/backwards.csv"],
    ["identify", "{d}/short.csv"],
    ["identify", "{d}/flat.csv"],
    ["identify", "{d}/empty.csv"],
    ["identify", "{d}/nan.csv", "--output", "no_such_column"],
    ["identify", "{d}/not.mcap"],
    ["info", "{d}/not.mcap"],
    ["info", "{d}/missing.mcap"],
    ["salvage", "{d}/missing.mcap", "{d}/out.mcap"],
    ["diagnose", "{d}/missing.csv", "--json", "{d}/v.json"],
    ["diagnose", "{d}/nan.csv", "--model", "{d}/model.json", "--json", "{d}/v.json"],
    ["frobnicate"],
    ["identify"],
]


@pytest.mark.parametrize("argv", CORE_CASES, ids=lambda a: " ".join(a)[:40])
def test_core_commands_in_process(argv, files, capsys):
    args = [a.format(d=files) for a in argv]
    with pytest.raises(SystemExit) if argv in (["frobnicate"], ["identify"]) else _nothing():
        rc = hasel_main(args)
        assert rc == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) >= 1 and "Traceback" not in "\n".join(err)
    assert err[-1].startswith("hasel") and "error" in err[-1]


class _nothing:
    def __enter__(self):
        return self

    def __exit__(self, *exc):
        return False


ROS_CASES = [
    ["steps", "--sequence", "2,abc"],
    ["steps", "--hold", "-1"],
    ["steps", "--plant", "imaginary"],
    ["steps", "--calibration", "/no/such/file.yaml"],
    ["calibrate", "--points", "2", "--degree", "2"],
    ["chirp", "--offsets", "9"],
    ["record", "-o", "{d}/exists.mcap", "--duration", "0.1"],
    ["replay", "{d}/missing.mcap"],
    ["replay", "{d}/not.mcap"],
    ["replay", "{d}/exists.mcap", "--remap", "a-b"],
]


@pytest.mark.parametrize("argv", ROS_CASES, ids=lambda a: " ".join(a)[:40])
def test_ros_commands_as_a_user_runs_them(argv, files):
    env = {k: v for k, v in os.environ.items() if k != "HASEL_ROS_ENV_READY"}
    out = subprocess.run([HASEL, *[a.format(d=files) for a in argv]], capture_output=True, text=True,
                         timeout=120, env=env)
    err = out.stderr.strip().splitlines()
    assert out.returncode == 2, out.stderr
    assert "Traceback" not in out.stderr
    assert len([line for line in err if "error" in line]) == 1 and err[-1].startswith("hasel")
