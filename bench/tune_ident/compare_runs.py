"""Two runs of varied.py side by side: the tally of each, the logs whose outcome changed, and why refused.

Usage: python bench/tune_ident/compare_runs.py BEFORE.txt[,MORE.txt] AFTER.txt[,MORE.txt]
Each argument is a comma-separated list of varied.py outputs (the same logs in the same order for both).
Prints the four outcomes per run (good / wrong yet usable / right yet refused / wrong and refused), the sum of
the identify seconds (s), the logs that changed (design, rate, draw, max dB / deg, order, outcome), and each
right-yet-refused model of AFTER with the check that refused it (its reason).
"""
from __future__ import annotations

import sys

KEYS = ("good", "WRONG_USABLE", "RIGHT_REFUSED", "WRONG_REFUSED")


def rows(paths: str) -> list[dict]:
    """The log rows of the varied.py outputs ``paths`` (comma-separated), in order."""
    out = []
    for path in paths.split(","):
        for n, line in enumerate(open(path)):
            f = line.split()
            if len(f) < 11 or f[0] == "design" or line.startswith("logs ") or "REFUSED(exit" in line:
                continue
            try:
                max_db, max_deg, secs = float(f[3]), float(f[4]), float(f[9])
            except ValueError:
                continue
            kind = f[11] if len(f) > 11 and f[11] in KEYS else "good"
            parts = line.rstrip("\n").split(" | ")
            out.append({"id": f"{path.rsplit('/', 1)[-1]}:{f[0]} {f[1]} {f[2]}", "db": max_db, "deg": max_deg,
                        "s": secs, "order": f[10], "kind": kind, "cond": parts[1] if len(parts) > 1 else "",
                        "reasons": parts[2] if len(parts) > 2 else ""})
    return out


def tally(rs: list[dict]) -> str:
    """One line: the count of each outcome and the summed seconds."""
    c = {k: sum(r["kind"] == k for r in rs) for k in KEYS}
    return (f"n {len(rs)}: good {c['good']}, WRONG YET USABLE {c['WRONG_USABLE']}, right yet refused "
            f"{c['RIGHT_REFUSED']}, wrong and refused {c['WRONG_REFUSED']}; identify seconds {sum(r['s'] for r in rs):.0f}")


def main() -> int:
    """Print the comparison (see the module)."""
    before, after = rows(sys.argv[1]), rows(sys.argv[2])
    print("before:", tally(before))
    print("after: ", tally(after))
    sb, sa = sum(r["s"] for r in before), sum(r["s"] for r in after)
    if sb > 0:
        print(f"speed after/before {sa / sb:.2f}x")
    by = {r["id"]: r for r in before}
    print("\nchanged:")
    for r in after:
        b = by.get(r["id"])
        if b is None or (b["kind"], b["order"]) != (r["kind"], r["order"]) or abs(b["deg"] - r["deg"]) > 0.5:
            was = "(not in before)" if b is None else f"{b['order']} {b['db']:.2f} dB {b['deg']:.1f} deg {b['kind']}"
            print(f"  {r['id']}: {was} -> {r['order']} {r['db']:.2f} dB {r['deg']:.1f} deg {r['kind']} | {r['cond']}")
    print("\nright yet refused (after):")
    for r in after:
        if r["kind"] == "RIGHT_REFUSED":
            print(f"  {r['id']} {r['order']} {r['db']:.2f} dB {r['deg']:.1f} deg | {r['reasons']}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
