"""Check 8's thresholds swept on check8_dump.py's pickles: good / wrong yet usable / right yet refused.

Usage: python bench/tune_ident/check8_eval.py Z REL SHARE RUN A.pkl [B.pkl ...]   (Z = 1e10: check 8 off)
The other checks' outcome is the stored one; check 8 is rerun on the stored error response. ALL=1 prints every row.
"""
import pickle, sys, math
import numpy as np
from hasel.ident import checks as C
Z, REL, SHARE, RUN = [float(x) for x in sys.argv[1:5]]
files = sys.argv[5:]
tally = {}
rows = []
for fn in files:
    for d in pickle.load(open(fn, "rb")):
        r = d["r"]
        other = [x for x in r.reasons if not x.startswith("the model's residual") and not x.startswith("the model disagrees with the data")]
        reasons, fixes, det = [], [], {}
        old = (C.RESID_Z, C.RESID_REL_TOL, C.RESID_MAX_SHARE, C.RESID_MAX_RUN_OCTAVES)
        C.RESID_Z, C.RESID_REL_TOL, C.RESID_MAX_SHARE, C.RESID_MAX_RUN_OCTAVES = Z, REL, SHARE, RUN
        if d["resid"] is not None and Z < 1e9:
            C._residual_bias(r.model, d["resid"], r.band_hz, reasons, fixes, det)
        C.RESID_Z, C.RESID_REL_TOL, C.RESID_MAX_SHARE, C.RESID_MAX_RUN_OCTAVES = old
        usable = not (other or reasons)
        good = d["cmp"]["max_db"] <= 1.0 and d["cmp"]["max_deg"] <= 5.0
        key = ("good" if usable else "right_refused") if good else ("wrong_usable" if usable else "wrong_refused")
        tally[key] = tally.get(key, 0) + 1
        rows.append((d["seed"], d["design"], d["rate"], d["k"], d["cmp"]["max_db"], d["cmp"]["max_deg"], key, det.get("residual_disagreeing_share"), det.get("residual_longest_run_octaves"), (reasons or other or [""])[0][:150]))
for row in rows:
    import os
    if row[6] != "good" or os.environ.get("ALL"):
        print("%d %-13s %6.0f %d %6.2f %6.1f %-14s share=%s run=%s | %s" % row)
print(tally, sum(tally.values()))
import collections
grp = collections.defaultdict(lambda: collections.Counter())
for row in rows:
    g = f"seed {row[0]}, " + ("10 kHz" if row[2] == 10000 else "200 Hz + 1 kHz")
    grp[g][row[6]] += 1
for g, c in sorted(grp.items()):
    print(g, dict(c))
