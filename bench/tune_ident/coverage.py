"""Coverage of check 6's 95 % response bound, measured on repeated-noise tuning logs.

For each design of ``src/tests/designs.py`` (at one rate, with the measurement
conditions that ``varied.py --seed S`` draws for it, ``k = 0``) the same excitation is
logged ``--draws`` times with independent noise draws (closed loop: the noise also
moves the input). Each log is identified with the default options; the
output-error fit's response bound (``hasel.ident.timefit.response_uncertainty``,
times ``SPREAD_Z``) is recorded at check 6's grid with the TRUE error of the fitted
model against P(s) (:mod:`hasel.paper`) there.

Per design and frequency band it prints:

- ``cov_dB`` / ``cov_deg``: the share of (fit, frequency) pairs whose true error lies
  inside the claimed bound (a calibrated 95 % bound: about 0.95);
- ``u/sd``: the claimed standard error over the empirical spread of the estimates
  across the draws (1 when the covariance is right; a bias is not in it);
- ``bias``: the mean error across draws in empirical standard deviations;
- ``u95_dB`` / ``u95_deg``: the median claimed bound, ``|e|dB`` / ``|e|deg`` the median true error;
- the chosen orders and how many fits check 6 refused.

``u/sd`` and ``bias`` are taken over the fits of the most frequent order.

Variants of the covariance (``--variants``) are computed on the same fits beside the
one ``identify`` uses: ``cl=S`` cluster length S seconds; ``shift=est`` / ``shift=all``
the timing offset as a parameter of the covariance when the fit estimated one / always.

Usage: python bench/tune_ident/coverage.py [--rate 1000] [--designs a,b] [--draws 12] [--seed 1]
       [--variants cl=2,cl=0.05,cl=5]
"""
from __future__ import annotations

import argparse
import os
import sys

import numpy as np

sys.path.insert(0, os.path.join(os.path.dirname(__file__), "..", "..", "src", "tests"))
sys.path.insert(0, os.path.dirname(__file__))
import designs  # noqa: E402
import varied  # noqa: E402

from hasel import paper  # noqa: E402
from hasel.ident import identify  # noqa: E402
from hasel.ident.checks import SPREAD_Z  # noqa: E402

idmod = sys.modules["hasel.ident.identify"]

BANDS = ((0.0, 1.0), (1.0, 5.0), (5.0, 10.0), (10.0, 1e9))


def _log(design: str, rate: float, cond: dict, seed: int, k: int) -> designs.Log:
    """The log of ``design`` with the excitation of ``seed`` and noise draw ``k`` (mm, kV, s)."""
    if design == "closed_loop":
        return designs.make_log(design, rate, seed=seed * 1000 + k, **cond)
    quiet = dict(cond, noise_mm=0.0, lsb_mm=0.0)
    clean = designs.make_log(design, rate, seed=seed, **quiet)
    rng = np.random.default_rng([seed, k, 99])
    y = clean.y_mm + designs._noise(rng, clean.y_mm.size, rate, cond["noise_mm"], cond["noise_kind"],
                                    cond["noise_fc_hz"])
    if cond["lsb_mm"] > 0:
        y = np.round(y / cond["lsb_mm"]) * cond["lsb_mm"]
    return designs.Log(clean.t_s, clean.u_kv, y, design, rate, clean.meta)


def main() -> int:
    ap = argparse.ArgumentParser()
    ap.add_argument("--rate", type=float, default=1000.0)
    ap.add_argument("--designs", default=",".join(designs.DESIGNS))
    ap.add_argument("--draws", type=int, default=12)
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--k", type=int, default=0, help="which of varied.py's draws of conditions (its k)")
    ap.add_argument("--variants", default="", help="comma list of cl=SECONDS (cluster length), shift=est (the timing offset's column when the "
                                        "fit estimated one), shift=all (always)")
    ap.add_argument("--opt", action="append", default=[], metavar="NAME=VALUE")
    a = ap.parse_args()
    import ast
    opts = {kv.split("=", 1)[0]: ast.literal_eval(kv.split("=", 1)[1]) for kv in a.opt}
    variants = [v for v in a.variants.split(",") if v]
    num, den = paper.plant_tf()
    orig = idmod.response_uncertainty
    rec: dict = {}

    def wrapped(oe, u, y, rate_hz, pieces, f_hz, **kw):
        out = orig(oe, u, y, rate_hz, pieces, f_hz, **kw)
        if "f" in rec:          # the tied rivals' calls after the chosen model's
            return out
        rec["f"] = np.asarray(f_hz, float)
        rec["sd"] = out
        for v in variants:
            name, val = v.split("=")
            kv = dict(kw)
            if name == "cl":
                kv["cluster_s"] = float(val)
            elif name == "shift":      # the timing offset's column in the covariance (when the fit moved it)
                kv["max_shift"] = 1.0 if (val == "all" or oe.shift != 0.0) else 0.0
            rec[v] = orig(oe, u, y, rate_hz, pieces, f_hz, **kv)
        s = 2j * np.pi * rec["f"]
        q = (np.polyval(oe.model.num, s) / np.polyval(oe.model.den, s)) / (np.polyval(num, s) / np.polyval(den, s))
        rec["err"] = (20 * np.log10(np.abs(q)), np.degrees(np.angle(q)))
        return out

    idmod.response_uncertainty = wrapped
    print(f"# coverage.py --rate {a.rate:g} --draws {a.draws} --seed {a.seed} {'--variants ' + a.variants if variants else ''}")
    print(f"{'design':14s} {'band_hz':>9s} {'variant':>8s} {'cov_dB':>6s} {'cov_deg':>7s} {'u/sd_dB':>7s} "
          f"{'u/sd_deg':>8s} {'bias_dB':>7s} {'bias_deg':>8s} {'u95_dB':>6s} {'u95_deg':>7s} {'|e|dB':>6s} {'|e|deg':>6s}"
          "  n  orders / check6-refused")
    totals: dict = {}
    for di, d in enumerate(a.designs.split(",")):
        di_all = list(designs.DESIGNS).index(d)
        cond = varied.draw(np.random.default_rng([a.seed, int(a.rate), di_all, a.k]))
        cond.pop("settle_s")
        seed = int(np.random.default_rng([a.seed, int(a.rate), di_all, a.k, 5]).integers(1 << 30))
        fits = []
        for k in range(a.draws):
            log = _log(d, a.rate, dict(cond, settle_s=1.0), seed, k)
            rec.clear()
            try:
                r = identify(log.t_s, log.u_kv, log.y_mm, input_name="voltage_kv", output_name="stroke_mm", **opts)
            except Exception as err:  # noqa: BLE001 - a bench: count and go on
                print(f"{d}: draw {k} failed: {err}", flush=True)
                continue
            if "f" not in rec or rec["sd"] is None:
                continue
            c6 = any("pin the response" in x for x in r.reasons)
            fits.append((dict(rec), f"{r.fit.nz}/{r.fit.np}", c6))
        if not fits:
            continue
        orders = {}
        for _, o, _ in fits:
            orders[o] = orders.get(o, 0) + 1
        n6 = sum(c for _, _, c in fits)
        # a common grid: each fit's grid, binned
        for lo, hi in BANDS:
            for v in ["sd"] + variants:
                e_db, e_deg, s_db, s_deg = [], [], [], []
                for rc, _, _ in fits:
                    sd = rc.get(v)
                    if sd is None:
                        continue
                    m = (rc["f"] >= lo) & (rc["f"] < hi)
                    e_db.append(rc["err"][0][m])
                    e_deg.append(rc["err"][1][m])
                    s_db.append(sd[0][m])
                    s_deg.append(sd[1][m])
                if not e_db or sum(x.size for x in e_db) == 0:
                    continue
                # per-frequency statistics need the same grid across draws: interpolate on log f
                ed, eg, sd_, sg = (np.concatenate(x) for x in (e_db, e_deg, s_db, s_deg))
                cov_db = float(np.mean(np.abs(ed) <= SPREAD_Z * sd_))
                cov_deg = float(np.mean(np.abs(eg) <= SPREAD_Z * sg))
                # empirical spread across draws at a few common frequencies of this band
                fs = np.geomspace(max(lo, 0.12), min(hi, 16.0), 5) if hi > lo else np.zeros(0)
                ratio_db, ratio_deg, b_db, b_deg = [], [], [], []
                modal = max(orders, key=orders.get)
                for f0 in fs:
                    vals = []
                    for rc, o, _ in fits:
                        if o != modal:
                            continue
                        sd = rc.get(v)
                        f = rc["f"]
                        if sd is None or f0 < f[0] or f0 > f[-1]:
                            continue
                        lf = np.log(f)
                        vals.append([np.interp(np.log(f0), lf, rc["err"][0]), np.interp(np.log(f0), lf, rc["err"][1]),
                                     np.interp(np.log(f0), lf, sd[0]), np.interp(np.log(f0), lf, sd[1])])
                    if len(vals) < 4:
                        continue
                    vals = np.array(vals)
                    emp = vals[:, :2].std(axis=0, ddof=1)
                    ratio_db.append(np.median(vals[:, 2]) / max(emp[0], 1e-12))
                    ratio_deg.append(np.median(vals[:, 3]) / max(emp[1], 1e-12))
                    b_db.append(abs(vals[:, 0].mean()) / max(emp[0], 1e-12))
                    b_deg.append(abs(vals[:, 1].mean()) / max(emp[1], 1e-12))
                med = lambda x: float(np.median(x)) if x else float("nan")  # noqa: E731
                print(f"{d:14s} {lo:4.3g}-{min(hi, 99):<4.3g} {v if v != 'sd' else 'used':>8s} {cov_db:6.2f} "
                      f"{cov_deg:7.2f} {med(ratio_db):7.2f} {med(ratio_deg):8.2f} {med(b_db):7.2f} {med(b_deg):8.2f} "
                      f"{SPREAD_Z * float(np.median(sd_)):6.2f} {SPREAD_Z * float(np.median(sg)):7.2f} "
                      f"{float(np.median(np.abs(ed))):6.2f} {float(np.median(np.abs(eg))):6.2f} "
                      f"{len(e_db):2d}  {orders} / {n6}", flush=True)
                t = totals.setdefault((v, lo), [0, 0, 0])
                t[0] += int(np.sum(np.abs(ed) <= SPREAD_Z * sd_))
                t[1] += int(np.sum(np.abs(eg) <= SPREAD_Z * sg))
                t[2] += ed.size
    for (v, lo), (a_db, a_deg, n) in sorted(totals.items()):
        print(f"ALL band from {lo:g} Hz, {v if v != 'sd' else 'used'}: coverage dB {a_db / n:.2f}, deg {a_deg / n:.2f} "
              f"({n} fit-frequency pairs)")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
