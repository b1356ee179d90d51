"""A CLI fuzzer: random argument lists for every ``hasel`` subcommand, random and
damaged files for every file argument, random node parameters.

Every case must end with exit code 0, 1 or 2 (or 128 + N after our own signal N),
never a traceback; a bad input (2) is one ``error`` line; no output that existed is
changed without ``--overwrite``; no temporary file is left behind; every MCAP file a
command wrote opens with mcap's own reader (summary present) and holds no applied
voltage above 9 kV.

ROS-free commands (identify, diagnose, info, salvage) run in-process through
``hasel.cli.main(argv)``; the graph commands (steps, calibrate, chirp, record,
replay) and the nodes run as real processes. ``HASEL_CLI_FUZZ_SCALE`` multiplies the
number of cases (``make bench`` runs it longer, non-deterministically, and reports
the cases tried through ``HASEL_CLI_FUZZ_REPORT``); ``make test`` runs a fixed set.
A valid ``diagnose`` run takes 10 s or more even on a tiny log, so ``diagnose`` is
fuzzed here with inputs that cannot all be valid.
"""
from __future__ import annotations

import contextlib
import io
import json
import os
import signal
import subprocess
from collections import Counter
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, Phase, given, settings
from hypothesis import strategies as st

from hasel.cli import main as hasel_main
from hasel_bench.fuzz import make_seeds, mutate
from test_stop_signals import recorded_kv

ROOT = Path(__file__).resolve().parents[1]
HASEL = str(ROOT / ".venv" / "bin" / "hasel")
INSTALL = ROOT / "install"
SCALE = float(os.environ.get("HASEL_CLI_FUZZ_SCALE", "1"))
REPORT = os.environ.get("HASEL_CLI_FUZZ_REPORT")
TRIED: Counter = Counter()
SEEN: dict[str, str] = {}  # one example of each first error word pattern, for the report


def _settings(n: int):
    # no shrinking: each case is a process start or a model fit, and the failing case is printed as is
    return settings(max_examples=max(1, int(n * SCALE)), deadline=None, derandomize=SCALE <= 1,
                    suppress_health_check=list(HealthCheck), database=None,
                    phases=[Phase.explicit, Phase.generate])


@pytest.fixture(scope="module", autouse=True)
def _report():
    yield
    if REPORT:
        Path(REPORT).write_text(json.dumps({"cases": dict(TRIED), "examples": SEEN}, indent=1))


@pytest.fixture(scope="module")
def pool(tmp_path_factory):
    """Files for every file argument: valid, damaged, of the wrong kind, missing."""
    d = tmp_path_factory.mktemp("fuzzpool")
    rng = np.random.default_rng(17)
    seeds = make_seeds(d / "seeds", rng)
    files = {p.name: p for p in seeds}
    for p in seeds:
        other = seeds[0].read_bytes()
        for k in range(4):
            q = d / f"bad{k}_{p.name}"
            q.write_bytes(mutate(p.read_bytes(), p.suffix, rng, other))
            files[q.name] = q
    t = np.arange(0, 4, 2e-3)
    u = 2 + np.sin(2 * np.pi * (0.5 + 2 * t) * t)
    y = np.convolve(u, np.exp(-np.arange(50) / 10) / 10)[:t.size]
    np.savetxt(d / "tiny.csv", np.column_stack([t, u, y]), delimiter=",", header="t_s,voltage_kv,stroke_mm",
               comments="")
    files["tiny.csv"] = d / "tiny.csv"
    bad = {
        "empty.csv": b"", "empty.mcap": b"", "binary.csv": rng.bytes(2000), "text.mcap": b"t_s,u\n1,2\n",
        "notmagic.mcap": b"\x89MCAP0\r\n" + rng.bytes(500), "model.json": b'{"num": [1.0], "den": [0.1, 1.0]}',
        "badmodel.json": b'{"num": "x"}', "list.json": b"[1, 2]", "cal.yaml": b"coeffs: [0.1, -5.0]\n",
        "badcal.yaml": b"coeffs: {a: 1}\n", "binary.yaml": b"\x89MCAP\x00\xff" * 40, "nan.csv":
        b"t_s,voltage_kv,stroke_mm\n" + b"".join(f"{i * 1e-3},nan,{i}\n".encode() for i in range(100)),
    }
    for name, data in bad.items():
        (d / name).write_bytes(data)
        files[name] = d / name
    (d / "adir.csv").mkdir()
    files["adir.csv"] = d / "adir.csv"
    files["missing.mcap"] = d / "missing.mcap"
    files["model_is_mcap"] = seeds[0]
    return files


NUMBERS = ["-1", "0", "1", "2", "3", "0.5", "0.2", "nan", "inf", "-inf", "1e308", "99999999999", "-0", "abc", "",
           "1,2", "0,0", "2,1", "3,5", "-3", "1e-9", "8", "12"]
SIGNALS = ["0", "1", "2", "t_s", "voltage_kv", "stroke_mm", "nope", "/plant/batch.voltage_kv",
           "/plant/batch.stroke_mm", "/amp/applied.applied_kv", "/nope.x", "/plant/batch"]


def _value(data, key: str, pool: dict) -> list[str]:
    """One option's argument list: a value from the right pool (files for file options)."""
    if key in ("--model", "--heldout", "--calibration"):
        return [key, str(pool[data.draw(st.sampled_from(sorted(pool)), label=key)])]
    if key in ("--input", "--output", "--time"):
        return [key, data.draw(st.sampled_from(SIGNALS + ["fs=1000", "dt=-1", "fs=0"]), label=key)]
    if key == "--identify":
        return [key, data.draw(st.sampled_from(["auto", "internal", "ident", "bogus"]), label=key)]
    if key in ("--delay", "--no-markers", "--paper", "--clock"):
        return [key]
    return [f"{key}={data.draw(st.sampled_from(NUMBERS), label=key)}"]


def _outputs(data, tmp: Path, names: list[str]) -> tuple[list[str], dict[Path, bytes]]:
    """Output options, each absent, a new file, an existing file (content kept to compare) or unwritable."""
    argv, existing = [], {}
    for opt in names:
        kind = data.draw(st.sampled_from(["none", "new", "none", "new", "existing", "unwritable"]), label=opt)
        if kind == "none":
            continue
        suffix = {"--plot": ".png", "--report": "", "--export-sim": ".csv", "out": ".mcap", "-o": ".mcap",
                  "--record": ".mcap", "--output": ".mcap"}.get(opt, ".json")
        path = tmp / f"out_{opt.strip('-').replace('-', '_')}{suffix}"
        if kind == "unwritable":
            path = Path("/proc/no_such_dir") / path.name
        if kind == "existing":
            target = path / "report.md" if opt == "--report" else path
            target.parent.mkdir(parents=True, exist_ok=True)
            content = f"keep me {opt}\n".encode()
            target.write_bytes(content)
            existing[target] = content
        argv += [str(path)] if opt == "out" else [opt, str(path)]
    return argv, existing


def _check_end(rc: int, err: str, cmd: str, argv: list[str], existing: dict[Path, bytes], tmp: Path,
               allowed=(0, 1, 2)) -> None:
    """The promises every case keeps."""
    where = f"hasel {' '.join(argv)}\n{err}"
    last = err.strip().splitlines()[-1] if err.strip() else ""
    SEEN.setdefault(f"{cmd} {rc} {' '.join(w for w in last.split()[2:5] if '/' not in w)}",
                    f"{' '.join(argv)} -> {last}"[:400])
    assert rc in allowed, where
    assert "Traceback" not in err, where
    if rc == 2:
        lines = [ln for ln in err.strip().splitlines() if "error" in ln]
        assert len(lines) == 1 and lines[0].startswith(("hasel:", f"hasel {cmd}")), where
    if "--overwrite" not in argv:
        for path, content in existing.items():
            assert path.read_bytes() == content, f"{path} overwritten without --overwrite: {where}"
    left = [p for p in tmp.rglob(".*") if p.is_file()]
    assert not left, f"temporary files left: {left}: {where}"
    for p in tmp.rglob("*.mcap"):
        if p not in existing and p.stat().st_size:
            _, top = recorded_kv(p)
            assert top <= 9.0, where


CORE = {
    "identify": (["--time", "--input", "--output", "--band", "--order", "--max-poles", "--holdout", "--settle",
                  "--delay", "--no-markers", "--paper"], ["--json", "--plot", "--report"]),
    "diagnose": (["--model", "--heldout", "--time", "--input", "--output", "--identify", "--rate",
                  "--max-effects"], ["--json", "--export-sim", "--report"]),
    "info": ([], ["--json"]),
    "salvage": ([], ["out"]),
}
# inputs that make diagnose stop early (a valid run takes 10 s or more): a bad file or a bad option
SURELY_BAD = ["empty.csv", "binary.csv", "text.mcap", "notmagic.mcap", "adir.csv", "missing.mcap", "nan.csv"]


@_settings(45)
@given(data=st.data())
def test_core_commands_keep_their_promises(pool, tmp_path_factory, data):
    cmd = data.draw(st.sampled_from(sorted(CORE)), label="command")
    opts, outs = CORE[cmd]
    tmp = tmp_path_factory.mktemp("case")
    names = SURELY_BAD if cmd == "diagnose" else ["tiny.csv"] * 6 + ["seed_zstd.mcap", "seed_none.mcap"] + \
        sorted(k for k in pool if k != "model_is_mcap")
    plain = cmd == "identify" and data.draw(st.booleans(), label="valid data, no options")
    argv = [cmd, str(pool["tiny.csv" if plain else data.draw(st.sampled_from(names), label="DATA")])]
    for key in [] if plain or not opts else data.draw(st.lists(st.sampled_from(opts), unique=True, max_size=3),
                                                      label="options"):
        argv += _value(data, key, pool)
    out_argv, existing = _outputs(data, tmp, outs)
    argv += out_argv
    if data.draw(st.booleans(), label="--overwrite"):
        argv.append("--overwrite")
    err = io.StringIO()
    with contextlib.redirect_stderr(err), contextlib.redirect_stdout(io.StringIO()):
        try:
            rc = hasel_main(argv)
        except SystemExit as stop:  # argparse refusing an option
            rc = stop.code
    TRIED[f"{cmd} exit {rc}"] += 1
    _check_end(rc, err.getvalue(), cmd, argv, existing, tmp)
    if rc == 0 and cmd == "salvage":
        assert Path(argv[2]).exists()


GRAPH = {
    "steps": (["--sequence", "--hold", "--feedback", "--plant", "--seed", "--calibration"],
              ["--record", "--json", "--plot"]),
    "calibrate": (["--points", "--hold", "--degree", "--plant", "--seed"], ["--out"]),
    "chirp": (["--offsets", "--amplitude", "--f0", "--f1", "--chirp", "--precondition-s", "--settle-s", "--plant",
               "--seed", "--repeats"], ["--out"]),
    "record": (["--topics"], ["-o"]),
    "replay": (["--topics", "--remap", "--clock"], []),
}
GRAPH_VALUES = {
    "--sequence": ["2,4", "2,50", "2,-1", "abc", "2", "nan,2", "3,5,3"],
    "--hold": ["0.1", "0.2", "-1", "nan", "0", "1e9"],
    "--feedback": ["laser", "strain", "bogus"],
    "--plant": ["nominal", "truth", "imaginary", "truth:bogus("],
    "--seed": ["0", "1", "-1", "99999999999", "abc"],
    "--points": ["2,3", "2,3,4", "abc", "0,12", "2"],
    "--degree": ["1", "2", "4"],
    "--offsets": ["3", "3,5", "-3", "9", "abc", "8.5"],
    "--amplitude": ["1", "0", "-1", "5", "nan"],
    "--f0": ["0.001", "0", "-1", "30"],
    "--f1": ["20", "6000", "2400", "0", "inf"],
    "--chirp": ["paper", "linear", "multisine", "bogus"],
    "--precondition-s": ["0", "0.5", "-1", "0.0031"],
    "--settle-s": ["0", "0.1"],
    "--repeats": ["1", "0", "-1"],
    "--topics": ["", "/plant/batch", "/nope,/clock"],
    "--remap": ["a-b", "/plant/batch:=/x", "/a:=b"],
}
# every run is bounded: a valid case is a short one
BOUNDS = {"chirp": ["--duration", ["0.1", "0.2", "0", "-1", "nan"]], "record": ["--duration", ["0.3", "-1", "nan", "0"]],
          "replay": ["--wait", ["0", "0.1", "-1"]], "calibrate": ["--hold", ["0.2", "0.1", "nan"]]}


def _env() -> dict[str, str]:
    return {k: v for k, v in os.environ.items() if k != "HASEL_ROS_ENV_READY"}


@_settings(7)
@given(data=st.data())
def test_graph_commands_keep_their_promises(pool, tmp_path_factory, data):
    cmd = data.draw(st.sampled_from(sorted(GRAPH)), label="command")
    opts, outs = GRAPH[cmd]
    tmp = tmp_path_factory.mktemp("gcase")
    argv = [cmd]
    if cmd == "replay":
        argv += [str(pool[data.draw(st.sampled_from(sorted(pool)), label="FILE")]), "--rate",
                 data.draw(st.sampled_from(["0", "-1", "nan"]), label="--rate")]
    if cmd in BOUNDS:
        key, vals = BOUNDS[cmd]
        argv += [f"{key}={data.draw(st.sampled_from(vals), label=key)}"]
    for key in data.draw(st.lists(st.sampled_from(opts), unique=True, max_size=4), label="options"):
        if key == "--hold" and cmd == "calibrate":
            continue
        if key in ("--calibration",):
            argv += _value(data, key, pool)
        elif key == "--clock":
            argv.append(key)
        else:
            argv.append(f"{key}={data.draw(st.sampled_from(GRAPH_VALUES[key]), label=key)}")
    if cmd == "steps" and not any(a.startswith("--hold") for a in argv):
        argv.append("--hold=0.1")
    out_argv, existing = _outputs(data, tmp, outs)
    argv += out_argv
    if outs and data.draw(st.booleans(), label="--overwrite"):
        argv.append("--overwrite")
    proc = subprocess.run([HASEL, *argv], capture_output=True, text=True, timeout=120, env=_env(), cwd=tmp)
    TRIED[f"{cmd} exit {proc.returncode}"] += 1
    _check_end(proc.returncode, proc.stderr, cmd, argv, existing, tmp)


NODES = {
    "hasel_control/lib/hasel_control/hv_amplifier": {
        "v_max_kv": ["12.0", "9.0", "5.0", "-1.0", "abc", "nan"], "v_min_kv": ["0.0", "5.0", "-1.0", "10.0"],
        "period_s": ["0.0", "0.005", "2.0"], "watchdog_periods": ["0.0", "3.0", "-1.0", "1e9"]},
    "sim_plant/lib/sim_plant/plant": {
        "period_s": ["0.0", "0.005", "-1.0", "2.0"], "seed": ["-1", "5", "99999999999"],
        "variant": ["nominal", "bogus", "truth"], "clock_mode": ["sim", "wall", "moon"],
        "laser_noise_mm": ["-1.0", "0.01", "nan"], "stop_at_s": ["0.1", "-1.0"]},
    "hasel_control/lib/hasel_control/pid_controller": {
        "feedback": ["laser", "strain", "bogus"], "period_s": ["0.0", "0.005"]},
}


@_settings(5)
@given(data=st.data())
def test_nodes_refuse_bad_parameters_in_one_line(data):
    exe = data.draw(st.sampled_from(sorted(NODES)), label="node")
    params = data.draw(st.dictionaries(st.sampled_from(sorted(NODES[exe])), st.just(None), min_size=1, max_size=3),
                       label="p")
    args = []
    for name in params:
        args += ["-p", f"{name}:={data.draw(st.sampled_from(NODES[exe][name]), label=name)}"]
    proc = subprocess.Popen([HASEL, "env", "--", str(INSTALL / exe), "--ros-args", *args], env=_env(),
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        try:
            _, err = proc.communicate(timeout=5.0)
            stopped = False
        except subprocess.TimeoutExpired:  # it started: stop it as a script would
            proc.send_signal(signal.SIGTERM)
            _, err = proc.communicate(timeout=20)
            stopped = True
    finally:
        proc.kill()
    TRIED[f"node {Path(exe).name} exit {proc.returncode}"] += 1
    where = f"{exe} {' '.join(args)}\n{err}"
    # stopped by us: rclpy's handler ends it with 0; a process still starting up (before any
    # handler, nothing commanded yet) ends by the signal itself
    assert proc.returncode in ((0, 1, 2, 128 + signal.SIGTERM, -signal.SIGTERM) if stopped else (0, 1, 2)), where
    assert "Traceback" not in err, where
    if proc.returncode == 2:
        assert len([ln for ln in err.strip().splitlines() if ln.startswith("error")]) == 1, where
