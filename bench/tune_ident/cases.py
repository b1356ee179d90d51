"""Rerun single logs of ``varied.py`` (same draws) and print the outcome, the timing note and the check details.

Usage: python bench/tune_ident/cases.py SEED:DESIGN:RATE:K [...] [--opt NAME=VALUE ...]
For a quick look at the logs a change is about, without the whole corpus.
"""
from __future__ import annotations

import argparse
import ast
import os
import sys

import numpy as np

sys.path.insert(0, os.path.dirname(__file__))
sys.path.insert(0, os.path.join(os.path.dirname(__file__), "..", "..", "src", "tests"))
import designs  # noqa: E402
from varied import draw  # noqa: E402

from hasel.ident import identify  # noqa: E402


def main() -> int:
    """Run each named log and print what it gave (tolerance 1 dB / 5 deg as ``varied.py``)."""
    ap = argparse.ArgumentParser()
    ap.add_argument("cases", nargs="+")
    ap.add_argument("--opt", action="append", default=[])
    a = ap.parse_args()
    opts = {kv.split("=", 1)[0]: ast.literal_eval(kv.split("=", 1)[1]) for kv in a.opt}
    for case in a.cases:
        seed, d, rate, k = case.split(":")
        rate, k, seed = float(rate), int(k), int(seed)
        di = designs.DESIGNS.index(d)
        rng = np.random.default_rng([seed, int(rate), di, k])
        c = draw(rng)
        log = designs.make_log(d, rate, seed=int(rng.integers(1 << 30)), **c)
        r = identify(log.t_s, log.u_kv, log.y_mm, input_name="voltage_kv", output_name="stroke_mm", **opts)
        cm = r.paper_comparison()
        good = cm["max_db"] <= 1.0 and cm["max_deg"] <= 5.0
        # the data follow P(s) exp(-s tau): a first-order hold or a mid-sample reading leads by half a sample,
        # offset_samples delays the output
        true_shift = (-0.5 if c["convention"] in ("centred", "foh") else 0.0) + c["offset_samples"]
        print(f"== {case} {c['convention']} off={c['offset_samples']:+.2f} (true tau {true_shift:+.2f} samples, "
              f"{1e3 * true_shift / rate:+.3g} ms) {c['noise_kind']} {c['noise_mm']:.3f}mm: "
              f"{cm['max_db']:.2f} dB {cm['max_deg']:.1f} deg order {r.fit.nz}/{r.fit.np} usable={r.usable} "
              f"{'GOOD' if good and r.usable else 'RIGHT_REFUSED' if good else 'WRONG_USABLE' if r.usable else 'wrong_refused'}")
        print("   timing_offset_s", r.to_model_json().get("timing_offset_s"))
        for n in r.notes:
            if "timing" in n:
                print("   note:", n)
        for x in r.reasons:
            print("   reason:", x)
        det = r.check.details if r.check is not None else {}
        print("   ", {k2: v for k2, v in det.items() if not isinstance(v, list)})
        sys.stdout.flush()
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
