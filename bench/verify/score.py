"""Score `hasel identify` / `hasel diagnose` on the verification corpus (black box).

    python bench/verify/score.py --corpus bench/verify/out [--only ident|diagnose]
        [--jobs N] [--quick] [--hasel PATH] [--timeout S] [--json FILE]

Runs the CLI as a subprocess on every case, reads only its JSON output and exit code,
compares with the hidden labels, prints a table and writes a JSON (default
CORPUS/score.json). A timeout counts as a failure of the case.
"""
from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import time
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))
import plant as pl  # noqa: E402

NAMES = ["static_nonlinearity", "asymmetric_dynamics", "charge_drift", "saturation",
         "time_delay", "sensor_nonlinearity", "load_mass", "hysteresis"]
QUICK = ["free00", "free03", "single00", "single09", "near00", "pair00", "triple00", "closed00",
         "id00", "id09"]
# Words that would mark a verdict as saying "the augmented model is worse" or "did not
# generalise"; any key or string value containing one counts as a flag.
FLAG_WORDS = ("worse", "generalis", "generaliz", "flag")


def run_case(hasel: str, corpus: Path, lab: dict, outdir: Path, timeout: float, reuse: bool = False) -> dict:
    """Run the CLI on one case; returns exit code, seconds, stderr's last line, JSON.
    With `reuse`, a case already run (its .meta.json exists) is read back instead."""
    cdir = corpus / "cases" / lab["id"]
    out_json = outdir / f"{lab['id']}.json"
    args = lab["train"]["args"]
    if lab["kind"] == "ident":
        cmd = [hasel, "identify", lab["train"]["file"], "--json", str(out_json)] + args
    else:
        cmd = [hasel, "diagnose", lab["train"]["file"], "--model", "model.json", "--json", str(out_json)] + args
        if "heldout" in lab:
            cmd += ["--heldout", lab["heldout"]["file"]]
    meta = outdir / f"{lab['id']}.meta.json"
    if reuse and meta.exists():
        res = json.loads(meta.read_text())
        if out_json.exists():
            res["out"] = json.loads(out_json.read_text())
        return res
    out_json.unlink(missing_ok=True)
    t0 = time.monotonic()
    try:
        p = subprocess.run(cmd, cwd=cdir, capture_output=True, text=True, timeout=timeout)
        rc, err = p.returncode, p.stderr
    except subprocess.TimeoutExpired as e:
        rc = "timeout"
        err = (e.stderr.decode() if isinstance(e.stderr, bytes) else e.stderr) or ""
    dt = time.monotonic() - t0
    lines = [ln for ln in err.splitlines() if ln.strip()]
    # The line that matters: a traceback's last line, an error line, or the last line.
    last = next((ln for ln in reversed(lines) if "Error" in ln or "error" in ln), lines[-1] if lines else "")
    if rc == "timeout":
        last = f"timeout after {timeout:.0f} s (last stderr line: {last[:150]})"
    res = {"id": lab["id"], "rc": rc, "seconds": round(dt, 2), "stderr_last": last[:300],
           "traceback": "Traceback" in err, "cmd": " ".join(cmd)}
    meta.write_text(json.dumps(res))
    if out_json.exists():
        try:
            res["out"] = json.loads(out_json.read_text())
        except ValueError as e:
            res["out_error"] = str(e)
    return res


# ----------------------------------------------------------------------------- identify
def ident_error(out: dict) -> dict:
    """Largest magnitude (dB) and phase (deg) error of the identified model (with its
    delay_s) against the true P(s) over 0.1-15 Hz; also without the delay."""
    f = np.logspace(np.log10(0.1), np.log10(15.0), 300)
    num, den = pl.paper_tf()
    P = pl.freq_response(num, den, f)
    r = {}
    for key, d in (("", float(out.get("delay_s") or 0.0)), ("_no_delay", 0.0)):
        M = pl.freq_response(np.asarray(out["num"], float), np.asarray(out["den"], float), f, d)
        ratio = M / P
        r["err_db" + key] = float(np.max(np.abs(20 * np.log10(np.abs(ratio)))))
        r["err_deg" + key] = float(np.max(np.abs(np.degrees(np.angle(ratio)))))
    return r


def score_ident(labels: dict, results: list) -> dict:
    """Identification: error per case and per design, usable flags, exit codes, and the
    offset-dependence test's false rejections at p = 0.05 (all logs are LTI)."""
    rows, rej, n_test = [], 0, 0
    for res in results:
        lab = labels[res["id"]]
        out = res.get("out") or {}
        row = {"id": res["id"], "design": lab["design"], "fs": lab["fs"], "format": lab["format"],
               "precond": lab.get("precond"), "settle_s": lab.get("settle_s"), "rc": res["rc"],
               "seconds": res["seconds"], "usable": out.get("usable"), "category": lab["category"],
               "stderr_last": res["stderr_last"] if res["rc"] != 0 else ""}
        if "num" in out and "den" in out:
            try:
                row.update(ident_error(out))
            except (ValueError, TypeError, ZeroDivisionError) as e:
                row["err_note"] = f"model unreadable: {e}"
            row["g0"] = float(out["num"][-1] / out["den"][-1]) if out["den"][-1] else None
            row["delay_s"] = out.get("delay_s")
        od = out.get("offset_dependence") or {}
        pv = od.get("p_value")
        row["offset_p"] = pv
        if pv is not None and len(od.get("offsets") or []) >= 2:
            n_test += 1
            rej += pv < 0.05
        row["ok_1db_5deg"] = bool(row.get("err_db", 99) <= 1.0 and row.get("err_deg", 999) <= 5.0)
        rows.append(row)
    by_design: dict = {}
    for r in rows:
        if r["category"] != "ident":
            continue
        k = f"{r['design']}@{r['fs']:g}"
        by_design.setdefault(k, []).append(r)
    design_tab = {k: {"n": len(v), "err_db": [x.get("err_db") for x in v], "err_deg": [x.get("err_deg") for x in v],
                      "ok": sum(x["ok_1db_5deg"] for x in v), "rc": [x["rc"] for x in v],
                      "usable": [x["usable"] for x in v]} for k, v in sorted(by_design.items())}
    return {"cases": rows, "by_design": design_tab,
            "within_1db_5deg": sum(r["ok_1db_5deg"] for r in rows), "n": len(rows),
            "offset_test": {"n": n_test, "rejected_at_0.05": int(rej),
                            "false_rejection_rate": (rej / n_test) if n_test else None},
            "exit_codes": _count([r["rc"] for r in rows])}


# ----------------------------------------------------------------------------- diagnose
def _flags(verdict: dict) -> list:
    """Keys or string values of the verdict that look like a 'worse than nominal' or
    'did not generalise' flag (any depth)."""
    hits = []

    def walk(o, path):
        if isinstance(o, dict):
            for k, v in o.items():
                if any(w in k.lower() for w in FLAG_WORDS) and v not in (None, False, [], {}, ""):
                    hits.append(f"{path}/{k}")
                walk(v, f"{path}/{k}")
        elif isinstance(o, list):
            for i, v in enumerate(o):
                walk(v, f"{path}[{i}]")
        elif isinstance(o, str) and any(w in o.lower() for w in ("worse", "generalis", "generaliz")):
            hits.append(f"{path}: {o[:80]}")

    walk(verdict, "")
    return hits


def _count(xs) -> dict:
    out: dict = {}
    for x in xs:
        out[str(x)] = out.get(str(x), 0) + 1
    return out


def score_diagnose(labels: dict, results: list) -> dict:
    """Diagnosis: top-1 per effect (singles), precision/recall of the named set
    (pairs, triples), false alarms (effect-free), false attributions (near-floor),
    held-out shrink distribution and unflagged worsening, seconds per case."""
    rows = []
    for res in results:
        lab = labels[res["id"]]
        v = res.get("out") or {}
        named = [e.get("name") for e in v.get("effects", []) if isinstance(e, dict)]
        truth = [e["name"] for e in lab["effects"]]
        h = v.get("heldout") or {}
        nom, aug = h.get("nrmse_nominal"), h.get("nrmse_augmented")
        shrink = (nom - aug) / nom if (nom and aug is not None) else None
        rows.append({"id": res["id"], "category": lab["category"], "fs": lab["fs"], "format": lab["format"],
                     "design": lab["design"], "noise": lab["noise"], "convention": lab["convention"],
                     "timing_offset_s": lab["timing_offset_s"], "closed_loop": lab["closed_loop"],
                     "truth": truth, "forms": [e["form"] for e in lab["effects"]], "named": named,
                     "rc": res["rc"], "seconds": res["seconds"], "n_samples": lab["n_samples"],
                     "nrmse_nominal": nom, "nrmse_augmented": aug, "shrink": shrink,
                     "noise_floor_nrmse": v.get("noise_floor_nrmse"),
                     "worse_than_nominal": bool(nom is not None and aug is not None and aug > nom),
                     "flags": _flags(v) if v else [], "usable": v.get("usable"),
                     "stderr_last": res["stderr_last"] if res["rc"] != 0 else ""})
    ok = [r for r in rows if r["rc"] == 0]
    # Single effects: top-1 per true name (a failed run counts as a miss).
    singles = [r for r in rows if r["category"] == "single"]
    per_name = {n: {"n": 0, "top1": 0, "named_first": []} for n in NAMES}
    for r in singles:
        d = per_name[r["truth"][0]]
        d["n"] += 1
        d["top1"] += bool(r["named"] and r["named"][0] == r["truth"][0])
        d["named_first"].append(r["named"][0] if r["named"] else "none")
    n_single = len(singles)
    top1 = sum(d["top1"] for d in per_name.values())
    # Pairs and triples: micro-averaged precision and recall of the named set.
    multi = {}
    for cat in ("pair", "triple"):
        rs = [r for r in rows if r["category"] == cat]
        tp = sum(len(set(r["named"]) & set(r["truth"])) for r in rs)
        nn = sum(len(set(r["named"])) for r in rs)
        nt = sum(len(set(r["truth"])) for r in rs)
        multi[cat] = {"n": len(rs), "precision": tp / nn if nn else None, "recall": tp / nt if nt else None,
                      "tp": tp, "named": nn, "true": nt}
    free = [r for r in rows if r["category"] == "effect_free"]
    fa = [r for r in free if r["named"]]
    near = [r for r in rows if r["category"] == "near_floor"]
    fattr = [r for r in near if set(r["named"]) - set(r["truth"])]
    near_right = [r for r in near if r["named"] and set(r["named"]) <= set(r["truth"])]
    eff_rows = [r for r in rows if r["category"] in ("single", "pair", "triple") and r["shrink"] is not None]
    shr = np.array([r["shrink"] for r in eff_rows]) if eff_rows else np.array([])
    worse = [r for r in rows if r["worse_than_nominal"]]
    secs = np.array([r["seconds"] for r in rows]) if rows else np.array([0.0])
    return {
        "cases": rows,
        "single": {"n": n_single, "top1": top1, "top1_rate": top1 / n_single if n_single else None,
                   "per_name": per_name},
        "multi": multi,
        "effect_free": {"n": len(free), "false_alarms": len(fa), "rate_clean": 1 - len(fa) / len(free) if free else None,
                        "named": {r["id"]: r["named"] for r in fa}},
        "near_floor": {"n": len(near), "false_attributions": len(fattr), "named_right": len(near_right),
                       "none": sum(not r["named"] for r in near),
                       "wrong": {r["id"]: {"truth": r["truth"], "named": r["named"]} for r in fattr}},
        "shrink": {"n": int(shr.size), "median": float(np.median(shr)) if shr.size else None,
                   "worst": float(np.min(shr)) if shr.size else None,
                   "p10": float(np.quantile(shr, 0.1)) if shr.size else None},
        "worse_than_nominal": {"n": len(worse), "flagged": sum(bool(r["flags"]) for r in worse),
                               "cases": {r["id"]: {"shrink": r["shrink"], "flags": r["flags"][:3] or "not flagged"}
                                         for r in worse}},
        "seconds": {"median": float(np.median(secs)), "max": float(np.max(secs)), "total": float(np.sum(secs))},
        "exit_codes": _count([r["rc"] for r in rows]),
        "ran_ok": len(ok),
    }


# ----------------------------------------------------------------------------- report
def _f(x, fmt="{:.2f}"):
    return "-" if x is None else fmt.format(x)


def print_tables(s: dict) -> str:
    """Human-readable tables of a score dict; returns the text."""
    L = []
    if "diagnose" in s:
        d = s["diagnose"]
        L.append("## diagnose")
        L.append(f"exit codes {d['exit_codes']}; seconds per case median {d['seconds']['median']:.1f}, "
                 f"max {d['seconds']['max']:.1f}, total {d['seconds']['total']:.0f}")
        sg = d["single"]
        L.append(f"single effects top-1: {sg['top1']}/{sg['n']} ({_f(sg['top1_rate'], '{:.0%}')})")
        L.append("| effect | n | top-1 | named first |")
        L.append("|---|---|---|---|")
        for n, v in sg["per_name"].items():
            if v["n"]:
                L.append(f"| {n} | {v['n']} | {v['top1']} | {', '.join(v['named_first'])} |")
        for cat, m in d["multi"].items():
            L.append(f"{cat}s: n {m['n']}, precision {_f(m['precision'])} ({m['tp']}/{m['named']}), "
                     f"recall {_f(m['recall'])} ({m['tp']}/{m['true']})")
        ef = d["effect_free"]
        L.append(f"effect-free: {ef['n'] - ef['false_alarms']}/{ef['n']} with no effect named "
                 f"(false alarms {ef['false_alarms']}: {ef['named']})")
        nf = d["near_floor"]
        L.append(f"near-floor: n {nf['n']}, none {nf['none']}, right name {nf['named_right']}, "
                 f"false attributions {nf['false_attributions']}: {nf['wrong']}")
        sh = d["shrink"]
        L.append(f"held-out shrink (effect cases, n {sh['n']}): median {_f(sh['median'], '{:.0%}')}, "
                 f"10th pct {_f(sh['p10'], '{:.0%}')}, worst {_f(sh['worst'], '{:.0%}')}")
        w = d["worse_than_nominal"]
        L.append(f"augmented worse than nominal: {w['n']} (flagged {w['flagged']}): {w['cases']}")
        L.append("")
        L.append("| case | fs | fmt | truth | named | shrink | rc | s |")
        L.append("|---|---|---|---|---|---|---|---|")
        for r in d["cases"]:
            L.append(f"| {r['id']} | {r['fs']:g} | {r['format']} | {'+'.join(r['forms']) or '-'} | "
                     f"{','.join(r['named']) or 'none'} | {_f(r['shrink'], '{:.0%}')} | {r['rc']} | {r['seconds']:.0f} |"
                     + (f" {r['stderr_last'][:100]}" if r["stderr_last"] else ""))
    if "ident" in s:
        d = s["ident"]
        L.append("## identify")
        L.append(f"exit codes {d['exit_codes']}; within 1 dB and 5 deg over 0.1-15 Hz: {d['within_1db_5deg']}/{d['n']}")
        ot = d["offset_test"]
        L.append(f"offset-dependence test on LTI logs: rejected at p<0.05 in {ot['rejected_at_0.05']}/{ot['n']} "
                 f"(false rejection rate {_f(ot['false_rejection_rate'], '{:.0%}')})")
        L.append("| design @ rate | n | within 1 dB/5 deg | worst dB | worst deg | exit codes | usable |")
        L.append("|---|---|---|---|---|---|---|")
        for k, v in d["by_design"].items():
            db = [x for x in v["err_db"] if x is not None]
            dg = [x for x in v["err_deg"] if x is not None]
            L.append(f"| {k} | {v['n']} | {v['ok']} | {_f(max(db) if db else None)} | "
                     f"{_f(max(dg) if dg else None, '{:.1f}')} | {_count(v['rc'])} | {_count(v['usable'])} |")
        L.append("")
        L.append("| case | design | fs | fmt | precond | settle | rc | usable | dB | deg | dB/deg w/o delay | G(0) | p | s |")
        L.append("|---|---|---|---|---|---|---|---|---|---|---|---|---|---|")
        for r in d["cases"]:
            L.append(f"| {r['id']} | {r['design']} | {r['fs']:g} | {r['format']} | {r['precond']} | {r['settle_s']} | "
                     f"{r['rc']} | {r['usable']} | {_f(r.get('err_db'))} | {_f(r.get('err_deg'), '{:.1f}')} | "
                     f"{_f(r.get('err_db_no_delay'))}/{_f(r.get('err_deg_no_delay'), '{:.1f}')} | {_f(r.get('g0'), '{:.3f}')} | "
                     f"{_f(r['offset_p'], '{:.3g}')} | {r['seconds']:.0f} |"
                     + (f" {r['stderr_last'][:100]}" if r["stderr_last"] else ""))
    txt = "\n".join(L)
    print(txt)
    return txt


def main(argv=None) -> int:
    """Command line: run and score; exit 0 when the scorer itself worked."""
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--corpus", default=str(HERE / "out"))
    ap.add_argument("--only", choices=["ident", "diagnose"])
    ap.add_argument("--jobs", type=int, default=1)
    ap.add_argument("--quick", action="store_true")
    ap.add_argument("--cases", default="", help="comma-separated case id prefixes")
    ap.add_argument("--hasel", default=str(HERE.parents[1] / ".venv" / "bin" / "hasel"))
    ap.add_argument("--timeout", type=float, default=180.0)
    ap.add_argument("--json", default=None)
    ap.add_argument("--reuse", action="store_true", help="read back cases already run instead of running them")
    ap.add_argument("--work", default=None,
                    help="folder for the tool's outputs (default CORPUS/runs; give one per scorer run at once)")
    a = ap.parse_args(argv)
    corpus = Path(a.corpus).resolve()
    labels = {p.stem: json.loads(p.read_text()) for p in sorted((corpus / "labels").glob("*.json"))}
    ids = sorted(labels)
    if a.quick:
        ids = [i for i in ids if any(i.startswith(q) for q in QUICK)]
    if a.cases:
        ids = [i for i in ids if any(i.startswith(q) for q in a.cases.split(","))]
    if a.only:
        ids = [i for i in ids if labels[i]["kind"] == a.only]
    outdir = Path(a.work) if a.work else corpus / "runs"
    outdir.mkdir(parents=True, exist_ok=True)
    hasel = str(Path(a.hasel).resolve())

    def one(i):
        r = run_case(hasel, corpus, labels[i], outdir, a.timeout, a.reuse)
        print(f"{i:60s} rc={r['rc']} {r['seconds']:6.1f} s", file=sys.stderr, flush=True)
        return r

    t0 = time.monotonic()
    with ThreadPoolExecutor(max_workers=max(1, a.jobs)) as ex:
        results = list(ex.map(one, ids))
    score = {"corpus": str(corpus), "hasel": hasel, "wall_s": round(time.monotonic() - t0, 1),
             "jobs": a.jobs, "git": _git_rev()}
    di = [r for r in results if labels[r["id"]]["kind"] == "diagnose"]
    idr = [r for r in results if labels[r["id"]]["kind"] == "ident"]
    if di:
        score["diagnose"] = score_diagnose(labels, di)
    if idr:
        score["ident"] = score_ident(labels, idr)
    crashes = [{"id": r["id"], "rc": r["rc"], "stderr": r["stderr_last"]} for r in results
               if r["rc"] not in (0,) or r["traceback"]]
    score["failures"] = crashes
    txt = print_tables(score)
    if crashes:
        print("\nfailures (exit != 0, timeouts, tracebacks):")
        for c in crashes:
            print(f"  {c['id']}: rc {c['rc']}: {c['stderr']}")
    out = Path(a.json) if a.json else corpus / "score.json"
    out.write_text(json.dumps(score, indent=1, default=str))
    (out.with_suffix(".md")).write_text(txt + "\n")
    return 0


def _git_rev() -> str:
    try:
        return subprocess.run(["git", "rev-parse", "--short", "HEAD"], cwd=HERE, capture_output=True,
                              text=True).stdout.strip()
    except OSError:
        return ""


if __name__ == "__main__":
    os.environ.setdefault("PYTHONUNBUFFERED", "1")
    raise SystemExit(main())
