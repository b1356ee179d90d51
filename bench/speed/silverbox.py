"""The Silverbox dataset diagnosed as the README's real-data table does (default options, no model:
identified first), timed: ``python bench/speed/silverbox.py [--part multisine|all] [--json FILE]``.

Prints the names, the held-out NRMSE (nominal -> augmented), wall and CPU seconds (this process
and its fitting workers). Run it with ``PYTHONPATH=TREE/src`` to time another tree's code with the
same data, side by side, under ``nice``.
"""
from __future__ import annotations

import argparse
import json
import os
import resource
import sys
import time

HERE = os.path.dirname(os.path.abspath(__file__))


def main() -> int:
    """Diagnose Silverbox once; print one JSON line (seconds, NRMSE; names)."""
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--part", default="multisine", choices=("multisine", "noise", "all"))
    ap.add_argument("--json", default=None)
    a = ap.parse_args()
    import hasel

    sys.path.insert(0, os.path.join(os.path.dirname(os.path.dirname(hasel.__file__)), "tests"))
    import realdata as D  # the tests' loader of ../shared/datasets

    from hasel.diagnose.core import diagnose

    d = D.load_silverbox(a.part)
    r0 = resource.getrusage(resource.RUSAGE_SELF)
    c0 = resource.getrusage(resource.RUSAGE_CHILDREN)
    t0 = time.perf_counter()
    v = diagnose(d.t_s, d.u, d.y)
    wall = time.perf_counter() - t0
    r1 = resource.getrusage(resource.RUSAGE_SELF)
    c1 = resource.getrusage(resource.RUSAGE_CHILDREN)
    cpu = sum(getattr(e, f) - getattr(b, f) for e, b in ((r1, r0), (c1, c0)) for f in ("ru_utime", "ru_stime"))
    out = {"src": os.path.dirname(hasel.__file__), "samples": int(d.t_s.size), "names": v.names,
           "nrmse_nominal": v.heldout["nrmse_nominal"], "nrmse_augmented": v.heldout["nrmse_augmented"],
           "dropped": [x["name"] for x in v.dropped], "wall_s": round(wall, 2), "cpu_s": round(cpu, 2)}
    print(json.dumps(out), flush=True)
    if a.json:
        with open(a.json, "w") as fh:
            json.dump(out, fh)
    return 0


if __name__ == "__main__":
    sys.exit(main())
