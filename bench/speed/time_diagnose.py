"""Wall and CPU seconds of one ``hasel diagnose`` run, for timing one tree against another.

Usage::

    python bench/speed/time_diagnose.py [--src TREE/src] [--label NAME] -- DIAGNOSE-ARGS...

Runs ``hasel.cli.main(["diagnose", *ARGS])`` in a child Python (``PYTHONPATH`` set to
``--src`` so a second worktree's code can be timed with the same venv) and prints one
JSON line: label, wall seconds, CPU seconds of the child and its workers (user + system),
and the exit code. Start it under ``nice``; other processes on the machine load it too, so
compare only runs made side by side.
"""
from __future__ import annotations

import argparse
import json
import os
import resource
import subprocess
import sys
import time


def main() -> int:
    """Parse the arguments, run the diagnosis once, print the timing as JSON (seconds)."""
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--src", default=None, help="the src/ directory whose hasel is run (default: the installed one)")
    ap.add_argument("--label", default="")
    ap.add_argument("args", nargs=argparse.REMAINDER)
    a = ap.parse_args()
    args = a.args[1:] if a.args[:1] == ["--"] else a.args
    env = dict(os.environ)
    if a.src:
        env["PYTHONPATH"] = os.path.abspath(a.src) + (os.pathsep + env["PYTHONPATH"] if env.get("PYTHONPATH") else "")
    code = "import sys; from hasel.cli import main; sys.exit(main(sys.argv[1:]))"
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    t0 = time.perf_counter()
    rc = subprocess.run([sys.executable, "-c", code, "diagnose", *args], env=env).returncode
    wall = time.perf_counter() - t0
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    cpu = (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)
    print(json.dumps({"label": a.label, "wall_s": round(wall, 2), "cpu_s": round(cpu, 2), "rc": rc}), flush=True)
    return rc


if __name__ == "__main__":
    sys.exit(main())
