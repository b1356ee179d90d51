"""Check 7's tied rivals judged up to 15 Hz (the top of issue 14's tolerance band), from notch_rivals.py's pickle.

Usage: python bench/tune_ident/notch_rivals_eval.py IN.pkl [--rows]
Per log: the largest difference (deg, dB) between the chosen model and a tied rival (each with its own timing
offset) over check 6's grid and over grid top..15 Hz, the combined 95 % uncertainty at the grid's top, and the
rival's own true error. Then the class counts a refusal rule would give (factor x tolerance beyond u95, plain or
widened by 0.1 G(0) / |G|).
"""
import sys, pickle, math
import numpy as np
from hasel.paper import plant_tf

num_p, den_p = plant_tf()
fP = np.geomspace(0.1, 15.0, 400)
P = np.polyval(num_p, 2j * np.pi * fP) / np.polyval(den_p, 2j * np.pi * fP)
res = pickle.load(open(sys.argv[1], "rb"))
rows = []
for x in res:
    c = x["cmp"]
    good = c["max_db"] <= 1.0 and c["max_deg"] <= 5.0
    key = ("good" if x["usable"] else "right_refused") if good else ("WRONG_USABLE" if x["usable"] else "wrong_refused")
    s = x["spread"]
    best = None
    if s is not None and s["f"].size and s["rivals"]:
        f_top = float(s["f"][-1])
        f = np.geomspace(f_top, 15.0, 24) if f_top < 15.0 else np.array([f_top])
        G = np.polyval(s["num"], 2j * np.pi * f) / np.polyval(s["den"], 2j * np.pi * f)
        g0 = abs(s["num"][-1] / s["den"][-1])
        widen = np.maximum(1.0, 0.1 * g0 / np.abs(G))
        c_deg = 0.0 if s["sd_deg"] is None else float(np.asarray(s["sd_deg"])[-1])
        c_db = 0.0 if s["sd_db"] is None else float(np.asarray(s["sd_db"])[-1])
        for r in s["rivals"]:
            q = (np.polyval(r["num"], 2j * np.pi * f) / np.polyval(r["den"], 2j * np.pi * f)) / G \
                * np.exp(-2j * np.pi * f * (r["tau"] - s["tau"]))
            d_deg, d_db = np.abs(np.degrees(np.angle(q))), np.abs(20 * np.log10(np.abs(q)))
            r_deg = 0.0 if r["sd"] is None else float(np.asarray(r["sd"][1])[-1])
            r_db = 0.0 if r["sd"] is None else float(np.asarray(r["sd"][0])[-1])
            u_deg, u_db = 2 * math.hypot(c_deg, r_deg), 2 * math.hypot(c_db, r_db)
            Gr = np.polyval(r["num"], 2j * np.pi * fP) / np.polyval(r["den"], 2j * np.pi * fP)
            true_r = float(np.max(np.abs(np.degrees(np.angle(Gr / P)))))
            # tolerances beyond u95: plain and widened
            w_plain = np.maximum(np.where(d_deg > u_deg, d_deg / 5.0, 0), np.where(d_db > u_db, d_db / 1.0, 0))
            w_wide = w_plain / widen
            cand = (float(w_plain.max()), float(w_wide.max()), float(d_deg.max()), float(d_db.max()), u_deg, r["order"],
                    true_r)
            if best is None or cand[0] > best[0]:
                best = cand
    rows.append((key, x["spec"], x["label"].split()[1], c["max_deg"], x["order"], best))
if "--rows" in sys.argv:
    for key, spec, d, m, o, b in rows:
        if b is None:
            print(f"{key:13s} {spec:22s} {d:13s} {m:6.2f} {o} no rival")
        else:
            print(f"{key:13s} {spec:22s} {d:13s} {m:6.2f} {o} rival {b[5]} d {b[2]:5.2f} deg {b[3]:5.2f} dB u95 {b[4]:4.2f} "
                  f"w_plain {b[0]:4.2f} w_wide {b[1]:4.2f} rival_true {b[6]:5.2f}")
for name, j in (("plain", 0), ("widened", 1)):
    for fac in (1.0, 1.5, 2.0):
        cnt = {}
        for key, spec, d, m, o, b in rows:
            cnt.setdefault(key, [0, 0])[1] += 1
            if b is not None and b[j] > fac:
                cnt[key][0] += 1
        print(f"rival beyond u95 by > {fac:g} x tolerance ({name}) at grid top..15 Hz: refused anew / n: "
              + ", ".join(f"{k} {v[0]}/{v[1]}" for k, v in cnt.items()))
