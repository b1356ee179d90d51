"""Why one tuning log's model is wrong yet usable or right yet refused: its error against P(s) and its checks.

Usage: python bench/tune_ident/diag_logs.py SPEC [SPEC ...] [--opt NAME=VALUE ...]
SPEC: ``SEED:DESIGN:RATE:K`` for a varied.py drawn log (seed, design, rate Hz, draw k), or ``wSEED:CASE`` for a
``--widened`` case. Prints per log: order, timing offset (ms), band (Hz), the worst error against the paper's
P(s) over 0.1-15 Hz in dB and deg with its frequency (Hz), the 95 % covariance bound (check 6) at that
frequency and its largest value, the checks' numbers, and the reasons.
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
import varied  # noqa: E402

from hasel.ident import identify  # noqa: E402
from hasel.paper import plant_tf  # noqa: E402


def log_of(spec: str):
    """The (label, log) of ``spec`` (see the module)."""
    f = spec.split(":")
    if f[0].startswith("w"):
        seed, case = int(f[0][1:]), int(f[1])
        d, rate, i, c = varied.widened_cases(seed)[case]
    else:
        seed, d, rate, k = int(f[0]), f[1], float(f[2]), int(f[3])
        di = designs.DESIGNS.index(d)
        rng = np.random.default_rng([seed, int(rate), di, k])
        c = varied.draw(rng)
        c["log_seed"] = int(rng.integers(1 << 30))
    c = dict(c)
    ls = c.pop("log_seed")
    return f"{spec} {d} {rate:g}", designs.make_log(d, rate, seed=ls, **c), c


def main() -> int:
    ap = argparse.ArgumentParser()
    ap.add_argument("specs", nargs="+")
    ap.add_argument("--opt", action="append", default=[])
    a = ap.parse_args()
    opts = {kv.split("=", 1)[0]: ast.literal_eval(kv.split("=", 1)[1]) for kv in a.opt}
    num, den = plant_tf()
    f = np.geomspace(0.1, 15.0, 400)
    P = np.polyval(num, 2j * np.pi * f) / np.polyval(den, 2j * np.pi * f)
    for spec in a.specs:
        label, log, c = log_of(spec)
        r = identify(log.t_s, log.u_kv, log.y_mm, input_name="voltage_kv", output_name="stroke_mm", **opts)
        q = r.fit.model.freqresp(f) / P
        e_db, e_deg = 20 * np.log10(np.abs(q)), np.degrees(np.angle(q))
        idb, ideg = int(np.argmax(np.abs(e_db))), int(np.argmax(np.abs(e_deg)))
        det = r.check.details
        fu = np.asarray(det.get("response_f_hz", []), float)
        ud = np.asarray(det.get("response_u95_deg", []), float)
        ub = np.asarray(det.get("response_u95_db", []), float)
        at = (f"u95 at {f[ideg]:.3g} Hz: +-{np.interp(f[ideg], fu, ub):.2g} dB +-{np.interp(f[ideg], fu, ud):.2g} deg"
              f" (grid {fu[0]:.3g}-{fu[-1]:.3g} Hz, max +-{ub.max():.2g} dB +-{ud.max():.2g} deg)") if fu.size else \
            "no covariance grid"
        print(f"== {label} usable={r.usable} order {r.fit.nz}/{r.fit.np} offset {1e3 * r.timing_offset_s:+.3f} ms "
              f"band {r.band_hz[0]:.3g}-{r.band_hz[1]:.3g} Hz fs {r.analysis_rate_hz:.4g}")
        print(f"   cond {c}")
        print(f"   err {e_db[idb]:+.3f} dB at {f[idb]:.3g} Hz, {e_deg[ideg]:+.2f} deg at {f[ideg]:.3g} Hz; "
              f"err at 5/10/15 Hz: " + ", ".join(f"{np.interp(x, f, e_deg):+.1f}" for x in (5, 10, 15)) + " deg")
        print(f"   {at}")
        print("   details " + ", ".join(f"{k}={v if not isinstance(v, float) else round(v, 4)}"
                                        for k, v in det.items() if not k.startswith("response_")
                                        or k in ("response_u95_max_db", "response_u95_max_deg", "response_checked_hz")))
        for n in r.notes:
            if "timing" in n or "offset" in n or "order" in n:
                print(f"   note: {n[:300]}")
        for x in r.reasons:
            print(f"   REASON: {x}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
