"""Tuning cases of the diagnosis for the failure kinds of issue 14 item 4 (a tuning set, not verification).

Built on the independent simulator :mod:`hasel_bench.othersim` (its chain and excitation), with
forms it does not draw itself:

- ``pole_load``: one of P(s)'s pole pairs gets the added inertia so that its frequency falls
  15-30 % (``heavier_mode`` with ``mass_ratio`` 0.38-1.04), static gain kept;
- ``voltage_clip``: the amplifier's output saturates: the command is clipped at an upper
  voltage (4.6-5.6 kV) before the actuator (an input-side hard limit);
- pairs ``load + drift`` and ``slew + lag`` (an amplifier slew limit beside a direction-
  dependent lag), and triples;
- effect-free logs of several designs (:func:`hasel_bench.othersim.make_free_case`).

Every case is written as an unlabelled ``.npz`` like othersim's and diagnosed with the
nominal P(s). Run ``python bench/tune_diag/cases.py --out DIR [--only KIND,...]``; it
prints one line per case and a summary (top-1 of singles, pair/triple recall and
precision, false alarms on effect-free logs, held-out shrink, seconds per case) and
writes ``DIR/results.json``.
"""
from __future__ import annotations

import argparse
import json
import os
import sys
import time

import numpy as np

from hasel_bench import othersim as o
from hasel import paper

F = o.ForeignEffect


def _pole_load(rng: np.random.Generator) -> F:
    drop = rng.uniform(0.15, 0.30)  # natural frequency falls by this share
    return F("load_mass", "heavier_mode", {"mass_ratio": float(1.0 / (1.0 - drop) ** 2 - 1.0)})


def _double_pole_plant(drop: float) -> tuple[np.ndarray, np.ndarray]:
    """P(s) with its double pole pair's frequency lowered by ``drop`` (a mass times ``1/(1-drop)^2``:
    frequency and damping ratio fall together), the gain rescaled so that the static gain is kept."""
    num, den = paper.plant_tf()
    mu = 1.0 / (1.0 - drop) ** 2 - 1.0
    w2 = paper.P_NOTCH_RAD_S ** 2
    quad = np.array([1.0, 230.0 / (1.0 + mu), w2 / (1.0 + mu)])
    den2 = np.polymul(np.polymul([1, 18.85], [1, 56.55]), np.polymul(quad, quad))
    num2 = num * (den2[-1] / den[-1])
    return num2, den2


def _simulate(u: np.ndarray, rate: float, effs: list[F], plant: tuple | None) -> np.ndarray:
    """othersim's chain, with its P(s) replaced by ``plant`` (num, den) when given."""
    if plant is None:
        return o.simulate(u, rate, effs)
    saved = paper.plant_tf
    paper.plant_tf = lambda: plant  # othersim reads P(s) from hasel.paper at each call
    try:
        return o.simulate(u, rate, effs)
    finally:
        paper.plant_tf = saved


DP = "double_pole"


#: name -> (list of effect makers, voltage clip kV or None, or minus the share of samples clipped);
#: a double-pole load is the marker (DP, drop)
def _spec(kind: str, rng: np.random.Generator) -> tuple[list, float | None]:
    s = o.sample_foreign
    if kind.startswith("dpole"):
        rest = {"dpole_load": [], "dpole_load_drift": [s("charge_drift", rng)],
                "dpole_triple": [s("hysteresis", rng), s("sensor_nonlinearity", rng)]}[kind]
        return [(DP, float(rng.uniform(0.15, 0.30)))] + rest, None
    if kind == "voltage_clip_high":  # a clip that only the highest 0.5-2 % of the command reach
        return [], -float(rng.uniform(0.005, 0.02))
    if kind == "pole_load":
        return [_pole_load(rng)], None
    if kind == "voltage_clip":
        return [], float(rng.uniform(4.6, 5.6))
    if kind == "delay":
        return [s("time_delay", rng)], None
    if kind == "load_drift":
        return [_pole_load(rng), s("charge_drift", rng, "offset")], None
    if kind == "slew_lag":
        return [s("saturation", rng, "slew"), s("asymmetric_dynamics", rng, "switched_2nd")], None
    if kind == "slew_ratelimit":
        return [s("saturation", rng, "slew"), s("asymmetric_dynamics", rng, "rate_limit")], None
    if kind == "clip_sensor":
        return [s("sensor_nonlinearity", rng)], float(rng.uniform(4.8, 5.6))
    if kind == "triple_load_hyst_sensor":
        return [_pole_load(rng), s("hysteresis", rng), s("sensor_nonlinearity", rng)], None
    if kind == "triple_delay_drift_map":
        return [s("time_delay", rng), s("charge_drift", rng), s("static_nonlinearity", rng)], None
    raise ValueError(kind)


KINDS = ("pole_load", "pole_load", "pole_load", "voltage_clip", "voltage_clip", "delay", "load_drift",
         "load_drift", "slew_lag", "slew_ratelimit", "clip_sensor", "triple_load_hyst_sensor",
         "triple_delay_drift_map", "dpole_load", "dpole_load", "dpole_load", "dpole_load_drift",
         "dpole_triple", "voltage_clip_high", "voltage_clip_high")
FREE = 8


def make(directory: str, seed: int = 7, n_free: int = FREE, free_s: float | None = 20.0) -> list[dict]:
    """Write every case's file to ``directory``; returns their labels (kept here, not in the files).

    ``n_free`` effect-free logs of :data:`hasel_bench.othersim.FREE_DESIGNS` in turn, ``free_s`` long
    (None: othersim's own lengths, 40 s up to 1 kHz, 20 s above)."""
    out = []
    for i, kind in enumerate(KINDS):
        rng = np.random.default_rng([seed, i])
        spec, vclip = _spec(kind, rng)
        plant = next((_double_pole_plant(x[1]) for x in spec if isinstance(x, tuple)), None)
        effs = [x for x in spec if not isinstance(x, tuple)]
        rate = [500.0, 1000.0][int(rng.integers(2))]
        u, _ = o.excitation(rng, rate)
        if vclip is not None and vclip < 0:  # a share of samples to clip, not a level
            vclip = float(np.quantile(u, 1.0 + vclip))
        u_act = np.minimum(u, vclip) if vclip is not None else u
        z = _simulate(u_act, rate, effs, plant)
        noise = float(rng.uniform(0.003, 0.012))
        y = np.round((z + noise * rng.standard_normal(u.size)) / o.LASER_LSB_MM) * o.LASER_LSB_MM
        num, den = paper.plant_tf()
        path = os.path.join(directory, f"tune_{i:02d}_{kind}.npz")
        np.savez_compressed(path, t_s=np.arange(u.size) / rate, voltage_kv=u, stroke_mm=y, num=num, den=den)
        labels = sorted({e.name for e in effs} | ({"saturation"} if vclip is not None else set())
                        | ({"load_mass"} if plant is not None else set()))
        out.append({"path": path, "kind": kind, "labels": labels,
                    "truth": [f"{e.name}:{e.kind}:{e.params}" for e in effs]
                    + [f"double pole lowered {100 * x[1]:.0f} %" for x in spec if isinstance(x, tuple)]
                    + ([f"voltage clip {vclip:.2f} kV"] if vclip is not None else [])})
    for j in range(n_free):
        c = o.make_free_case(100 + j, seed * 1000 + j, directory, design=o.FREE_DESIGNS[j % len(o.FREE_DESIGNS)],
                             duration_s=free_s)
        out.append({"path": c.path, "kind": f"free:{c.design}:{c.rate_hz:g}:{c.convention}:{c.noise}",
                    "labels": [], "truth": []})
    return out


def run(cases: list[dict], say=print) -> list[dict]:
    """Diagnose each case with the nominal model; one row per case."""
    from hasel.diagnose.core import diagnose

    rows = []
    for c in cases:
        d = np.load(c["path"])
        t0 = time.perf_counter()
        try:
            v = diagnose(d["t_s"], d["voltage_kv"], d["stroke_mm"],
                         model={"num": d["num"].tolist(), "den": d["den"].tolist()}, units=("kV", "mm"))
            r = {"names": v.names, "nominal": v.heldout["nrmse_nominal"], "augmented": v.heldout["nrmse_augmented"],
                 "floor": v.noise_floor_nrmse, "dropped": [x["name"] for x in v.dropped],
                 "ambiguous": [(a["chosen"], a["alternative"]) for a in v.ambiguous],
                 "params": {e["name"]: e["params"] for e in v.effects},
                 "rounds": [{k: x.get(k) for k in ("best", "gain", "nominal_gap_share", "t_block", "z_coloured",
                                                   "over_floor", "accepted")} for x in v.rounds]}
        except Exception as err:  # noqa: BLE001 - a crash is a result
            r = {"names": [], "error": f"{type(err).__name__}: {err}"}
        r.update(kind=c["kind"], labels=c["labels"], seconds=time.perf_counter() - t0)
        g = r.get("nominal", 0) - r.get("floor", 0)
        r["shrink"] = (r["nominal"] - r["augmented"]) / g if c["labels"] and "nominal" in r and g > 0 else None
        rows.append(r)
        say(f"{os.path.basename(c['path']):36s} truth {','.join(c['labels']) or 'none':45s} named "
            f"{','.join(r['names']) or 'none':45s} shrink {r['shrink'] if r['shrink'] is None else round(r['shrink'], 2)}"
            f" {r['seconds']:.1f} s {r.get('error', '')}")
    return rows


def summary(rows: list[dict]) -> dict:
    """Top-1 of singles, recall/precision of multi-effect sets, false alarms, shrink, seconds."""
    single = [r for r in rows if len(r["labels"]) == 1]
    multi = [r for r in rows if len(r["labels"]) > 1]
    free = [r for r in rows if not r["labels"]]
    tp = sum(len(set(r["labels"]) & set(r["names"])) for r in multi)
    sh = [r["shrink"] for r in rows if r["shrink"] is not None]
    return {"top1": f"{sum(bool(r['names']) and r['names'][0] == r['labels'][0] for r in single)}/{len(single)}",
            "multi_recall": tp / max(sum(len(r["labels"]) for r in multi), 1),
            "multi_precision": tp / max(sum(len(r["names"]) for r in multi), 1),
            "false_alarms": f"{sum(bool(r['names']) for r in free)}/{len(free)}",
            "shrink_median": float(np.median(sh)) if sh else None, "shrink_min": min(sh) if sh else None,
            "seconds_mean": float(np.mean([r["seconds"] for r in rows]))}


def finish(cases: list[dict], rows: list[dict], out: str) -> dict:
    """Print and write (``out/results.json``) the summary of ``rows``, with pairs and triples apart."""
    for r, c in zip(rows, cases):
        r["truth"] = c.get("truth", [])
    s = summary(rows)
    for k in (2, 3):  # pairs and triples apart, as the issue reports them
        sub = [r for r in rows if len(r["labels"]) == k]
        tp = sum(len(set(r["labels"]) & set(r["names"])) for r in sub)
        s[f"recall_{k}"] = tp / max(sum(len(r["labels"]) for r in sub), 1)
        s[f"precision_{k}"] = tp / max(sum(len(r["names"]) for r in sub), 1)
    print(json.dumps(s))
    with open(os.path.join(out, "results.json"), "w") as fh:
        json.dump({"summary": s, "rows": rows}, fh, indent=1, default=str)
    return s


def main(argv: list[str] | None = None) -> int:
    """``python bench/tune_diag/cases.py --out DIR [--only SUBSTR,...]``."""
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--out", required=True)
    p.add_argument("--only", default="", help="comma-separated substrings of case kinds to run")
    p.add_argument("--seed", type=int, default=7)
    p.add_argument("--free", type=int, default=FREE, help="effect-free logs (default %(default)s)")
    p.add_argument("--free-s", type=float, default=20.0, help="their length, s (0: othersim's own)")
    a = p.parse_args(argv)
    os.makedirs(a.out, exist_ok=True)
    cases = make(a.out, a.seed, a.free, a.free_s or None)
    if a.only:
        keys = a.only.split(",")
        cases = [c for c in cases if any(k in c["kind"] for k in keys)]
    finish(cases, run(cases, lambda m: (print(m), sys.stdout.flush())), a.out)
    return 0


if __name__ == "__main__":
    sys.exit(main())
