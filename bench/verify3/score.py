"""Black-box scorer for the third blind verification corpus (bench/verify3).

    python score.py --corpus DIR --hasel PATH [--jobs N] [--timeout S]
                    [--json FILE] [--quick] [--cases PREFIX,...] [--work DIR]

Runs ``hasel identify`` / ``hasel diagnose`` as subprocesses on every case of
DIR/cases, reads only their exit codes and the JSON files they write (formats
of /work/shared/interfaces.md), compares with DIR/labels and prints the figures
of issue 14.  Units: frequency Hz, gain error dB, phase error deg, time s.
Written without reading the project's analysis code.
"""
from __future__ import annotations

import argparse
import concurrent.futures as cf
import glob
import json
import math
import os
import re
import subprocess
import sys
import tempfile
import time

import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, HERE)
import plant as P  # noqa: E402

TOOL_NAMES = ("static_nonlinearity", "asymmetric_dynamics", "charge_drift", "saturation",
              "time_delay", "sensor_nonlinearity", "load_mass", "hysteresis")
BAND = (0.1, 15.0)  # Hz, issue 14
TARGET_DB, TARGET_DEG = 1.0, 5.0
FLAG_RE = re.compile(r"worse|generali[sz]", re.I)


# ====================================================================== running
def _data_args(case, kind):
    """Data file and the --input/--output options for one log of a case."""
    fmt = case["format"]
    path = os.path.join(case["dir"], f"{kind}.{fmt}")
    if fmt == "mcap":
        return path, ["--input", case["input_topic"], "--output", case["output_topic"]]
    return path, []


def run_case(case, hasel, work, timeout):
    """Run the tool on one case; returns a dict with rc, seconds, stderr tail and
    the parsed JSON output (or None)."""
    cid = case["id"]
    out = os.path.join(work, cid + ".json")
    if os.path.exists(out):
        os.remove(out)
    data, io_args = _data_args(case, "train")
    if case["task"] == "identify":
        cmd = [hasel, "identify", data, "--json", out] + io_args
    else:
        held, _ = _data_args(case, "heldout")
        cmd = [hasel, "diagnose", data, "--heldout", held, "--model",
               os.path.join(case["dir"], "model.json"), "--json", out, "--jobs", "1"] + io_args
    env = dict(os.environ, OPENBLAS_NUM_THREADS="1", OMP_NUM_THREADS="1", MKL_NUM_THREADS="1")
    t0 = time.time()
    try:
        p = subprocess.run(cmd, capture_output=True, text=True, timeout=timeout, env=env)
        rc, err = p.returncode, p.stderr
    except subprocess.TimeoutExpired:
        rc, err = "timeout", ""
    dt = time.time() - t0
    res = None
    if os.path.exists(out):
        try:
            with open(out) as fh:
                res = json.load(fh)
        except (OSError, ValueError) as e:
            err += f"\n[score] unreadable JSON: {e}"
    tail = [ln for ln in err.strip().splitlines() if ln.strip()][-2:]
    return dict(id=cid, task=case["task"], rc=rc, seconds=dt, stderr=" | ".join(tail),
                out=res, cmd=" ".join(cmd))


# ====================================================================== identify
def _find(obj, pred, path=""):
    """Yield (path, key, value) for every dict item in obj where pred(key, value)."""
    if isinstance(obj, dict):
        for k, v in obj.items():
            if pred(k, v):
                yield path + "/" + str(k), k, v
            yield from _find(v, pred, path + "/" + str(k))
    elif isinstance(obj, list):
        for i, v in enumerate(obj):
            yield from _find(v, pred, f"{path}[{i}]")


def offset_verdict(model):
    """Heuristic reading of the identify JSON's offset-dependence result.

    interfaces.md names no key, so the scorer looks for a key containing
    'depend' (or 'offset' with a p value) and inside it a p value ('p',
    'p_value', 'pvalue') or a verdict string/boolean.  Returns (rejected: bool or
    None when not found, p or None, where found)."""
    for path, k, v in _find(model, lambda k, v: "depend" in str(k).lower()):
        p = None
        verdict = None
        if isinstance(v, dict):
            for kk, vv in v.items():
                kl = str(kk).lower()
                if kl in ("p", "p_value", "pvalue", "p_val") and isinstance(vv, (int, float)):
                    p = float(vv)
                if kl in ("dependent", "reject", "rejected") and isinstance(vv, bool):
                    verdict = vv
                if kl in ("verdict", "result", "decision") and isinstance(vv, str):
                    verdict = vv.lower().startswith("dep") or "reject" in vv.lower()
        elif isinstance(v, bool):
            verdict = v if "in" not in str(k).lower()[:2] else not v
        elif isinstance(v, str):
            s = v.lower()
            if s.startswith("dep") or s.startswith("indep") or "reject" in s:
                verdict = s.startswith("dep") or ("reject" in s and "not" not in s)
            m = re.search(r"p\s*=\s*([0-9.eE+-]+)", v)
            if m:
                try:
                    p = float(m.group(1))
                except ValueError:
                    pass
        if verdict is None and p is not None:
            verdict = p < 0.05
        if verdict is not None:
            return bool(verdict), p, path
    return None, None, None


def ident_error(model):
    """Max |gain error| (dB), max |phase error| (deg) and G(0) error (dB) of the
    identified model against the exact P(s) over BAND; None if no num/den."""
    try:
        num = np.asarray(model["num"], float)
        den = np.asarray(model["den"], float)
    except (KeyError, TypeError, ValueError):
        return None
    if num.size == 0 or den.size == 0 or not np.all(np.isfinite(num)) or not np.all(np.isfinite(den)):
        return None
    f = np.geomspace(BAND[0], BAND[1], 80)
    h = P.freq_resp(num, den, f)
    tau = model.get("delay_s") or 0.0
    if isinstance(tau, (int, float)) and tau:
        h = h * np.exp(-2j * np.pi * f * tau)
    n0, d0 = P.paper_tf()
    r = h / P.freq_resp(n0, d0, f)
    db = 20 * np.log10(np.abs(r))
    deg = np.degrees(np.angle(r))
    g0 = np.polyval(num, 0.0) / np.polyval(den, 0.0) if np.polyval(den, 0.0) != 0 else float("inf")
    g0db = 20 * math.log10(abs(g0) / P.dc_gain(n0, d0)) if np.isfinite(g0) and g0 != 0 else float("inf")
    return dict(max_db=float(np.max(np.abs(db))), max_deg=float(np.max(np.abs(deg))),
                g0=float(g0), g0_db=float(g0db),
                f_worst_db=float(f[np.argmax(np.abs(db))]), f_worst_deg=float(f[np.argmax(np.abs(deg))]))


# ====================================================================== diagnose
def named(verdict):
    """The named effect set of a verdict (ranked list of names)."""
    eff = (verdict or {}).get("effects") or []
    return [e.get("name") for e in eff if isinstance(e, dict)]


def match(names, truth):
    """Greedy match of named effects to truth effects (each truth effect has an
    'accept' list).  Returns (matched named count, matched truth count)."""
    used = set()
    hit = 0
    for n in names:
        for j, t in enumerate(truth):
            if j not in used and n in t["accept"]:
                used.add(j)
                hit += 1
                break
    return hit, len(used)


def flagged(verdict):
    """Heuristic: does the verdict say anywhere that the augmented model is worse
    or that an effect did not generalise?  interfaces.md names no key; any key or
    string value matching /worse|generali[sz]/ counts.  Returns the first match."""
    for path, k, v in _find(verdict, lambda k, v: True):
        if FLAG_RE.search(str(k)):
            if v not in (False, None, [], {}, 0):
                return path
        if isinstance(v, str) and FLAG_RE.search(v):
            return path
    return None


def shrink(verdict):
    """Held-out gap shrink 1 - nrmse_augmented / nrmse_nominal (fraction), or None."""
    h = (verdict or {}).get("heldout") or {}
    try:
        nom, aug = float(h["nrmse_nominal"]), float(h["nrmse_augmented"])
    except (KeyError, TypeError, ValueError):
        return None, None, None
    if not nom > 0:
        return None, nom, aug
    return 1.0 - aug / nom, nom, aug


# ====================================================================== summary
def pct(x):
    """Percentage string of a fraction or '-'."""
    return "-" if x is None else f"{100 * x:.0f} %"


def summarise(results, labels):
    """Compute the issue-14 figures from the per-case results and labels."""
    S = {}
    rows = []
    for r in results:
        lab = labels[r["id"]]
        row = dict(id=r["id"], cat=lab["category"], fs=lab["fs"], design=lab["design"],
                   fmt=lab["format"], rc=r["rc"], seconds=round(r["seconds"], 2),
                   stderr=r["stderr"][:300])
        out = r["out"]
        if lab["task"] == "identify":
            e = ident_error(out) if out else None
            usable = None if out is None else out.get("usable", True)
            row.update(usable=usable, err=e)
            rej, p, where = offset_verdict(out) if out else (None, None, None)
            row.update(offset_rejected=rej, offset_p=p, offset_key=where)
            row["pass"] = bool(r["rc"] == 0 and usable is not False and e is not None and
                               e["max_db"] <= TARGET_DB and e["max_deg"] <= TARGET_DEG)
        else:
            names = named(out)
            truth = lab["effects"]
            sh, nom, aug = shrink(out)
            fl = flagged(out) if out else None
            row.update(named=names, truth=[t["form"] + "->" + "|".join(t["accept"]) for t in truth],
                       shrink=sh, nrmse_nominal=nom, nrmse_augmented=aug, flag=fl,
                       noise_floor=(out or {}).get("noise_floor_nrmse"))
            row["worse_unflagged"] = bool(sh is not None and aug > nom * (1 + 1e-6) and not fl)
            row["unknown_names"] = [n for n in names if n not in TOOL_NAMES]
        rows.append(row)
    by = lambda *cats: [x for x in rows if x["cat"] in cats]  # noqa: E731
    ok = lambda x: x["rc"] == 0  # noqa: E731

    # identification
    idr = by("ident")
    S["identify"] = dict(
        n=len(idr), passed=sum(x["pass"] for x in idr), exit0=sum(ok(x) for x in idr),
        per_case=[dict(id=x["id"], design=x["design"], fs=x["fs"], rc=x["rc"], usable=x["usable"],
                       max_db=None if not x["err"] else round(x["err"]["max_db"], 3),
                       max_deg=None if not x["err"] else round(x["err"]["max_deg"], 2),
                       g0_db=None if not x["err"] else round(x["err"]["g0_db"], 3),
                       offset_rejected=x["offset_rejected"], offset_p=x["offset_p"])
                  for x in idr])
    fams = {}
    for x in idr:
        k = next((p for p in ("paper", "lin", "log", "ms", "prbs", "rlev", "steps", "cl", "mix")
                  if x["design"].startswith(p)), x["design"])
        d = fams.setdefault(k, dict(n=0, passed=0, worst_db=0.0, worst_deg=0.0, rates=[]))
        d["n"] += 1
        d["passed"] += int(x["pass"])
        d["rates"].append(x["fs"])
        e = x["err"] or dict(max_db=float("inf"), max_deg=float("inf"))
        d["worst_db"] = max(d["worst_db"], e["max_db"])
        d["worst_deg"] = max(d["worst_deg"], e["max_deg"])
    S["identify"]["per_design"] = fams
    tested = [x for x in idr if x["offset_rejected"] is not None]
    S["offset_test"] = dict(reported=len(tested), rejected=sum(x["offset_rejected"] for x in tested),
                            false_rejection=(sum(x["offset_rejected"] for x in tested) / len(tested)
                                             if tested else None),
                            key=tested[0]["offset_key"] if tested else None)
    # singles: top-1 per family
    sg = by("single", "single_cl")
    fam = {}
    for x in sg:
        lab = labels[x["id"]]
        t = lab["effects"][0]
        top = x["named"][0] if x["named"] else "none"
        d = fam.setdefault(t["family"], dict(n=0, top1=0, got=[]))
        d["n"] += 1
        d["top1"] += int(top in t["accept"])
        d["got"].append(f"{x['id']}:{t['form']}->{top}")
    S["singles"] = dict(n=len(sg), top1=sum(d["top1"] for d in fam.values()),
                        frac=(sum(d["top1"] for d in fam.values()) / len(sg)) if sg else None,
                        per_family=fam)
    # pairs and triples
    for key, cats in (("pairs", ("pair", "pair_cl")), ("triples", ("triple",))):
        xs = by(*cats)
        tp_n = tp_t = nn = nt = 0
        per = []
        for x in xs:
            truth = labels[x["id"]]["effects"]
            a, b = match(x["named"], truth)
            tp_n, tp_t, nn, nt = tp_n + a, tp_t + b, nn + len(x["named"]), nt + len(truth)
            per.append(f"{x['id']}: {[t['form'] for t in truth]} -> {x['named']}")
        S[key] = dict(n=len(xs), precision=(tp_n / nn) if nn else (None if not xs else 0.0),
                      recall=(tp_t / nt) if nt else None, named=nn, truth=nt, per_case=per)
    # effect-free false alarms
    fr = by("free")
    fa = [x for x in fr if x["named"] or not ok(x)]
    S["effect_free"] = dict(n=len(fr), clean=sum(1 for x in fr if ok(x) and not x["named"]),
                            false_alarm=sum(1 for x in fr if x["named"]),
                            failed=sum(1 for x in fr if not ok(x)),
                            per_case=[f"{x['id']}({x['design']},{x['fs']} Hz): rc={x['rc']} {x['named']}"
                                      for x in fa])
    # near floor
    nf = by("near_floor")
    S["near_floor"] = dict(
        n=len(nf),
        false_attribution=sum(1 for x in nf
                              if any(n not in sum((t["accept"] for t in labels[x["id"]]["effects"]), [])
                                     for n in x["named"])),
        none=sum(1 for x in nf if not x["named"]),
        right=sum(1 for x in nf if x["named"] and x["named"][0] in labels[x["id"]]["effects"][0]["accept"]),
        per_case=[f"{x['id']}:{labels[x['id']]['effects'][0]['form']}"
                  f"(rms/sigma={labels[x['id']]['effect_rms_over_white_sigma']:.2f}) -> {x['named']}"
                  for x in nf])
    # shrink
    eff = by("single", "single_cl", "pair", "pair_cl", "triple")
    sh = np.array([x["shrink"] for x in eff if x["shrink"] is not None])
    allx = [x for x in rows if x["cat"] != "ident"]
    S["shrink"] = dict(
        n=int(sh.size), median=float(np.median(sh)) if sh.size else None,
        p10=float(np.percentile(sh, 10)) if sh.size else None,
        worst=float(np.min(sh)) if sh.size else None,
        worst_case=(min(((x["shrink"], x["id"]) for x in eff if x["shrink"] is not None),
                        default=(None, None))[1]),
        worse_than_nominal=[x["id"] for x in allx if x.get("shrink") is not None and x["shrink"] < 0],
        worse_unflagged=[x["id"] for x in allx if x.get("worse_unflagged")])
    # time
    sec = np.array([x["seconds"] for x in rows])
    S["seconds"] = dict(total=float(sec.sum()) if sec.size else 0.0,
                        median=float(np.median(sec)) if sec.size else None,
                        max=float(sec.max()) if sec.size else None,
                        per_case={x["id"]: x["seconds"] for x in rows})
    S["failures"] = [f"{x['id']}: rc={x['rc']} {x['stderr']}" for x in rows if x["rc"] != 0]
    S["unknown_names"] = sorted({n for x in rows for n in x.get("unknown_names", [])})
    return S, rows


def report(S):
    """Human-readable summary lines."""
    L = []
    i = S["identify"]
    L.append(f"IDENTIFY: {i['passed']}/{i['n']} within {TARGET_DB} dB and {TARGET_DEG} deg over "
             f"{BAND[0]}-{BAND[1]} Hz (exit 0: {i['exit0']})")
    L.append(f"  {'id':5s} {'design':14s} {'fs':>6s} {'rc':>7s} {'usable':>6s} {'dB':>7s} {'deg':>7s} "
             f"{'G0 dB':>7s} offset-test")
    for c in i["per_case"]:
        L.append(f"  {c['id']:5s} {c['design']:14s} {c['fs']:6d} {str(c['rc']):>7s} {str(c['usable']):>6s} "
                 f"{str(c['max_db']):>7s} {str(c['max_deg']):>7s} {str(c['g0_db']):>7s} "
                 f"{'-' if c['offset_rejected'] is None else ('REJECT' if c['offset_rejected'] else 'ok')}"
                 f"{'' if c['offset_p'] is None else ' p=%.3g' % c['offset_p']}")
    for k, d in sorted(i.get("per_design", {}).items()):
        L.append(f"  design {k:14s} {d['passed']}/{d['n']} pass, worst {d['worst_db']:.2f} dB "
                 f"{d['worst_deg']:.1f} deg, rates {sorted(set(d['rates']))}")
    o = S["offset_test"]
    L.append(f"OFFSET TEST: false rejections {o['rejected']}/{o['reported']} ({pct(o['false_rejection'])}),"
             f" key {o['key']}")
    s = S["singles"]
    L.append(f"SINGLES top-1: {s['top1']}/{s['n']} ({pct(s['frac'])})")
    for f, d in sorted(s["per_family"].items()):
        L.append(f"  {f:20s} {d['top1']}/{d['n']}   " + "; ".join(d["got"]))
    for k in ("pairs", "triples"):
        d = S[k]
        L.append(f"{k.upper()}: precision {pct(d['precision'])} ({d['named']} named), recall "
                 f"{pct(d['recall'])} ({d['truth']} true), n={d['n']}")
        L += ["  " + x for x in d["per_case"]]
    e = S["effect_free"]
    L.append(f"EFFECT-FREE: no effect named on {e['clean']}/{e['n']}; false alarms {e['false_alarm']},"
             f" failed runs {e['failed']}")
    L += ["  " + x for x in e["per_case"]]
    n = S["near_floor"]
    L.append(f"NEAR-FLOOR: false attributions {n['false_attribution']}/{n['n']} (none {n['none']},"
             f" right {n['right']})")
    L += ["  " + x for x in n["per_case"]]
    h = S["shrink"]
    L.append(f"HELD-OUT SHRINK (effect cases, n={h['n']}): median {pct(h['median'])}, p10 {pct(h['p10'])},"
             f" worst {pct(h['worst'])} ({h['worst_case']}); worse than nominal: {h['worse_than_nominal']};"
             f" of which unflagged: {h['worse_unflagged']}")
    t = S["seconds"]
    L.append(f"SECONDS: total {t['total']:.0f}, median {t['median']:.1f} per case, max {t['max']:.1f}")
    if S["failures"]:
        L.append("NON-ZERO EXITS:")
        L += ["  " + x for x in S["failures"]]
    if S["unknown_names"]:
        L.append(f"NAMES OUTSIDE interfaces.md: {S['unknown_names']}")
    return "\n".join(L)


def load_corpus(corpus, prefixes, quick):
    """Cases (with their directory) and labels, filtered by id prefixes."""
    cases, labels = [], {}
    for cj in sorted(glob.glob(os.path.join(corpus, "cases", "*", "case.json"))):
        with open(cj) as fh:
            c = json.load(fh)
        c["dir"] = os.path.dirname(cj)
        if prefixes and not any(c["id"].startswith(p) for p in prefixes):
            continue
        with open(os.path.join(corpus, "labels", c["id"] + ".json")) as fh:
            labels[c["id"]] = json.load(fh)
        cases.append(c)
    if quick and not prefixes:
        pick, seen = [], set()
        for c in cases:
            cat = labels[c["id"]]["category"]
            if cat in ("ident", "free", "single") and cat not in seen:
                seen.add(cat)
                pick.append(c)
        cases = pick
    return cases, labels


def main(argv=None):
    """CLI."""
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--corpus", required=True)
    ap.add_argument("--hasel", required=True, help="path of the hasel executable")
    ap.add_argument("--jobs", type=int, default=1, help="cases run at once (each diagnose uses --jobs 1)")
    ap.add_argument("--timeout", type=float, default=600.0, help="seconds per case")
    ap.add_argument("--json", help="write the summary and per-case rows here")
    ap.add_argument("--quick", action="store_true", help="one identify, one effect-free, one single case")
    ap.add_argument("--cases", default="", help="comma-separated id prefixes")
    ap.add_argument("--work", help="folder for the tool's outputs (default: a temporary one)")
    a = ap.parse_args(argv)
    cases, labels = load_corpus(a.corpus, [p for p in a.cases.split(",") if p], a.quick)
    if not cases:
        print("no cases", file=sys.stderr)
        return 2
    work = a.work or tempfile.mkdtemp(prefix="verify3_")
    os.makedirs(work, exist_ok=True)
    t0 = time.time()
    results = []
    with cf.ThreadPoolExecutor(max_workers=max(1, a.jobs)) as ex:
        futs = {ex.submit(run_case, c, a.hasel, work, a.timeout): c for c in cases}
        for fu in cf.as_completed(futs):
            r = fu.result()
            results.append(r)
            print(f"[{len(results):3d}/{len(cases)}] {r['id']:5s} rc={r['rc']} {r['seconds']:6.1f} s",
                  file=sys.stderr, flush=True)
    results.sort(key=lambda r: r["id"])
    S, rows = summarise(results, labels)
    S["wall_s"] = time.time() - t0
    S["hasel"] = a.hasel
    S["corpus"] = os.path.abspath(a.corpus)
    print(report(S))
    if a.json:
        with open(a.json, "w") as fh:
            json.dump(dict(summary=S, rows=rows), fh, indent=1, default=str)
    return 0


if __name__ == "__main__":
    sys.exit(main())
