"""The cases whose named effects differ between two runs of runsets.sh (or held16.sh), with truth and shrink.
usage: [TALLY_SETS="a b"] python bench/tune_diag/cmp_names.py BASE_OUT NEW_OUT (rows matched by order within a set)"""
import sys

from tally import SETS, load_rows, names_of, truth_of



def _num(x) -> float:
    """A row's figure, NaN where it is missing or None (a case that failed)."""
    return float("nan") if x is None else float(x)


base, new = sys.argv[1:3]
for s in SETS:
    ra, rb = load_rows(base, s), load_rows(new, s)
    if ra is None or rb is None:
        continue
    for i, (a, b) in enumerate(zip(ra, rb)):
        na, nb = names_of(a), names_of(b)
        if na != nb:
            truth = truth_of(a, s)
            tag = a.get("kind") or a.get("name") or a.get("case") or ""
            print(f"{s:12s} #{i:<3d} {str(tag)[:40]:40s} truth {','.join(sorted(truth)) or 'none'}: "
                  f"{','.join(sorted(na)) or 'none'} -> {','.join(sorted(nb)) or 'none'} "
                  f"(shrink {_num(a.get('shrink')):.2f} -> {_num(b.get('shrink')):.2f})")
