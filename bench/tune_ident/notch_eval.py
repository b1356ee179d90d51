"""Check 8's residual response near the band's top, per log, against the model's true error (notch_dump.py's pickle).

Usage: python bench/tune_ident/notch_eval.py IN.pkl [--score] [--truth] [--curv]
(rows of the top-of-band points f:rel/z are always printed first)
"""
import sys, pickle
import numpy as np
sys.path.insert(0, __import__("os").path.dirname(__file__))
from hasel.paper import plant_tf

num_p, den_p = plant_tf()
P = lambda f: np.polyval(num_p, 2j * np.pi * f) / np.polyval(den_p, 2j * np.pi * f)  # noqa: E731
res = pickle.load(open(sys.argv[1], "rb"))
show = "--show" in sys.argv


def top_stats(x, f_lo=10.0, f_hi=15.0):
    """Top-of-band residual points: (f, rel, z) for f_lo <= f <= f_hi among the judged points."""
    r = x["resid"]
    if r is None:
        return None
    f, E, sig, coh = r["f"], r["H"], r["sigma"], r["coh"]
    use = np.isfinite(E) & np.isfinite(sig) & (sig > 0) & (f >= x["band"][0]) & (f <= x["band"][1])
    use &= np.where(np.isfinite(coh), coh >= 0.5, False)
    G = np.polyval(x["num"], 2j * np.pi * f) / np.polyval(x["den"], 2j * np.pi * f)
    g0 = abs(x["num"][-1] / x["den"][-1])
    rel = np.abs(E) / np.maximum(np.abs(G), 0.1 * g0)
    z = np.abs(E) / np.maximum(sig / np.sqrt(2.0), 1e-300)
    sel = use & (f >= f_lo) & (f <= f_hi)
    return f[sel], rel[sel], z[sel], coh[sel]


for x in res:
    c = x["cmp"]
    good = c["max_db"] <= 1.0 and c["max_deg"] <= 5.0
    key = ("good" if x["usable"] else "RIGHT_REFUSED") if good else ("WRONG_USABLE" if x["usable"] else "wrong_ref")
    st = top_stats(x, 8.0, 25.0)
    line = f"{x['spec']:24s} {x['label'].split()[1]:13s} {key:13s} {c['max_deg']:6.2f} {x['order']} band {x['band'][1]:.3g}"
    if st is None or st[0].size == 0:
        print(line, "no resid top"); continue
    f, rel, z, coh = st
    print(line + " | " + " ".join(f"{a:.3g}:{b:.2f}/{int(min(d, 999))}" for a, b, d in zip(f, rel, z)))


def score(x, f_lo, f_hi, z_min=4.0, widened=False):
    """Largest |E| / |G| (unwidened unless ``widened``) among points with z > z_min in [f_lo, f_hi] Hz; 0 if none."""
    r = x["resid"]
    if r is None:
        return float("nan")
    f, E, sig, coh = r["f"], r["H"], r["sigma"], r["coh"]
    use = np.isfinite(E) & np.isfinite(sig) & (sig > 0) & (f >= x["band"][0]) & (f <= x["band"][1])
    use &= np.where(np.isfinite(coh), coh >= 0.5, False)
    G = np.polyval(x["num"], 2j * np.pi * f) / np.polyval(x["den"], 2j * np.pi * f)
    g0 = abs(x["num"][-1] / x["den"][-1])
    den = np.maximum(np.abs(G), 0.1 * g0) if widened else np.abs(G)
    rel = np.abs(E) / den
    z = np.abs(E) / np.maximum(sig / np.sqrt(2.0), 1e-300)
    sel = use & (f >= f_lo) & (f <= f_hi) & (z > z_min)
    return float(rel[sel].max()) if sel.any() else 0.0


if "--score" in sys.argv:
    for (a, b, w) in ((10, 15, False), (10, 15, True), (12, 20, False), (12, 20, True)):
        print(f"== score: max |E|/|G|{' (widened)' if w else ''} over z>4 points in {a}-{b} Hz, by class")
        by = {}
        for x in res:
            c = x["cmp"]
            good = c["max_db"] <= 1.0 and c["max_deg"] <= 5.0
            key = ("good" if x["usable"] else "right_refused") if good else ("WRONG_USABLE" if x["usable"] else "wrong_refused")
            by.setdefault(key, []).append((score(x, a, b, widened=w), x["spec"], c["max_deg"]))
        for k, v in by.items():
            v.sort(reverse=True)
            print(f"  {k:14s} n={len(v):3d} " + " ".join(f"{s:.3f}" for s, _, _ in v[:12]))
        for thr in (0.06, 0.087, 0.1, 0.12):
            cnt = {k: sum(1 for s, _, _ in v if s > thr) for k, v in by.items()}
            print(f"  thr {thr}: refused anew ->", cnt)


if "--truth" in sys.argv:
    # the residual's relative size near 15 Hz against the model's true relative error there (|G / P - 1|)
    print(f"{'spec':22s} {'design':13s} {'class':13s} {'maxdeg':>6s} {'f':>5s} {'|G/P-1|':>7s} {'|E/G|':>6s} {'z':>5s}")
    for x in res:
        c = x["cmp"]
        good = c["max_db"] <= 1.0 and c["max_deg"] <= 5.0
        key = ("good" if x["usable"] else "right_refused") if good else ("WRONG_USABLE" if x["usable"] else "wrong_refused")
        r = x["resid"]
        if r is None:
            continue
        f = r["f"]
        ok = (f <= 15.5) & (f >= x["band"][0]) & (f <= x["band"][1])
        if not ok.any():
            continue
        i = int(np.flatnonzero(ok)[-1])
        fi = f[i]
        G = np.polyval(x["num"], 2j * np.pi * fi) / np.polyval(x["den"], 2j * np.pi * fi)
        t = abs(G / P(fi) - 1)
        z = abs(r["H"][i]) / (r["sigma"][i] / np.sqrt(2))
        print(f"{x['spec']:22s} {x['label'].split()[1]:13s} {key:13s} {c['max_deg']:6.2f} {fi:5.3g} {t:7.3f} "
              f"{abs(r['H'][i] / G):6.3f} {z:5.0f}")


def curvature(x, f_hi=15.5, f_top=10.0):
    """E/G with its best linear-phase part (a timing offset, -j w d) removed over the band up to f_hi Hz.

    Returns (d, s; the largest |remaining| with z > 4 over f_top..f_hi Hz) or None.
    """
    r = x["resid"]
    if r is None:
        return None
    f, E, sig, coh = r["f"], r["H"], r["sigma"], r["coh"]
    use = np.isfinite(E) & np.isfinite(sig) & (sig > 0) & (f >= x["band"][0]) & (f <= min(x["band"][1], f_hi))
    use &= np.where(np.isfinite(coh), coh >= 0.5, False)
    if use.sum() < 4:
        return None
    f, E, sig = f[use], E[use], sig[use]
    G = np.polyval(x["num"], 2j * np.pi * f) / np.polyval(x["den"], 2j * np.pi * f)
    q, s = E / G, sig / np.abs(G) / np.sqrt(2)
    w = 2 * np.pi * f
    # weighted LS of Im(q) = -w d
    d = -np.sum(w * q.imag / s ** 2) / np.sum(w ** 2 / s ** 2)
    rem = q + 1j * w * d
    z = np.abs(rem) / s
    sel = (f >= f_top) & (z > 4)
    return d, (float(np.abs(rem[sel]).max()) if sel.any() else 0.0)


if "--curv" in sys.argv:
    by = {}
    for x in res:
        c = x["cmp"]
        good = c["max_db"] <= 1.0 and c["max_deg"] <= 5.0
        key = ("good" if x["usable"] else "right_refused") if good else ("WRONG_USABLE" if x["usable"] else "wrong_refused")
        cv = curvature(x)
        if cv is None:
            continue
        by.setdefault(key, []).append((cv[1], x["spec"], c["max_deg"], cv[0] * 1e3))
    print("== max |E/G + j w d| (z > 4) over 10-15.5 Hz after the best timing offset d, by class (score spec maxdeg d_ms)")
    for k, v in by.items():
        v.sort(reverse=True)
        print(f"  {k:14s} n={len(v):3d} " + " ".join(f"{s:.3f}({sp},{m:.1f},{dd:+.2f})" for s, sp, m, dd in v[:10]))
    for thr in (0.05, 0.06, 0.087, 0.1):
        print(f"  thr {thr}:", {k: sum(1 for s, *_ in v if s > thr) for k, v in by.items()})
