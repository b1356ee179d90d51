"""The cases whose named effects differ between two runs of runsets.sh (or held16.sh), with truth and shrink.
usage: [TALLY_SETS="a b"] python bench/tune_diag/cmp_names.py BASE_OUT NEW_OUT (rows matched by order within a set)"""
import json, os, sys

from tally import SETS, as_set

base, new = sys.argv[1:3]
for s in SETS:
    pa, pb = (os.path.join(o, s, "results.json") for o in (base, new))
    if not (os.path.exists(pa) and os.path.exists(pb)):
        continue
    ra, rb = ([r for r in (lambda d: d["rows"] if isinstance(d, dict) else d)(json.load(open(p)))] for p in (pa, pb))
    for i, (a, b) in enumerate(zip(ra, rb)):
        na, nb = as_set(a.get("names")), as_set(b.get("names"))
        if na != nb:
            truth = set() if s.startswith("free") else as_set(a.get("labels", a.get("truth", [])))
            tag = a.get("kind") or a.get("name") or a.get("case") or ""
            print(f"{s:12s} #{i:<3d} {str(tag)[:40]:40s} truth {','.join(sorted(truth)) or 'none'}: "
                  f"{','.join(sorted(na)) or 'none'} -> {','.join(sorted(nb)) or 'none'} "
                  f"(shrink {a.get('shrink', float('nan')):.2f} -> {b.get('shrink', float('nan')):.2f})")
