"""Study (session 23, RESULT-s-hfside.md): at the map-side stage, does the residual above the resonance prefer the
true side of a map more often than the full-band validation error does?

usage: python bench/tune_diag/side_band_study.py TREE OUTJSON SET [SET...]   (the sets' logs under BASE, a runsets.sh
output). Each log whose truth holds exactly one of the two map sides is diagnosed on TREE's code; each map-side
comparison (``checks._side_round``, wrapped in this process only, the diagnosis unchanged) records both sets'
validation residuals high-passed (4th-order Butterworth, zero phase) at 0.5-3x the nominal resonance."""
import sys, json, glob, os, time, numpy as np
tree, outp, sets = sys.argv[1], sys.argv[2], sys.argv[3:]
sys.path.insert(0, tree + "/src")
from scipy import signal
from hasel.diagnose import diagnose, DiagnoseOptions
from hasel.diagnose import checks
from hasel.diagnose.significance import block_test
BASE = os.environ.get("STUDY_BASE", "/work/wt/out22-fastq")
SIDES = {"static_nonlinearity", "sensor_nonlinearity"}
cap = []
orig = checks._side_round

def hook(ctx, st, alt, best, accepted, pref, m_cur, m_alt, after_hysteresis=False):
    if not after_hysteresis:
        pipe = ctx.pipe
        den = np.asarray(ctx.den, float)
        r = np.roots(den); wn = np.abs(r[np.abs(r.imag) > 1e-9])
        fr = float(wn.max() / 2 / np.pi) if wn.size else float(np.abs(r).max() / 2 / np.pi)
        fs = 1.0 / pipe.prep.dt_s
        inc = [k for k in st.current if k in SIDES][0]; oth = [k for k in alt if k in SIDES][0]
        row = {"inc": inc, "alt": oth, "fr": fr, "fs": fs, "m_cur": m_cur, "m_alt": m_alt, "pref": pref, "bands": {}}
        for mult in (0.5, 1.0, 1.5, 2.0, 3.0):
            fc = mult * fr
            if fc >= 0.45 * fs:
                continue
            sos = signal.butter(4, fc, "highpass", fs=fs, output="sos")
            ea, eb, ua = [], [], []
            for ri, rec in enumerate(pipe.prep.records):
                m = rec.valid
                if not m.any() or rec.y.size < 64:
                    continue
                a = signal.sosfiltfilt(sos, rec.y - pipe.simulate(st.current, ri))
                b = signal.sosfiltfilt(sos, rec.y - pipe.simulate(alt, ri))
                u = signal.sosfiltfilt(sos, rec.u - rec.u.mean())
                ea.append(a[m]); eb.append(b[m]); ua.append(u[m])
            if not ea:
                continue
            ea, eb = np.concatenate(ea), np.concatenate(eb)
            n = min(ea.size, ctx.labels_va.size)
            row["bands"][mult] = {"inc": float(np.mean(ea ** 2)), "alt": float(np.mean(eb ** 2)),
                                  "pref_alt": block_test(ea[:n], eb[:n], ctx.labels_va[:n], 0),
                                  "u_hf_share": float(np.mean(np.concatenate(ua) ** 2))}
        cap.append(row)
    return orig(ctx, st, alt, best, accepted, pref, m_cur, m_alt, after_hysteresis)

checks._side_round = hook
rows = []
for s in sets:
    d = os.path.join(BASE, s)
    if s == "cases":
        res = json.load(open(d + "/results.json")); res = res["rows"] if isinstance(res, dict) else res
        files = sorted(glob.glob(d + "/tune_*.npz"))
        items = [(f, res[i]["labels"], res[i]["kind"]) for i, f in enumerate(files)]
    else:
        cj = [f for f in glob.glob(d + "/cases_*.json")][0]
        items = [(c["path"], c["labels"], c["kind"]) for c in json.load(open(cj))]
    for path, labels, kind in items:
        if not (set(labels) & SIDES) or (set(labels) >= SIDES):
            continue
        z = np.load(path)
        cap.clear(); t0 = time.time()
        try:
            v = diagnose(z["t_s"], z["voltage_kv"], z["stroke_mm"], model={"num": z["num"].tolist(), "den": z["den"].tolist()},
                         units=("kV", "mm"), options=DiagnoseOptions())
            names = list(v.names)
        except Exception as e:
            names = ["ERR " + repr(e)[:80]]
        rows.append({"set": s, "path": os.path.basename(path), "labels": labels, "kind": kind, "names": names,
                     "side": list(cap), "sec": time.time() - t0})
        print(s, os.path.basename(path), labels, names, "side rounds", len(cap), flush=True)
        json.dump(rows, open(outp, "w"), indent=1)
