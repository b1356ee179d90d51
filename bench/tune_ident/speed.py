"""Wall time of identify on one 1 kHz and one 10 kHz log, for two source trees in one run.

Usage: python bench/tune_ident/speed.py [--before DIR_WITH_hasel] [--design paper_chirp3] [--repeat 2]
       [--rates 1000,10000]
``--before`` is a directory holding another version's ``hasel`` package (e.g. from
``git archive BASE src/hasel``); each tree runs in its own process, alternately, and the
best of ``--repeat`` runs is kept. Prints seconds per log and the ratio before/after.
"""
from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys

HERE = os.path.dirname(os.path.abspath(__file__))
CHILD = r"""
import sys, time, json
sys.path.insert(0, sys.argv[1]); sys.path.insert(0, sys.argv[2])
import designs
from hasel.ident import identify
log = designs.make_log(sys.argv[3], float(sys.argv[4]), seed=0)
t0 = time.perf_counter()
r = identify(log.t_s, log.u_kv, log.y_mm, input_name="voltage_kv", output_name="stroke_mm")
print(json.dumps({"s": time.perf_counter() - t0, "stages": r.timings_s}))
"""


def _time(tree: str, design: str, rate: float) -> dict:
    out = subprocess.run([sys.executable, "-W", "ignore", "-c", CHILD, tree,
                          os.path.join(HERE, "..", "..", "src", "tests"), design, str(rate)],
                         capture_output=True, text=True, check=True)
    return json.loads(out.stdout.strip().splitlines()[-1])


def main() -> int:
    ap = argparse.ArgumentParser()
    ap.add_argument("--before", required=True)
    ap.add_argument("--design", default="paper_chirp3")
    ap.add_argument("--repeat", type=int, default=2)
    ap.add_argument("--rates", default="1000,10000")
    a = ap.parse_args()
    after_tree = os.path.join(HERE, "..", "..", "src")
    for rate in [float(r) for r in a.rates.split(",")]:
        best = {"before": float("inf"), "after": float("inf")}
        for _ in range(a.repeat):
            for name, tree in (("before", a.before), ("after", after_tree)):
                best[name] = min(best[name], _time(tree, a.design, rate)["s"])
        print(f"{a.design} {rate:.0f} Hz: before {best['before']:.2f} s, after {best['after']:.2f} s, "
              f"ratio before/after {best['before'] / best['after']:.2f}", flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
