"""Every command rejects bad input with one clear line on stderr and exit code 2, no traceback."""
from __future__ import annotations

import os
import subprocess
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
    ["identify", "{d}/backwards.csv", "--input", "0", "--output", "0"],
    ["identify", "{d}/backwards.csv", "--input", "voltage_kv", "--output", "voltage_kv"],
    ["diagnose", "{d}/nan.csv", "--model", "{d}/not.mcap"],
    ["identify", "{d}/nan.csv", "--json", "{d}/exists.mcap"],
    ["info", "{d}/not.mcap", "--json", "{d}/model.json"],
    ["salvage", "{d}/not.mcap", "{d}/exists.mcap"],
    ["identify", "{d}/nan.csv", "--json", "/proc/nope/model.json"],
]


@pytest.mark.parametrize("argv", CORE_CASES, ids=lambda a: " ".join(a)[:40])
def test_core_commands_in_process(argv, files, capsys):
    args = [a.format(d=files) for a in argv]
    with pytest.raises(SystemExit) if argv in (["frobnicate"], ["identify"]) else _nothing():
        rc = hasel_main(args)
        assert rc == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "Traceback" not in "\n".join(err)  # the error alone: no progress line before it
    assert err[-1].startswith("hasel") and "error" in err[-1]
    assert (files / "exists.mcap").read_bytes() == b"" and (files / "model.json").read_text() == '{"num": [1.0]}'


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
    ["replay", "{d}/model.json", "--rate", "0"],
    ["replay", "{d}/exists.mcap", "--wait=-1"],
    ["steps", "--seed", "-1"],
    ["steps", "--seed", "99999999999"],
    ["calibrate", "--seed", "-1"],
    ["chirp", "--seed", "-1"],
    ["calibrate", "--out", "/proc/nope.yaml"],
    ["chirp", "--offsets=-3"],
    ["chirp", "--f1", "6000"],
    ["chirp", "--f1", "3000", "--chirp", "paper"],
    ["steps", "--sequence", "2,-1"],
    ["steps", "--record", "{d}/exists.mcap"],
    ["chirp", "--out", "{d}/exists.mcap"],
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
    assert (files / "exists.mcap").read_bytes() == b"", "an existing output was touched"


def test_a_reference_beyond_reach_is_run_with_a_warning_naming_the_limit(tmp_path):
    env = {k: v for k, v in os.environ.items() if k != "HASEL_ROS_ENV_READY"}
    out = subprocess.run([HASEL, "steps", "--sequence", "2,50", "--hold", "0.2"], capture_output=True, text=True,
                         timeout=120, env=env, cwd=tmp_path)
    assert out.returncode == 0, out.stderr
    warning = [line for line in out.stderr.splitlines() if "warning" in line]
    assert len(warning) == 1 and "12.2 mm" in warning[0] and "9 kV" in warning[0]
    assert "9.000 kV" in out.stdout  # saturated at the ceiling, not above


@pytest.mark.parametrize("exe,param", [("hasel_control/lib/hasel_control/hv_amplifier", "v_max_kv:=12.0"),
                                       ("sim_plant/lib/sim_plant/plant", "period_s:=0.0"),
                                       ("sim_plant/lib/sim_plant/plant", "seed:=-1")])
def test_a_node_refuses_a_bad_start_parameter_in_one_line(exe, param):
    env = {k: v for k, v in os.environ.items() if k != "HASEL_ROS_ENV_READY"}
    out = subprocess.run([HASEL, "env", "--", str(ROOT / "install" / exe), "--ros-args", "-p", param],
                         capture_output=True, text=True, timeout=60, env=env)
    assert out.returncode == 2, out.stderr
    lines = out.stderr.strip().splitlines()
    assert "Traceback" not in out.stderr and len(lines) == 1
    assert param.split(":=")[0] in lines[0]


def test_outputs_honour_the_umask_all_alike(files, tmp_path, capsys):
    old = os.umask(0o027)
    try:
        assert hasel_main(["info", str(files / "not.mcap"), "--json", str(tmp_path / "i.json")]) == 2
        t = np.arange(0, 20, 1e-3)
        u = 2 + np.sin(2 * np.pi * (0.1 + 0.5 * t) * t)
        y = np.convolve(u, np.exp(-np.arange(50) / 10) / 10)[:t.size]
        np.savetxt(tmp_path / "d.csv", np.column_stack([t, u, y]), delimiter=",",
                   header="t_s,voltage_kv,stroke_mm", comments="")
        # the JSON and the plot are written whether or not the model passes its checks (exit 0 or 1);
        # since session 8 this noise-free toy is refused: check 6 finds the response unpinned at
        # 22.4 Hz, past the chirp's last frequency (20.1 Hz) at the excited band's top edge
        assert hasel_main(["identify", str(tmp_path / "d.csv"), "--json", str(tmp_path / "m.json"),
                           "--plot", str(tmp_path / "b.png")]) in (0, 1)
    finally:
        os.umask(old)
    modes = {p.name: p.stat().st_mode & 0o777 for p in tmp_path.iterdir() if p.name != "d.csv"}
    assert modes == {"i.json": 0o640, "m.json": 0o640, "b.png": 0o640}
    capsys.readouterr()


def test_debug_shows_the_traceback_that_users_do_not_see(files, capsys):
    args = ["diagnose", str(files / "nan.csv"), "--model", str(files / "not.mcap")]
    assert hasel_main(args) == 2
    assert "Traceback" not in capsys.readouterr().err
    assert hasel_main(["--debug", *args]) == 2
    err = capsys.readouterr().err
    assert "Traceback" in err and err.strip().splitlines()[-1].startswith("hasel diagnose: error: --model")
