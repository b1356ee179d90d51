"""Wall time of identify on drawn tuning logs (varied.py specs), for two source trees in one run, alternately.

Usage: python bench/tune_ident/speed_cases.py --before DIR_WITH_hasel SPEC [SPEC ...] [--repeat 3]
SPEC as diag_logs.py: ``SEED:DESIGN:RATE:K`` (a varied.py drawn log) or ``wSEED:CASE`` (a ``--widened`` case).
``speed.py`` times seed-0 logs with default conditions only; this times the logs a change is about (e.g. those
whose timing criteria disagree). Each tree runs in its own process; the best of ``--repeat`` runs is kept.
Prints seconds per log (s) and the ratio before/after, then the ratio of the sums.
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
sys.path.insert(0, sys.argv[1]); sys.path.insert(0, sys.argv[2]); sys.path.insert(0, sys.argv[3])
import diag_logs
from hasel.ident import identify
label, log, c = diag_logs.log_of(sys.argv[4])
t0 = time.perf_counter()
r = identify(log.t_s, log.u_kv, log.y_mm, input_name="voltage_kv", output_name="stroke_mm")
print(json.dumps({"s": time.perf_counter() - t0, "usable": bool(r.usable)}))
"""


def _time(tree: str, spec: str) -> float:
    """Seconds of one identify run of ``spec`` with the ``hasel`` package under ``tree``."""
    out = subprocess.run([sys.executable, "-W", "ignore", "-c", CHILD, tree, HERE,
                          os.path.join(HERE, "..", "..", "src", "tests"), spec],
                         capture_output=True, text=True, check=True)
    return float(json.loads(out.stdout.strip().splitlines()[-1])["s"])


def main() -> int:
    """Time each SPEC with both trees (see the module)."""
    ap = argparse.ArgumentParser()
    ap.add_argument("--before", required=True)
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("specs", nargs="+")
    a = ap.parse_args()
    after_tree = os.path.join(HERE, "..", "..", "src")
    tot = {"before": 0.0, "after": 0.0}
    for spec in a.specs:
        best = {"before": float("inf"), "after": float("inf")}
        for _ in range(a.repeat):
            for name, tree in (("before", a.before), ("after", after_tree)):
                best[name] = min(best[name], _time(tree, spec))
        for k in tot:
            tot[k] += best[k]
        print(f"{spec}: before {best['before']:.2f} s, after {best['after']:.2f} s, "
              f"ratio before/after {best['before'] / best['after']:.2f}", flush=True)
    print(f"sum: before {tot['before']:.2f} s, after {tot['after']:.2f} s, ratio before/after "
          f"{tot['before'] / tot['after']:.2f}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
