"""False-rejection rate of the offset-dependence test on linear time-invariant logs (src/tests/designs.py).

Usage: python bench/tune_ident/false_rejection.py [--seeds 7] [--rate 200] [--designs a,b] [--opt NAME=VALUE ...]
Every log is effect-free P(s), so every rejection at p < 0.05 is false.
"""
from __future__ import annotations

import argparse
import os
import sys

sys.path.insert(0, os.path.join(os.path.dirname(__file__), "..", "..", "src", "tests"))
import designs  # noqa: E402

from hasel.ident import identify  # noqa: E402

DESIGNS = ("paper_chirp", "paper_chirp3", "linear_chirp", "log_chirp", "multisine", "prbs")


def main() -> int:
    ap = argparse.ArgumentParser()
    ap.add_argument("--seeds", type=int, default=7)
    ap.add_argument("--rate", type=float, default=200.0)
    ap.add_argument("--designs", default=",".join(DESIGNS))
    ap.add_argument("--opt", action="append", default=[], metavar="NAME=VALUE",
                    help="an identify option (Python literal), e.g. --opt drift_knot_s=0")
    a = ap.parse_args()
    import ast
    opts = {kv.split("=", 1)[0]: ast.literal_eval(kv.split("=", 1)[1]) for kv in a.opt}
    n = rej = 0
    for seed in range(a.seeds):
        for d in a.designs.split(","):
            log = designs.make_log(d, a.rate, seed=100 + seed, precondition=bool(seed % 2), settle_s=0.5 * (seed % 3))
            r = identify(log.t_s, log.u_kv, log.y_mm, input_name="voltage_kv", output_name="stroke_mm", **opts)
            p = r.dependence.p_value
            if p != p:  # nan: untestable
                print(f"{d:14s} seed {seed}: untestable", flush=True)
                continue
            n += 1
            rej += p < 0.05
            print(f"{d:14s} seed {seed}: p = {p:.3f} {'REJECT' if p < 0.05 else ''}", flush=True)
    print(f"false rejections at p < 0.05: {rej} of {n} ({100.0 * rej / max(n, 1):.1f} %)")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
