"""Tally T (true members named), S (names not in the truth), FA (effect-free logs with a name), seconds per set.
usage: [TALLY_SETS="a b"] python bench/tune_diag/tally.py OUTDIR [OUTDIR2 ...] (outputs of runsets.sh)  (prints a side-by-side table when two are given)"""
import json, os, sys

SETS = (os.environ.get("TALLY_SETS") or  # other set names (the held-back sets' folders, say); names free* are effect-free
        "cases loads combos other_pairs maps free_noise free_quiet free_indep11 free_indep13 multi2 deadzones drifts modes "
        "forms3").split()

def as_set(x):
    """Effect names of a truth or verdict field (list, comma string, dict or 'none') as a set."""
    if x is None or x == "none" or x == "":
        return set()
    if isinstance(x, str):
        return set(p for p in x.replace("+", ",").split(",") if p and p != "none")
    if isinstance(x, dict):
        return set(x)
    return set(x)

def load_rows(out, s):
    """The result rows of set ``s`` in runsets.sh's ``out`` (None when the set was not run)."""
    p = os.path.join(out, s, "results.json")
    if not os.path.exists(p):
        return None
    d = json.load(open(p))
    return d["rows"] if isinstance(d, dict) and "rows" in d else d


def truth_of(r, s):
    """The true effect names of row ``r`` of set ``s`` (none in the effect-free sets, free*)."""
    return set() if s.startswith("free") else as_set(r["labels"] if "labels" in r else r.get("truth", r.get("true", [])))


def names_of(r):
    """The effect names the diagnosis gave in row ``r``."""
    return as_set(r.get("names", r.get("named", [])))


def tally(out, s):
    """Counts of set ``s`` in runsets.sh's ``out``: cases, T, S, FA, effect-free logs, seconds (sum of per-case s)."""
    rows = load_rows(out, s)
    if rows is None:
        return None
    T = S = FA = nfree = 0; sec = 0.0
    for r in rows:
        truth, names = truth_of(r, s), names_of(r)
        T += len(names & truth); S += len(names - truth)
        if not truth:
            nfree += 1; FA += bool(names)
        sec += float(r.get("seconds", 0) or 0)
    return dict(n=len(rows), T=T, S=S, FA=FA, nfree=nfree, sec=sec)

def main(outs: list[str]) -> None:
    """Print the side-by-side table of the runs ``outs``."""
    tot = [dict(T=0, S=0, FA=0, sec=0.0) for _ in outs]
    print(f"{'set':14s}" + "".join(f" | {os.path.basename(o.rstrip('/')):>30s}" for o in outs))
    for s in SETS:
        cells = []
        for i, o in enumerate(outs):
            t = tally(o, s)
            if t is None:
                cells.append(f"{'-':>30s}"); continue
            for k in ("T", "S", "FA", "sec"):
                tot[i][k] += t[k]
            cells.append(f"{'n%d T%d S%d FA%d/%d %5.0fs' % (t['n'], t['T'], t['S'], t['FA'], t['nfree'], t['sec']):>30s}")
        print(f"{s:14s}" + "".join(" | " + c for c in cells))
    print(f"{'total':14s}" + "".join(f" | {'T%d S%d FA%d %6.0fs' % (t['T'], t['S'], t['FA'], t['sec']):>30s}" for t in tot))


if __name__ == "__main__":
    main(sys.argv[1:])
