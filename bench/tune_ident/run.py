"""Identification on effect-free logs of every design (src/tests/designs.py): error vs P(s), checks, time.

Usage: python bench/tune_ident/run.py [--rates 1000,200] [--designs a,b] [--seeds 0] [--precondition]
Prints one row per log: max dB / deg error over 0.1-15 Hz, G(0), usable, offset-test p, seconds.
"""
from __future__ import annotations

import argparse
import os
import sys
import time

import numpy as np

sys.path.insert(0, os.path.join(os.path.dirname(__file__), "..", "..", "src", "tests"))
import designs  # noqa: E402

from hasel.ident import identify  # noqa: E402


def main() -> int:
    ap = argparse.ArgumentParser()
    ap.add_argument("--rates", default="1000,200")
    ap.add_argument("--designs", default=",".join(designs.DESIGNS))
    ap.add_argument("--seeds", default="0")
    ap.add_argument("--precondition", action="store_true")
    ap.add_argument("--settle", type=float, default=0.5)
    a = ap.parse_args()
    print(f"{'design':14s} {'rate':>6s} {'seed':>4s} {'max_dB':>8s} {'max_deg':>8s} {'G0':>8s} {'usable':>6s} "
          f"{'dep_p':>7s} {'fit%':>7s} {'s':>6s}  order")
    for rate in [float(r) for r in a.rates.split(",")]:
        for d in a.designs.split(","):
            for seed in [int(s) for s in a.seeds.split(",")]:
                log = designs.make_log(d, rate, seed=seed, precondition=a.precondition, settle_s=a.settle)
                t0 = time.perf_counter()
                try:
                    r = identify(log.t_s, log.u_kv, log.y_mm, input_name="voltage_kv", output_name="stroke_mm")
                except Exception as err:  # report every failure in the table
                    print(f"{d:14s} {rate:6.0f} {seed:4d} ERROR {type(err).__name__}: {err}")
                    continue
                dt = time.perf_counter() - t0
                c = r.paper_comparison()
                usable = getattr(r, "usable", None)
                fit = r.validation.compare_fit_pct if r.validation is not None else float("nan")
                print(f"{d:14s} {rate:6.0f} {seed:4d} {c['max_db']:8.3f} {c['max_deg']:8.2f} {r.model.dc_gain:8.4g} "
                      f"{str(usable):>6s} {r.dependence.p_value:7.3f} {fit:7.1f} {dt:6.2f}  "
                      f"{r.fit.nz}/{r.fit.np} {'; '.join(getattr(r, 'reasons', []) or [])}", flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
