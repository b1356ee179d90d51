"""Score `hasel` (as a black box) on the verify2 corpus.

    python score.py --corpus DIR --hasel PATH [--jobs N] [--timeout S] [--only ident|diagnose]
                    [--tool-jobs N] [--work DIR] --json FILE

Runs `hasel identify` / `hasel diagnose` once per case (in the case's folder, with the
arguments its label lists), reads the JSON the tool writes and the labels, and reports
what issue 14's Figures list. Writes FILE (JSON) and FILE with .md (readable).
Units: s, dB, degrees, Hz.
"""
from __future__ import annotations

import argparse
import concurrent.futures as cf
import json
import os
import statistics
import subprocess
import time

import numpy as np

NAMES = ["static_nonlinearity", "asymmetric_dynamics", "charge_drift", "saturation",
         "time_delay", "sensor_nonlinearity", "load_mass", "hysteresis"]
BAND_HZ = (0.1, 15.0)
TOL_DB, TOL_DEG = 1.0, 5.0
# what this scorer counts as the verdict flagging a held-out result (read from the JSON)
FLAG_RULES = [
    "exit code != 0",
    "\"usable\": false",
    "a non-empty \"dropped\" list (effects seen in training that did not generalise)",
    "a truthy key named warning/warnings/flag/flags/worse anywhere in the verdict",
    "a string anywhere in the verdict's \"heldout\" part containing 'worse'",
]


def run_case(label, corpus, hasel, work, timeout, tool_jobs):
    """Run the tool on one case; returns a dict with rc, seconds, stderr tail, JSON."""
    cid = label["id"]
    cdir = os.path.join(corpus, "cases", cid)
    out = os.path.join(work, cid + ".json")
    if os.path.exists(out):
        os.remove(out)
    sub = "identify" if label["kind"] == "ident" else "diagnose"
    cmd = [hasel, sub] + list(label["args"]) + ["--json", out]
    if label["kind"] == "diagnose" and tool_jobs:
        cmd += ["--jobs", str(tool_jobs)]
    t0 = time.monotonic()
    try:
        p = subprocess.run(cmd, cwd=cdir, capture_output=True, text=True, timeout=timeout)
        rc, err, outtxt = p.returncode, p.stderr, p.stdout
    except subprocess.TimeoutExpired:
        rc, err, outtxt = "timeout", "", ""
    dt = time.monotonic() - t0
    js = None
    if os.path.exists(out):
        try:
            with open(out) as fh:
                js = json.load(fh)
        except (OSError, ValueError):
            js = None
    tail = [ln for ln in (err or "").strip().splitlines() if ln.strip()]
    return {"id": cid, "rc": rc, "seconds": dt, "stderr_last": tail[-1] if tail else "",
            "stdout_head": (outtxt or "").strip().splitlines()[:1], "json": js,
            "cmd": " ".join(cmd[1:])}


# ------------------------------------------------------------------ identification

def tf_response(num, den, f, delay=0.0):
    """Frequency response of num/den (descending powers of s) at f (Hz), with a delay (s)."""
    s = 2j * np.pi * np.asarray(f, float)
    return np.polyval(num, s) / np.polyval(den, s) * np.exp(-s * delay)


def find_dependence(js):
    """(p-value, verdict text) of an offset-dependence test found in a model JSON, or
    (None, None). Looks for a dict whose path mentions 'depend' and a p-like key."""
    found = [None, None]

    def walk(o, path):
        if isinstance(o, dict):
            for k, v in o.items():
                pk = (path + "/" + k).lower()
                if "depend" in pk and isinstance(v, (int, float)) and not isinstance(v, bool) \
                        and k.lower() in ("p", "p_value", "pvalue", "p_val") and found[0] is None:
                    found[0] = float(v)
                if "depend" in pk and isinstance(v, str) and found[1] is None and \
                        k.lower() in ("verdict", "dependence", "offset_dependence", "result"):
                    found[1] = v
                walk(v, pk)
        elif isinstance(o, list):
            for i, v in enumerate(o):
                walk(v, path + f"[{i}]")

    walk(js, "")
    return found[0], found[1]


def score_ident(label, res):
    """Per-case identification figures."""
    tr = label["truth"]
    f = np.logspace(np.log10(BAND_HZ[0]), np.log10(BAND_HZ[1]), 200)
    P = tf_response(tr["num"], tr["den"], f)
    row = {"id": label["id"], "design": label["design_name"], "rate_hz": label["rate_hz"],
           "format": label["format"], "convention": label["convention"], "rc": res["rc"],
           "seconds": res["seconds"], "stderr_last": res["stderr_last"]}
    js = res["json"] or {}
    row["usable"] = js.get("usable")
    if "num" in js and "den" in js:
        try:
            G = tf_response(js["num"], js["den"], f, float(js.get("delay_s", 0.0) or 0.0))
            r = G / P
            row["err_db_max"] = float(np.max(np.abs(20 * np.log10(np.abs(r)))))
            row["err_deg_max"] = float(np.max(np.abs(np.degrees(np.angle(r)))))
            row["dc_gain"] = float(np.real(tf_response(js["num"], js["den"], [0.0])[0]))
            row["within_tol"] = row["err_db_max"] <= TOL_DB and row["err_deg_max"] <= TOL_DEG
        except (TypeError, ValueError, ZeroDivisionError):
            row["within_tol"] = False
    p, verdict = find_dependence(js)
    row["dependence_p"] = p
    row["dependence_verdict"] = verdict
    row["dependence_rejects"] = (p is not None and p < 0.05) or (
        verdict is not None and verdict.lower().startswith("dependent"))
    return row


# ------------------------------------------------------------------ diagnosis

def flagged(js, rc):
    """(flag?, reasons) under FLAG_RULES."""
    why = []
    if rc != 0:
        why.append(f"exit {rc}")
    if not js:
        return bool(why), why
    if js.get("usable") is False:
        why.append("usable false")
    if js.get("dropped"):
        why.append("dropped: " + ",".join(str(d.get("name", d)) if isinstance(d, dict) else str(d)
                                          for d in js["dropped"]))

    def walk(o, path):
        if isinstance(o, dict):
            for k, v in o.items():
                if k.lower() in ("warning", "warnings", "flag", "flags", "worse") and v:
                    why.append(f"{path}/{k}")
                walk(v, path + "/" + k)
        elif isinstance(o, list):
            for v in o:
                walk(v, path)
        elif isinstance(o, str) and path.startswith("/heldout") and "worse" in o.lower():
            why.append(f"{path}: '{o[:60]}'")

    walk(js, "")
    return bool(why), why


def score_diag(label, res):
    """Per-case diagnosis figures."""
    js = res["json"] or {}
    ok = res["rc"] == 0 and bool(js)
    named = [e.get("name") for e in js.get("effects", [])] if ok else None
    truth = set(label["truth_names"])
    row = {"id": label["id"], "category": label["category"], "closed_loop": label["closed_loop"],
           "truth": sorted(truth), "named": named, "rc": res["rc"], "seconds": res["seconds"],
           "rate_hz": label["rate_hz"], "convention": label["convention"],
           "noise": label["noise"]["kind"] + ("+wander" if label["noise"]["wander_rms_mm"] else ""),
           "effect_rms_over_noise": label["effect_rms_over_noise"],
           "n_train": int(round(label["train_s"] * label["rate_hz"])),
           "train_s": label["train_s"], "stderr_last": res["stderr_last"],
           "forms": [e["name"] + ":" + e["form"] for e in label["effects"]]}
    ho = js.get("heldout") or {}
    nn, na = ho.get("nrmse_nominal"), ho.get("nrmse_augmented")
    if ok and isinstance(nn, (int, float)) and isinstance(na, (int, float)) and nn > 0:
        row["nrmse_nominal"], row["nrmse_augmented"] = nn, na
        row["shrink"] = 1.0 - na / nn
    fl, why = flagged(js, res["rc"])
    row["flagged"], row["flag_reasons"] = fl, why
    row["worse_unflagged"] = (row.get("shrink") is not None and row["shrink"] < -1e-9 and not fl)
    if "timing_offset" in js and isinstance(js["timing_offset"], dict):
        row["timing_offset_samples_reported"] = js["timing_offset"].get("original_samples")
    row["timing_offset_samples_true"] = label.get("timing_offset_samples")
    return row


def pct(x, q):
    """Percentile or None."""
    return float(np.percentile(x, q)) if len(x) else None


def summarise(rows_i, rows_d):
    """The Figures of issue 14 from the per-case rows."""
    S = {}
    if rows_d:
        sing = [r for r in rows_d if r["category"] == "single"]
        per = {}
        for r in sing:
            t = r["truth"][0]
            d = per.setdefault(t, {"n": 0, "top1": 0, "named_instead": []})
            d["n"] += 1
            if r["named"] and r["named"][0] == t:
                d["top1"] += 1
            else:
                d["named_instead"].append(f"{r['id']}: {r['named'] if r['named'] is not None else 'exit ' + str(r['rc'])}")
        S["singles"] = {"n": len(sing), "top1": sum(d["top1"] for d in per.values()),
                        "per_effect": per}
        for cat in ("pair", "triple"):
            rs = [r for r in rows_d if r["category"] == cat]
            tp = sum(len(set(r["named"] or []) & set(r["truth"])) for r in rs)
            nn = sum(len(set(r["named"] or [])) for r in rs)
            nt = sum(len(r["truth"]) for r in rs)
            S[cat + "s"] = {"n": len(rs), "true_pos": tp, "named": nn, "truth": nt,
                            "precision": tp / nn if nn else None, "recall": tp / nt if nt else None,
                            "failed_runs": sum(1 for r in rs if r["rc"] != 0),
                            "cases": [f"{r['id']}: truth {r['truth']} named {r['named']}" for r in rs]}
        free = [r for r in rows_d if r["category"] == "effect_free"]
        fa = [r for r in free if r["named"]]
        S["effect_free"] = {"n": len(free), "false_alarms": len(fa),
                            "no_effect_named": sum(1 for r in free if r["named"] == []),
                            "failed_runs": [f"{r['id']}: exit {r['rc']}: {r['stderr_last'][:160]}"
                                            for r in free if r["rc"] != 0],
                            "alarms": [f"{r['id']} ({r['rate_hz']} Hz, {r['convention']}, {r['noise']}"
                                       f"{', closed loop' if r['closed_loop'] else ''}): {r['named']}"
                                       for r in fa]}
        fl = [r for r in rows_d if r["category"] == "near_floor"]
        S["near_floor"] = {
            "n": len(fl),
            "false_attributions": sum(1 for r in fl if r["named"] and set(r["named"]) - set(r["truth"])),
            "none": sum(1 for r in fl if r["named"] == []),
            "right_only": sum(1 for r in fl if r["named"] and not set(r["named"]) - set(r["truth"])),
            "failed_runs": sum(1 for r in fl if r["rc"] != 0),
            "cases": [f"{r['id']} (ratio {r['effect_rms_over_noise']:.2f}): named {r['named']}" for r in fl]}
        eff = [r for r in rows_d if r["category"] in ("single", "pair", "triple") and "shrink" in r]
        sh = [r["shrink"] for r in eff]
        worst = min(eff, key=lambda r: r["shrink"]) if eff else None
        S["shrink_effect_cases"] = {
            "n": len(sh), "median": pct(sh, 50), "p10": pct(sh, 10), "p25": pct(sh, 25),
            "p75": pct(sh, 75), "min": min(sh) if sh else None,
            "worst": f"{worst['id']} ({worst['forms']}): shrink {worst['shrink']:.3f}, "
                     f"nominal {worst['nrmse_nominal']:.4g}, augmented {worst['nrmse_augmented']:.4g}"
                     if worst else None,
            "negative": sum(1 for x in sh if x < 0)}
        for cat in ("effect_free", "near_floor"):
            x = [r["shrink"] for r in rows_d if r["category"] == cat and "shrink" in r]
            S["shrink_" + cat] = {"n": len(x), "median": pct(x, 50), "min": min(x) if x else None}
        wu = [r for r in rows_d if r["worse_unflagged"]]
        S["worse_unflagged"] = {"n": len(wu), "flag_rules": FLAG_RULES,
                                "cases": [f"{r['id']}: shrink {r['shrink']:.3f} "
                                          f"({r['nrmse_nominal']:.4g} -> {r['nrmse_augmented']:.4g})"
                                          for r in wu],
                                "worse_but_flagged": [f"{r['id']}: shrink {r['shrink']:.3f}: {r['flag_reasons']}"
                                                      for r in rows_d if r.get("shrink", 0) < -1e-9 and r["flagged"]]}
        secs = [r["seconds"] for r in rows_d]
        big = max(rows_d, key=lambda r: r["n_train"])
        S["diagnose_seconds"] = {"n": len(secs), "median": pct(secs, 50), "p90": pct(secs, 90),
                                 "max": max(secs), "total": sum(secs),
                                 "largest_log": f"{big['id']}: {big['n_train']} samples "
                                                f"({big['train_s']:.0f} s at {big['rate_hz']} Hz) "
                                                f"in {big['seconds']:.1f} s",
                                 "slowest": max(rows_d, key=lambda r: r["seconds"])["id"]}
        cl = [r for r in rows_d if r["closed_loop"]]
        S["closed_loop"] = [f"{r['id']}: truth {r['truth']} named {r['named']}" for r in cl]
        S["diagnose_failed_runs"] = [f"{r['id']}: exit {r['rc']}: {r['stderr_last'][:200]}"
                                     for r in rows_d if r["rc"] != 0]
    if rows_i:
        ok = [r for r in rows_i if r["rc"] == 0]
        S["ident"] = {
            "n": len(rows_i), "exit0": len(ok),
            "exit0_within_tol": sum(1 for r in ok if r.get("within_tol")),
            "exit0_outside_tol": [f"{r['id']}: {r.get('err_db_max', float('nan')):.2f} dB, "
                                  f"{r.get('err_deg_max', float('nan')):.1f} deg" for r in ok
                                  if not r.get("within_tol")],
            "refused": [f"{r['id']}: exit {r['rc']}: {r['stderr_last'][:200]}"
                        for r in rows_i if r["rc"] != 0],
            "refused_but_model_within_tol": [r["id"] for r in rows_i
                                             if r["rc"] != 0 and r.get("within_tol")],
            "dependence_tested": sum(1 for r in rows_i if r["dependence_p"] is not None
                                     or r["dependence_verdict"] is not None),
            "dependence_false_rejections": [f"{r['id']}: p={r['dependence_p']} "
                                            f"{r['dependence_verdict'] or ''}"
                                            for r in rows_i if r["dependence_rejects"]],
            "seconds_median": pct([r["seconds"] for r in rows_i], 50),
            "seconds_total": sum(r["seconds"] for r in rows_i),
        }
    return S


def fmt_md(S, rows_i, rows_d, meta):
    """score.md text."""
    L = ["# verify2 score", "", f"tool: `{meta['hasel']}`; corpus: `{meta['corpus']}`; "
         f"jobs {meta['jobs']}, tool --jobs {meta['tool_jobs']}; wall {meta['wall_s']:.0f} s", ""]
    if "singles" in S:
        s = S["singles"]
        L += ["## Figures (diagnose)", "",
              "| figure | value | issue's target |", "|---|---|---|",
              f"| single effects top-1 | {s['top1']} / {s['n']} ({100 * s['top1'] / max(s['n'], 1):.0f} %) | >= 95 % |"]
        for cat in ("pairs", "triples"):
            c = S[cat]
            pr = "-" if c["precision"] is None else f"{c['precision']:.2f}"
            rc = "-" if c["recall"] is None else f"{c['recall']:.2f}"
            L.append(f"| {cat}: precision / recall ({c['n']} cases) | {pr} / {rc} | >= 0.90 / >= 0.85 |")
        ef = S["effect_free"]
        L.append(f"| effect-free logs with no effect named | {ef['no_effect_named']} / {ef['n']} "
                 f"(false alarms {ef['false_alarms']}, failed runs {len(ef['failed_runs'])}) | >= 95 % |")
        nf = S["near_floor"]
        L.append(f"| near-floor: false attributions | {nf['false_attributions']} / {nf['n']} "
                 f"(none {nf['none']}, right name only {nf['right_only']}, failed {nf['failed_runs']}) | 0 |")
        sh = S["shrink_effect_cases"]
        if sh["n"]:
            L.append(f"| held-out shrink, effect cases (n={sh['n']}) | median {sh['median']:.3f}, "
                     f"p25 {sh['p25']:.3f}, p10 {sh['p10']:.3f}, min {sh['min']:.3f} | median >= 0.80 |")
        L.append(f"| augmented worse than nominal, not flagged | {S['worse_unflagged']['n']} | 0 |")
        ds = S["diagnose_seconds"]
        L.append(f"| seconds per diagnose case | median {ds['median']:.1f}, p90 {ds['p90']:.1f}, "
                 f"max {ds['max']:.1f} | 120 s at 1 kHz < 30 s |")
        L.append(f"| largest log | {ds['largest_log']} | |")
        L += ["", "### Singles, top-1 per effect", "", "| effect | top-1 | named instead |", "|---|---|---|"]
        for n in NAMES:
            d = s["per_effect"].get(n)
            if d:
                L.append(f"| {n} | {d['top1']} / {d['n']} | {'; '.join(d['named_instead'])} |")
        L += ["", "### Pairs and triples", ""] + [f"- {c}" for c in S["pairs"]["cases"] + S["triples"]["cases"]]
        L += ["", "### Effect-free false alarms", ""] + [f"- {a}" for a in ef["alarms"] or ["none"]]
        L += ["", "### Near-floor cases", ""] + [f"- {a}" for a in nf["cases"]]
        L += ["", "### Closed-loop cases", ""] + [f"- {a}" for a in S["closed_loop"]]
        L += ["", "### Augmented model worse than nominal", "",
              "Counted as flagged when: " + "; ".join(S["worse_unflagged"]["flag_rules"]), ""]
        L += ["Not flagged: " + (", ".join(S["worse_unflagged"]["cases"]) or "none"), "",
              "Flagged: " + (", ".join(S["worse_unflagged"]["worse_but_flagged"]) or "none"), ""]
        L += [f"Shrink on effect-free logs: {S['shrink_effect_free']}; near-floor: {S['shrink_near_floor']}", ""]
        L += ["### Failed diagnose runs", ""] + [f"- {a}" for a in S["diagnose_failed_runs"] or ["none"]]
    if "ident" in S:
        I = S["ident"]
        L += ["", "## Identification (effect-free logs; truth P(s); band 0.1-15 Hz)", "",
              f"- exit 0: {I['exit0']} / {I['n']}; of those within {TOL_DB} dB / {TOL_DEG} deg: "
              f"{I['exit0_within_tol']}",
              f"- exit 0 but outside tolerance: {', '.join(I['exit0_outside_tol']) or 'none'}",
              f"- refused (exit != 0): {len(I['refused'])}; of those whose written model was within "
              f"tolerance anyway: {', '.join(I['refused_but_model_within_tol']) or 'none'}",
              f"- offset-dependence test found in {I['dependence_tested']} model JSONs; false "
              f"rejections (p < 0.05 or 'dependent'): {len(I['dependence_false_rejections'])}"
              f" {I['dependence_false_rejections']}",
              f"- seconds: median {I['seconds_median']:.1f}, total {I['seconds_total']:.0f}", "",
              "| case | design | rate Hz | fmt | exit | dB max | deg max | G(0) | dep. p | s |",
              "|---|---|---|---|---|---|---|---|---|---|"]
        for r in rows_i:
            g = lambda k, f: (f.format(r[k]) if r.get(k) is not None else "-")
            L.append(f"| {r['id']} | {r['design']} | {r['rate_hz']} | {r['format']} | {r['rc']} | "
                     f"{g('err_db_max', '{:.2f}')} | {g('err_deg_max', '{:.1f}')} | {g('dc_gain', '{:.3f}')} | "
                     f"{g('dependence_p', '{:.3g}')} | {r['seconds']:.1f} |")
        L += ["", "Refusals:", ""] + [f"- {a}" for a in I["refused"] or ["none"]]
    if rows_d:
        L += ["", "## Diagnose cases", "", "| case | truth | named | exit | shrink | flagged | s |",
              "|---|---|---|---|---|---|---|"]
        for r in rows_d:
            sh = f"{r['shrink']:.3f}" if "shrink" in r else "-"
            L.append(f"| {r['id']} | {','.join(r['forms']) or '-'} | {r['named']} | {r['rc']} | {sh} | "
                     f"{'; '.join(r['flag_reasons'])} | {r['seconds']:.1f} |")
    return "\n".join(L) + "\n"


def main(argv=None):
    """CLI entry point."""
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--corpus", required=True)
    ap.add_argument("--hasel", required=True)
    ap.add_argument("--jobs", type=int, default=1)
    ap.add_argument("--tool-jobs", type=int, default=1,
                    help="--jobs passed to hasel diagnose (default 1; 0: the tool's default)")
    ap.add_argument("--timeout", type=float, default=300.0)
    ap.add_argument("--only", choices=["ident", "diagnose"])
    ap.add_argument("--cases", help="comma-separated case ids (default all)")
    ap.add_argument("--work", help="where the tool's JSON go (default: beside --json)")
    ap.add_argument("--json", required=True)
    a = ap.parse_args(argv)
    corpus = os.path.abspath(a.corpus)
    hasel = os.path.abspath(a.hasel)
    work = os.path.abspath(a.work or os.path.splitext(a.json)[0] + "_out")
    os.makedirs(work, exist_ok=True)
    labels = []
    for fn in sorted(os.listdir(os.path.join(corpus, "labels"))):
        with open(os.path.join(corpus, "labels", fn)) as fh:
            lab = json.load(fh)
        if a.only and lab["kind"] != a.only:
            continue
        if a.cases and lab["id"] not in a.cases.split(","):
            continue
        labels.append(lab)
    t0 = time.monotonic()
    results = {}
    with cf.ThreadPoolExecutor(max_workers=max(1, a.jobs)) as ex:
        futs = {ex.submit(run_case, lab, corpus, hasel, work, a.timeout, a.tool_jobs): lab
                for lab in labels}
        for fu in cf.as_completed(futs):
            lab = futs[fu]
            r = fu.result()
            results[lab["id"]] = r
            print(f"{lab['id']}: exit {r['rc']} {r['seconds']:.1f} s", flush=True)
    wall = time.monotonic() - t0
    rows_i = [score_ident(lab, results[lab["id"]]) for lab in labels if lab["kind"] == "ident"]
    rows_d = [score_diag(lab, results[lab["id"]]) for lab in labels if lab["kind"] == "diagnose"]
    S = summarise(rows_i, rows_d)
    meta = {"hasel": hasel, "corpus": corpus, "jobs": a.jobs, "tool_jobs": a.tool_jobs,
            "wall_s": wall, "n_cases": len(labels)}
    with open(a.json, "w") as fh:
        json.dump({"meta": meta, "summary": S, "ident": rows_i, "diagnose": rows_d}, fh,
                  indent=1, default=str)
    md = os.path.splitext(a.json)[0] + ".md"
    with open(md, "w") as fh:
        fh.write(fmt_md(S, rows_i, rows_d, meta))
    print(f"wrote {a.json} and {md} ({len(labels)} cases, {wall:.0f} s)")


if __name__ == "__main__":
    main()
