#!/usr/bin/env python
"""Score two diagnosis tool versions on the vload corpus.

usage: score.py run [--deadline EPOCH_S]   # run A on core 0, B on core 1, in parallel
       score.py report                       # build RESULT.md from runs/*.meta.json
"""
import json
import os
import subprocess
import sys
import threading
import time

# the corpus directory (VLOAD_DIR, default beside this file) and the two tools compared (HASEL_A, HASEL_B: hasel
# executables), A pinned to core 0 and B to core 1
D = os.environ.get("VLOAD_DIR") or os.path.dirname(os.path.abspath(__file__))
TOOLS = {"A": (os.environ.get("HASEL_A", "/work/wt/hasel-main31"), "0"), "B": (os.environ.get("HASEL_B", "/work/wt/hasel-main"), "1")}
MODEL = os.path.join(D, "model.json")
RUNS = os.path.join(D, "runs")


def run_one(tool, case, deadline):
    exe, core = TOOLS[tool]
    stem = os.path.splitext(case["file"])[0]
    out = os.path.join(RUNS, f"{stem}.{tool}.json")
    meta_p = os.path.join(RUNS, f"{stem}.{tool}.meta.json")
    if os.path.exists(meta_p):
        return
    if deadline and time.time() > deadline:
        return
    env = dict(os.environ, OPENBLAS_NUM_THREADS="1")
    cmd = ["taskset", "-c", core, exe, "diagnose", os.path.join(D, case["file"]),
           "--model", MODEL, "--json", out]
    t0 = time.time()
    try:
        p = subprocess.run(cmd, env=env, capture_output=True, text=True, timeout=300)
        rc, so, se = p.returncode, p.stdout, p.stderr
    except subprocess.TimeoutExpired as e:
        rc, so, se = "timeout", (e.stdout or b"").decode(errors="replace") if isinstance(e.stdout, bytes) else (e.stdout or ""), \
            (e.stderr or b"").decode(errors="replace") if isinstance(e.stderr, bytes) else (e.stderr or "")
    dt = time.time() - t0
    with open(os.path.join(RUNS, f"{stem}.{tool}.log"), "w") as fh:
        fh.write(f"$ {' '.join(cmd)}\nrc={rc}\n--- stdout\n{so}\n--- stderr\n{se}\n")
    meta = dict(case=case["file"], tool=tool, rc=rc, seconds=dt, out=out,
                stderr_tail=[l for l in (se or "").splitlines() if l.strip()][-5:])
    with open(meta_p, "w") as fh:
        json.dump(meta, fh, indent=1)
    print(f"[{tool}] {case['file']} rc={rc} {dt:.0f}s", flush=True)


def worker(tool, cases, deadline):
    for c in cases:
        run_one(tool, c, deadline)


def cmd_run(deadline):
    os.makedirs(RUNS, exist_ok=True)
    cases = json.load(open(os.path.join(D, "cases.json")))
    th = [threading.Thread(target=worker, args=(t, cases, deadline)) for t in TOOLS]
    for t in th:
        t.start()
    for t in th:
        t.join()


def read_verdict(path):
    try:
        v = json.load(open(path))
    except Exception as e:  # noqa
        return None, None, f"no verdict ({type(e).__name__})"
    names = [e.get("name") for e in (v.get("effects") or [])]
    h = v.get("heldout") or {}
    nn, na = h.get("nrmse_nominal"), h.get("nrmse_augmented")
    shrink = None
    if isinstance(nn, (int, float)) and isinstance(na, (int, float)) and nn:
        shrink = 1 - (na / nn) ** 2
    return names, shrink, None


def cmd_report():
    cases = json.load(open(os.path.join(D, "cases.json")))
    rows = []
    summ = {t: dict(load_run=0, load_named=0, load_only=0, spurious=0, spurious_cases=0, none_run=0,
                    none_named=0, failed=0, seconds=[]) for t in TOOLS}
    odd = []
    for c in cases:
        stem = os.path.splitext(c["file"])[0]
        r = dict(case=stem[:6], form=c["form"], design=c["design"]["kind"], rate=c["rate"],
                 vis=c["visibility_ratio"])
        for t in TOOLS:
            mp = os.path.join(RUNS, f"{stem}.{t}.meta.json")
            if not os.path.exists(mp):
                r[t] = None
                continue
            m = json.load(open(mp))
            names, shrink, err = read_verdict(m["out"])
            r[t] = dict(rc=m["rc"], sec=m["seconds"], names=names, shrink=shrink)
            s = summ[t]
            s["seconds"].append(m["seconds"])
            if m["rc"] != 0 or names is None:
                s["failed"] += 1
                odd.append(f"{t} {stem}: rc={m['rc']} {err or ''} :: " + " | ".join(m["stderr_tail"]))
                if names is None:
                    continue
            if c["label"] == "load_mass":
                s["load_run"] += 1
                if "load_mass" in names:
                    s["load_named"] += 1
                    if set(names) == {"load_mass"}:
                        s["load_only"] += 1
                sp = [n for n in names if n != "load_mass"]
            else:
                s["none_run"] += 1
                if names:
                    s["none_named"] += 1
                sp = list(names)
            s["spurious"] += len(sp)
            s["spurious_cases"] += bool(sp)
        rows.append(r)

    def fmt_names(x):
        if x is None:
            return "(not run)"
        if x["names"] is None:
            return f"FAILED rc={x['rc']}"
        return ",".join(x["names"]) or "-"

    def fmt_sh(x):
        return "" if not x or x["shrink"] is None else f"{x['shrink']:.3f}"

    L = ["# vload: independent load-change corpus, A = main31, B = main", ""]
    L += ["## Summary", "",
          "| tool | load cases run | load_mass named | load_mass only name | spurious names (cases) | effect-free run | effect-free with any name | failed runs | median s |",
          "|---|---|---|---|---|---|---|---|---|"]
    for t in TOOLS:
        s = summ[t]
        sec = sorted(s["seconds"])
        med = f"{sec[len(sec)//2]:.0f}" if sec else ""
        L.append(f"| {t} | {s['load_run']} | {s['load_named']} | {s['load_only']} | {s['spurious']} ({s['spurious_cases']}) | "
                 f"{s['none_run']} | {s['none_named']} | {s['failed']} | {med} |")
    L += ["", "## Per case", "",
          "| case | form | design | rate | vis/noise | names A | names B | shrink A | shrink B | s A | s B |",
          "|---|---|---|---|---|---|---|---|---|---|---|"]
    for r in rows:
        a, b = r["A"], r["B"]
        L.append(f"| {r['case']} | {r['form']} | {r['design']} | {r['rate']} | {r['vis']:.1f} | {fmt_names(a)} | {fmt_names(b)} | "
                 f"{fmt_sh(a)} | {fmt_sh(b)} | {'' if not a else '%.0f' % a['sec']} | {'' if not b else '%.0f' % b['sec']} |")
    if odd:
        L += ["", "## Failed / odd runs", ""] + [f"- {o}" for o in odd]
    txt = "\n".join(L) + "\n"
    open(os.path.join(D, "RESULT.md"), "w").write(txt)
    print(txt)


if __name__ == "__main__":
    if sys.argv[1] == "run":
        dl = float(sys.argv[sys.argv.index("--deadline") + 1]) if "--deadline" in sys.argv else None
        cmd_run(dl)
    else:
        cmd_report()
