"""Where ``hasel`` finds its subcommands: the core's table and the ``hasel.commands`` entry points."""
from __future__ import annotations

import importlib.util
import os
import subprocess
import sys

from hasel import cli


def test_help_lists_the_commands_and_imports_no_command_module():
    code = ("import sys\nfrom hasel.cli import main\n"
            "try:\n    main(['--help'])\nexcept SystemExit as e:\n    assert e.code in (0, None)\n"
            "heavy = [m for m in sys.modules if m.split('.')[0] in ('numpy', 'scipy', 'rclpy')\n"
            "         or m in ('hasel.ident.cli', 'hasel.diagnose.cli', 'hasel_sysid.steps', 'hasel_bench.figures')]\n"
            "print('HEAVY', heavy)\n")
    env = {k: v for k, v in os.environ.items() if k not in ("PYTHONPATH", "HASEL_ROS_ENV_READY")}
    p = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=env, timeout=60)
    assert p.returncode == 0, p.stderr
    assert "HEAVY []" in p.stdout
    for name in ("identify", "diagnose", "info", "salvage", "env"):
        assert f"    {name} " in p.stdout


def test_entry_point_commands_are_found_beside_the_core_ones():
    cmds = {c.name: c for c in cli.commands()}
    assert {"env", "identify", "diagnose", "info", "salvage"} <= set(cmds)
    assert not any(c.needs_ros for n, c in cmds.items() if n in ("identify", "diagnose", "info", "salvage"))
    if importlib.util.find_spec("hasel_bench") is not None:  # installed by make setup
        assert cmds["bench"].needs_ros and cmds["bench"].help.startswith("the benchmarks")
    if importlib.util.find_spec("hasel_sysid") is not None:  # the built workspace
        assert {"steps", "compare", "calibrate", "chirp", "record", "replay", "demo"} <= set(cmds)


def test_a_declared_command_whose_package_is_missing_asks_for_make_setup(monkeypatch, capsys):
    ghost = cli._unavailable("ghost", ModuleNotFoundError("No module named 'hasel_ros'", name="hasel_ros"))
    monkeypatch.setattr(cli, "commands", lambda: (*cli.COMMANDS, ghost))
    monkeypatch.setenv("HASEL_ROS_ENV_READY", "1")  # no re-execution into the workspace's environment
    assert cli.main(["ghost", "--anything", "x"]) == 1
    err = capsys.readouterr().err.strip().splitlines()
    assert err == ["hasel ghost: needs the built ROS workspace (hasel_ros not found); run `make setup`"]


def test_every_command_runs_with_one_blas_thread_unless_the_user_set_one(tmp_path):
    # the thread count changes the order of BLAS sums, hence results in their last digits (README: make demo)
    code = ("import os\nfrom hasel.cli import main\n"
            "main(['identify', {missing!r}])\n"
            "print('THREADS', os.environ.get('OPENBLAS_NUM_THREADS'), os.environ.get('OMP_NUM_THREADS'))\n")
    missing = str(tmp_path / "no_such_log.csv")
    base = {k: v for k, v in os.environ.items()
            if k not in ("PYTHONPATH", "OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS")}
    for env, want in ((base, "THREADS 1 1"), ({**base, "OPENBLAS_NUM_THREADS": "3"}, "THREADS 3 1")):
        p = subprocess.run([sys.executable, "-c", code.format(missing=missing)], capture_output=True, text=True,
                           env=env, timeout=60)
        assert want in p.stdout, (p.stdout, p.stderr)
        assert "no_such_log" in p.stderr  # the command did run (and refused the missing file)


def test_an_option_prefix_is_not_taken_for_the_whole_option(tmp_path, capsys):
    """``identify --out X`` is an unknown option (one line, exit 2), not ``--output X``: the prefix match had
    the command run and fail on a missing column named X."""
    log = tmp_path / "log.csv"
    log.write_text("t,u,y\n0,0,0\n0.001,1,0.1\n")
    try:
        code = cli.main(["identify", str(log), "--out", "x.json"])
    except SystemExit as e:
        code = e.code
    err = capsys.readouterr().err
    assert code == 2
    assert "unrecognized arguments: --out x.json" in err
    assert "column" not in err and len(err.strip().splitlines()) == 1
