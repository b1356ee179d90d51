"""Study (session 30, not product code): a prediction-error (whitened) held-out block score beside the product's two,

The whitening filter A(q) is an AR(p) fitted (least squares) to the round's old validation residual within its
blocks; both residuals are filtered by it within each block, then the block score is taken. Prints per log: names,
round-1 best, t_blk, z_col, t_w10 (both residuals whitened by the old one's AR) and t_pe10 (each by its own AR: the
score of ``h-pe.patch``). ``TREE`` (environment) names the source tree, default this repository."""
import sys, json, os
import numpy as np
TREE = os.environ.get("TREE", os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", ".."))
sys.path.insert(0, TREE + "/src")
from hasel.diagnose import core, pool
from hasel.diagnose import context as cx
from hasel.effects.heldout import block_test
pool.set_jobs(1)

def ar_fit(e, labels, p):
    p = int(min(p, max(1, int(np.median(np.bincount(labels))) // 4)))
    rows, ys = [], []
    for b in np.unique(labels):
        x = e[labels == b]
        if x.size <= p + 5: continue
        X = np.column_stack([x[p - j - 1:x.size - j - 1] for j in range(p)])
        rows.append(X); ys.append(x[p:])
    X = np.vstack(rows); y = np.concatenate(ys)
    return np.linalg.lstsq(X, y, rcond=None)[0]

def whiten(e, labels, a):
    p = a.size; out = np.zeros_like(e)
    for b in np.unique(labels):
        i = np.flatnonzero(labels == b); x = e[i]
        w = x.copy()
        for j in range(p):
            w[j + 1:] -= a[j] * x[:x.size - j - 1]
        w[:p] = 0.0  # the block's first p samples have no full past
        out[i] = w
    return out

REC = []
_orig = cx._Context.held_out
def held_out(self, e_old, e_new):
    t, z = _orig(self, e_old, e_new)
    lab = self.labels_va
    res = {"t_blk": t, "z_col": z}
    for p in (10,):
        try:
            a = ar_fit(e_old, lab, p)
            res[f"t_w{p}"] = block_test(whiten(e_old, lab, a), whiten(e_new, lab, a), lab, 0)
            res[f"a{p}sum"] = float(np.sum(a))
            b = ar_fit(e_new, lab, p)
            res[f"t_pe{p}"] = block_test(whiten(e_old, lab, a), whiten(e_new, lab, b), lab, 0)
        except Exception:  # a failed fit is a missing figure in a study
            res[f"t_w{p}"] = float("nan")
    REC.append(res)
    return t, z
cx._Context.held_out = held_out

def run(path, tag):
    d = np.load(path)
    held = (d["h_t_s"], d["h_voltage_kv"], d["h_stroke_mm"]) if "h_t_s" in d else None
    REC.clear()
    v = core.diagnose(d["t_s"], d["voltage_kv"], d["stroke_mm"], heldout=held,
                      model={"num": d["num"].tolist(), "den": d["den"].tolist()}, units=("kV", "mm"),
                      options=core.DiagnoseOptions())
    r1 = next((r for r in v.rounds if "candidates" in r), None)
    first = REC[0] if REC else {}
    print(json.dumps({"tag": tag, "names": v.names, "best1": r1 and r1.get("best"), "acc1": r1 and r1.get("accepted"),
                      **{k: round(x, 2) for k, x in first.items()}}), flush=True)

if __name__ == "__main__":
    for a in sys.argv[1:]:
        tag, path = a.split("=", 1)
        try:
            run(path, tag)
        except Exception as err:
            print(json.dumps({"tag": tag, "error": str(err)[:200]}), flush=True)
