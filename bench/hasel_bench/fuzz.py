"""Bounded fuzzing of the log loaders for ``hasel bench`` (issue 7, item 5).

Valid seed files (MCAP logs as the recorder writes them, zstd-compressed and
uncompressed, with batched 10 kHz samples, commands and experiment markers; a CSV
with a header row) are mutated at random: bit flips, overwritten bytes, "interesting"
integers written over length fields, truncation, deleted/inserted/duplicated slices,
splices of two seeds, and for CSV cell-level changes (NaN, inf, 1e999, empty, text,
quotes, a wrong number of cells, another delimiter, non-UTF-8 bytes, duplicated
columns). Each case goes through :func:`hasel.io.load_io` and, for MCAP,
:func:`hasel.io.info`.

Pass criteria: every case ends either with data or with
:class:`~hasel.errors.DataFileError` / :class:`~hasel.errors.BadInputError`; no case
runs longer than the per-case timeout (the worker is killed and the case recorded as
a hang); memory stays bounded (the worker runs under an address-space limit, so a
runaway allocation shows up as MemoryError, a failure; the peak resident size is
reported). Failing inputs are kept (``failures_dir``; ``hasel bench`` puts them beside
its JSON) for the I/O code's authors.

Cases run in a worker process (``python -m hasel_bench.fuzz``, no ROS) that
prints ``S <i>`` before and ``R <i> <status> <detail>`` after each case; the parent
enforces the timeouts and restarts the worker after a hang.
"""
from __future__ import annotations

import json
import os
import resource
import shutil
import subprocess
import sys
import tempfile
import threading
import time
from collections import Counter
from pathlib import Path
from typing import Any

import numpy as np

__all__ = ["make_seeds", "mutate", "run_fuzz", "run_cli_fuzz"]

_EXAMPLES = 3  # failing inputs kept per kind of failure
_INTERESTING = [0, 1, 0x7F, 0xFF, 0x7FFF, 0xFFFF, 0x7FFFFFFF, 0xFFFFFFFF, 2**63 - 1, 2**64 - 1, 2**32, 1 << 40]
_CSV_CELLS = [b"nan", b"NaN", b"inf", b"-inf", b"1e999", b"-1e999", b"", b"abc", b"0x10", b'"', b'"1,2"', b"1,2",
              b"\x00", b"\xff\xfe", "\u00e9".encode(), b"9" * 400, b"1e-400", b" ", b"--1", b"1.2.3", b"\t"]


def make_seeds(directory: Path, rng: np.random.Generator) -> list[Path]:
    """Write the valid seed files into ``directory``; return their paths."""
    from hasel.io import Ros2McapWriter
    from hasel_bench.iospeed import encode, encode_sample_batch

    directory.mkdir(parents=True, exist_ok=True)
    paths = []
    for comp, chunk in (("zstd", 4096), ("none", 2048)):
        path = directory / f"seed_{comp}.mcap"
        with Ros2McapWriter(path, compression=comp, chunk_size=chunk, fsync_interval_s=None) as w:
            b = w.add_topic("/plant/batch", "hasel_msgs/msg/SampleBatch")
            a = w.add_topic("/amp/applied", "hasel_msgs/msg/VoltageCommand")
            m = w.add_topic("/markers", "hasel_msgs/msg/ExperimentMarker")
            for i, (label, start) in enumerate([("excitation", True), ("excitation", False)]):
                t = 10**9 + i * 40 * 5_000_000
                w.write(m, encode("hasel_msgs/msg/ExperimentMarker", {
                    "header": {"stamp": {"sec": t // 10**9, "nanosec": t % 10**9}}, "label": label,
                    "signal": "paper", "offset_kv": 4.0, "amplitude_kv": 1.0, "f0_hz": 0.1, "f1_hz": 20.0,
                    "duration_s": 0.2, "start": start}), t, t)
            for i in range(40):
                t = 10**9 + i * 5_000_000
                v = 4.0 + np.sin(0.01 * np.arange(i * 50, (i + 1) * 50))
                y = 0.4 * v + 0.001 * rng.standard_normal(50)
                w.write(b, encode_sample_batch(t, 1e-4, v, y, y, 100.0 + y), t, t, i)
                w.write(a, encode("hasel_msgs/msg/VoltageCommand", {
                    "header": {"stamp": {"sec": t // 10**9, "nanosec": t % 10**9}}, "requested_kv": float(v[0]),
                    "applied_kv": float(v[0])}), t, t, i)
        paths.append(path)
    path = directory / "seed.csv"
    t = np.arange(400) * 1e-3
    v = 4.0 + np.sin(2 * np.pi * 5 * t)
    y = 0.4 * v + 0.001 * rng.standard_normal(t.size)
    with open(path, "w") as fh:
        fh.write("t_s,voltage_kv,stroke_mm\n")
        for row in zip(t, v, y):
            fh.write(",".join(f"{x:.9g}" for x in row) + "\n")
    paths.append(path)
    return paths


def _mutate_bytes(data: bytearray, rng: np.random.Generator, other: bytes) -> bytearray:
    n = len(data)
    op = int(rng.integers(9))
    if n == 0:
        return bytearray(rng.bytes(int(rng.integers(1, 64))))
    pos = int(rng.integers(n))
    if op == 0:  # bit flips
        for _ in range(int(rng.integers(1, 9))):
            p = int(rng.integers(n))
            data[p] ^= 1 << int(rng.integers(8))
    elif op == 1:  # random bytes over a few positions
        k = int(rng.integers(1, 17))
        data[pos:pos + k] = rng.bytes(min(k, n - pos))
    elif op == 2:  # an interesting integer over a (length) field
        width = int(rng.choice([1, 2, 4, 8]))
        val = int(rng.choice(_INTERESTING)) & ((1 << (8 * width)) - 1)
        data[pos:pos + width] = val.to_bytes(width, "little")[:max(0, n - pos)]
    elif op == 3:  # truncation
        del data[pos:]
    elif op == 4:  # delete a slice
        del data[pos:pos + int(rng.integers(1, 256))]
    elif op == 5:  # insert random bytes
        data[pos:pos] = rng.bytes(int(rng.integers(1, 64)))
    elif op == 6:  # duplicate a slice elsewhere
        a = int(rng.integers(n))
        seg = bytes(data[a:a + int(rng.integers(1, 512))])
        data[pos:pos] = seg
    elif op == 7:  # splice with another seed
        cut = int(rng.integers(len(other))) if other else 0
        data[pos:] = other[cut:]
    else:  # zero a region
        k = int(rng.integers(1, 128))
        data[pos:pos + k] = bytes(min(k, n - pos))
    return data


def _mutate_csv(data: bytearray, rng: np.random.Generator) -> bytearray:
    lines = bytes(data).split(b"\n")
    op = int(rng.integers(7))
    i = int(rng.integers(len(lines)))
    cells = lines[i].split(b",")
    if op == 0:  # replace a cell
        cells[int(rng.integers(len(cells)))] = _CSV_CELLS[int(rng.integers(len(_CSV_CELLS)))]
        lines[i] = b",".join(cells)
    elif op == 1:  # drop or add a cell
        if rng.random() < 0.5 and len(cells) > 1:
            del cells[int(rng.integers(len(cells)))]
        else:
            cells.append(b"1")
        lines[i] = b",".join(cells)
    elif op == 2:  # another delimiter in part of the file
        lines[i:] = [ln.replace(b",", rng.choice([b";", b"\t", b" "])) for ln in lines[i:]]
    elif op == 3:  # header changes: duplicate, rename, drop
        head = lines[0].split(b",")
        j = int(rng.integers(len(head)))
        head[j] = rng.choice([head[(j + 1) % len(head)], b"", b"x", b"\xff", b"t_s"])
        lines[0] = b",".join(head)
    elif op == 4:  # blank lines, CRLF, comment
        lines.insert(i, rng.choice([b"", b"\r", b"# comment", b",,", b"\x00"]))
    elif op == 5:  # time goes backwards or repeats
        if i > 0 and len(cells) > 0:
            cells[0] = rng.choice([b"0", b"-1", lines[max(1, i - 1)].split(b",")[0], b"1e300"])
            lines[i] = b",".join(cells)
    else:  # keep only a few rows
        lines = lines[:int(rng.integers(1, 12))]
    return bytearray(b"\n".join(lines))


def mutate(seed: bytes, suffix: str, rng: np.random.Generator, other: bytes) -> bytes:
    """One fuzz case: 1-3 stacked mutations of ``seed`` (cell-level ones too for CSV)."""
    data = bytearray(seed)
    for _ in range(int(rng.integers(1, 4))):
        if suffix == ".csv" and rng.random() < 0.6:
            data = _mutate_csv(data, rng)
        else:
            data = _mutate_bytes(data, rng, other)
    return bytes(data)


# -- worker ------------------------------------------------------------------------------

def _peak_rss_kib() -> int:
    """Peak resident size of this process image, KiB (VmHWM; ru_maxrss would count the forked parent)."""
    try:
        with open("/proc/self/status") as fh:
            for line in fh:
                if line.startswith("VmHWM:"):
                    return int(line.split()[1])
    except OSError:
        pass
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss


def _worker(seed_dir: str, work_dir: str, start: int, master: int, deadline: float, mem_limit: int) -> int:
    import warnings

    from hasel.errors import BadInputError
    from hasel.io import info, load_io

    if mem_limit > 0:
        resource.setrlimit(resource.RLIMIT_AS, (mem_limit, mem_limit))
    warnings.simplefilter("ignore")
    seeds = [(p.suffix, p.read_bytes()) for p in sorted(Path(seed_dir).iterdir())]
    base_rss = _peak_rss_kib()
    out = sys.stdout
    i = start
    while time.monotonic() < deadline:
        rng = np.random.default_rng([master, i])
        k = int(rng.integers(len(seeds)))
        suffix, seed = seeds[k]
        other = seeds[int(rng.integers(len(seeds)))][1]
        path = Path(work_dir) / f"case{suffix}"
        path.write_bytes(mutate(seed, suffix, rng, other))
        out.write(f"S {i} {suffix}\n")
        out.flush()
        status, detail = "ok", ""
        try:
            load_io(path)
            if suffix == ".mcap":
                info(path)
        except BadInputError as err:  # DataFileError is one
            status, detail = "rejected", type(err).__name__
        except BaseException as err:  # noqa: BLE001 - every other exception is a finding
            status, detail = "crash", f"{type(err).__name__}: {str(err)[:160]}".replace("\n", " ")
        out.write(f"R {i} {status} {detail}\n")
        out.flush()
        i += 1
    peak = _peak_rss_kib()
    out.write(f"D {i} {base_rss} {peak}\n")
    out.flush()
    return 0


def run_fuzz(budget_s: float, case_timeout_s: float = 5.0, seed: int = 0, mem_limit_mib: int = 3072,
             failures_dir: str | os.PathLike[str] | None = None, progress=None) -> dict[str, Any]:
    """Fuzz the loaders for ``budget_s`` seconds of wall time.

    Returns
    -------
    dict
        ``cases``, ``ok``, ``rejected`` (DataFileError/BadInputError), ``crashed`` (any other
        exception, or the worker died), ``crashes_by_type`` (``"<suffix> <exception>"`` ->
        count), ``crash_examples`` and ``hangs`` (lists of ``{"case", "suffix", "detail",
        "file"}``, a few examples per kind), ``rejected_by_type``,
        ``peak_rss_mib``, ``rss_growth_mib`` (peak minus the worker's resident size after
        its imports), ``mem_limit_mib``, ``case_timeout_s``, ``restarts``, ``wall_s``.
    """
    say = progress or (lambda m: None)
    t0 = time.monotonic()
    deadline = t0 + budget_s
    tmp = Path(tempfile.mkdtemp(prefix="hasel-fuzz-"))
    fail_dir = Path(failures_dir) if failures_dir else None
    counts: Counter = Counter()
    rejected_types: Counter = Counter()
    crash_types: Counter = Counter()
    crashes: list[dict] = []
    hangs: list[dict] = []
    peak_kib = 0
    growth_kib = 0
    restarts = 0
    next_case = 0
    env = dict(os.environ)
    env["OPENBLAS_NUM_THREADS"] = "1"

    def keep(case: int, suffix: str, src: Path) -> str:
        if fail_dir is None or not src.exists():
            return ""
        fail_dir.mkdir(parents=True, exist_ok=True)
        dst = fail_dir / f"case{case}{suffix}"
        shutil.copyfile(src, dst)
        return str(dst)

    try:
        seed_dir = tmp / "seeds"
        make_seeds(seed_dir, np.random.default_rng(seed))
        while time.monotonic() < deadline - 0.5:
            work = tmp / f"w{restarts}"
            work.mkdir()
            proc = subprocess.Popen([sys.executable, "-m", "hasel_bench.fuzz", str(seed_dir), str(work),
                                     str(next_case), str(seed), repr(deadline), str(mem_limit_mib * 2**20)],
                                    stdout=subprocess.PIPE, text=True, env=env)
            lines: list[str] = []
            cond = threading.Condition()

            def pump(p=proc, buf=lines, c=cond) -> None:
                for ln in p.stdout:
                    with c:
                        buf.append(ln)
                        c.notify()
                with c:
                    buf.append("")
                    c.notify()

            threading.Thread(target=pump, daemon=True).start()
            current: tuple[int, str] | None = None
            started = time.monotonic()
            finished = False
            while True:
                with cond:
                    limit = (started + case_timeout_s) if current else max(deadline + 30.0, time.monotonic() + 30.0)
                    while not lines and time.monotonic() < limit:
                        cond.wait(0.05)
                    ln = lines.pop(0) if lines else None
                if ln is None:  # no line in time: a hang (or a stuck start-up)
                    proc.kill()
                    proc.wait()
                    if current is not None:
                        hangs.append({"case": current[0], "suffix": current[1], "detail": f"> {case_timeout_s} s",
                                      "file": keep(current[0], current[1], work / f"case{current[1]}")})
                        next_case = current[0] + 1
                        say(f"fuzz: case {current[0]} hung (> {case_timeout_s} s); worker restarted")
                    break
                if ln == "":  # the worker died (a crash of the interpreter, or the memory limit)
                    rc = proc.wait()
                    if current is not None:
                        crash_types[f"{current[1]} worker died"] += 1
                        crashes.append({"case": current[0], "suffix": current[1], "detail": f"worker died ({rc})",
                                        "file": keep(current[0], current[1], work / f"case{current[1]}")})
                        next_case = current[0] + 1
                    finished = current is None
                    break
                parts = ln.rstrip("\n").split(" ", 3)
                if parts[0] == "S":
                    current, started = (int(parts[1]), parts[2]), time.monotonic()
                elif parts[0] == "R":
                    case, status = int(parts[1]), parts[2]
                    detail = parts[3] if len(parts) > 3 else ""
                    counts[status] += 1
                    if status == "rejected":
                        rejected_types[detail] += 1
                    elif status == "crash":
                        suffix = current[1] if current else ""
                        kind = detail.split(":", 1)[0]
                        crash_types[f"{suffix} {kind}"] += 1
                        if crash_types[f"{suffix} {kind}"] <= _EXAMPLES:
                            crashes.append({"case": case, "suffix": suffix, "detail": detail,
                                            "file": keep(case, suffix, work / f"case{suffix}")})
                    current = None
                    next_case = case + 1
                elif parts[0] == "D":
                    base, peak = int(parts[2]), int(parts[3])
                    peak_kib = max(peak_kib, peak)
                    growth_kib = max(growth_kib, peak - base)
                    finished = True
            proc.wait()
            if finished:
                break
            restarts += 1
    finally:
        shutil.rmtree(tmp, ignore_errors=True)
    died = sum(v for k, v in crash_types.items() if k.endswith("worker died"))
    n = sum(counts.values()) + len(hangs) + died
    return {"cases": n, "ok": counts["ok"], "rejected": counts["rejected"], "crashed": counts["crash"] + died,
            "crashes_by_type": dict(crash_types), "crash_examples": crashes, "hangs": hangs,
            "rejected_by_type": dict(rejected_types), "peak_rss_mib": peak_kib / 1024,
            "rss_growth_mib": growth_kib / 1024, "mem_limit_mib": mem_limit_mib, "case_timeout_s": case_timeout_s,
            "restarts": restarts, "wall_s": time.monotonic() - t0}



def run_cli_fuzz(scale: float = 4.0, root: str | os.PathLike[str] | None = None, timeout_s: float = 3600.0,
                 progress=None) -> dict[str, Any]:
    """Run the CLI fuzzer (``test/test_cli_fuzz.py``) with ``scale`` times the cases of ``make test``.

    Random argument lists for every subcommand, damaged files for every file argument
    and random node parameters, not derandomized (new cases each run). Returns
    ``cases`` (total tried), ``by_command`` (``"<command> exit <code>"`` -> count),
    ``examples`` (one argument list and last stderr line per kind of ending),
    ``passed`` (every promise kept), ``failure`` (pytest's last lines if not) and ``wall_s``.
    """
    say = progress or (lambda m: None)
    # the workspace: given, or the first parent (of this installed file, then of the cwd) holding the test
    here = [Path(root)] if root else [*Path(__file__).resolve().parents, Path.cwd(), *Path.cwd().parents]
    base = next((p for p in here if (p / "test" / "test_cli_fuzz.py").is_file()), here[0])
    report = Path(tempfile.mkdtemp(prefix="hasel-clifuzz-")) / "report.json"
    env = {**os.environ, "HASEL_CLI_FUZZ_SCALE": f"{scale:g}", "HASEL_CLI_FUZZ_REPORT": str(report)}
    env.pop("HASEL_ROS_ENV_READY", None)
    t0 = time.monotonic()
    say(f"CLI fuzzer: {scale:g} x the cases of make test")
    proc = subprocess.run([sys.executable, "-m", "pytest", "-q", "-x", "-p", "no:cacheprovider",
                           str(base / "test" / "test_cli_fuzz.py")], cwd=base, env=env, capture_output=True,
                          text=True, timeout=timeout_s)
    doc = json.loads(report.read_text()) if report.exists() else {"cases": {}, "examples": {}}
    shutil.rmtree(report.parent, ignore_errors=True)
    cases = sum(doc["cases"].values())
    say(f"CLI fuzzer: {cases} cases tried, {'all promises kept' if proc.returncode == 0 else 'FAILED'}")
    return {"cases": cases, "by_command": doc["cases"], "examples": doc["examples"], "passed": proc.returncode == 0,
            "failure": "" if proc.returncode == 0 else "\n".join(proc.stdout.splitlines()[-40:]),
            "wall_s": time.monotonic() - t0}


if __name__ == "__main__":
    a = sys.argv[1:]
    sys.exit(_worker(a[0], a[1], int(a[2]), int(a[3]), float(a[4]), int(a[5])))
