"""Pairs and triples drawn by the independent tuning simulator itself (a tuning set, not verification).

:func:`hasel_bench.othersim.run_othersim` makes a fifth of its cases pairs (about six of 28), too few
to see how the selection treats combinations. This draws only pairs and triples with othersim's own
forms, parameters and excitation (:func:`hasel_bench.othersim.sample_foreign`,
:func:`hasel_bench.othersim.make_case`), names and kinds at random, from seeds of its own
(``seed * 7919 + i``, never othersim's ``seed * 100003 + i``), and diagnoses each with the nominal
P(s) like ``cases.py``.

Run ``python bench/tune_diag/other_pairs.py --out DIR [--seed S] [--pairs N] [--triples M]``; the
output is ``cases.py``'s (one line per case, then the summary) plus recall/precision of pairs and
triples apart, in ``DIR/results.json`` too.
"""
from __future__ import annotations

import argparse
import os
import sys

import numpy as np

from hasel_bench import othersim as o

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from cases import finish, run  # noqa: E402
from combos import cached  # noqa: E402


def make(directory: str, seed: int = 5, n_pairs: int = 12, n_triples: int = 6) -> list[dict]:
    """Write the cases to ``directory``; returns their labels (kept here, not in the files)."""
    names = list(o.EFFECT_KINDS)
    out = []
    for i, k in enumerate([2] * n_pairs + [3] * n_triples):
        cs = seed * 7919 + i
        rng = np.random.default_rng([cs, 2])
        pick = [names[int(j)] for j in rng.choice(len(names), k, replace=False)]
        effs = tuple(o.sample_foreign(nm, rng) for nm in pick)
        c = o.make_case(i, cs, effs, directory)
        out.append({"path": c.path, "kind": f"{'pair' if k == 2 else 'triple'}:{c.rate_hz:g}",
                    "labels": sorted(pick), "truth": [f"{e.name}:{e.kind}" for e in effs]})
    return out


def main(argv: list[str] | None = None) -> int:
    """``python bench/tune_diag/other_pairs.py --out DIR [--seed S] [--pairs N] [--triples M] [--only I,...]``."""
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--out", required=True)
    p.add_argument("--seed", type=int, default=5)
    p.add_argument("--pairs", type=int, default=12)
    p.add_argument("--triples", type=int, default=6)
    p.add_argument("--only", default="", help="comma-separated case indices")
    a = p.parse_args(argv)
    os.makedirs(a.out, exist_ok=True)
    cases = cached(os.path.join(a.out, f"cases_{a.seed}_{a.pairs}_{a.triples}.json"),
                   lambda: make(a.out, a.seed, a.pairs, a.triples))
    if a.only:
        keep = {int(x) for x in a.only.split(",")}
        cases = [c for i, c in enumerate(cases) if i in keep]
    finish(cases, run(cases, lambda m: (print(m), sys.stdout.flush())), a.out)
    return 0


if __name__ == "__main__":
    sys.exit(main())
