"""Tuning cases of pairs and triples of effects in other forms than ``cases.py`` (a tuning set, not verification).

``cases.py`` draws its combinations on othersim's one researcher excitation at 500 Hz / 1 kHz with
white noise. These cases vary what the selection sees, so that its pair/triple logic is not tuned
on one generator:

- **designs**: othersim's excitation (``paper``), a random-phase multisine, a PRBS of held levels,
  a logarithmic chirp, and a closed-loop step log (the command a PI loop on the nominal P(s) gives
  for random stroke steps, then applied to the effect chain);
- **rates** 200 Hz to 5 kHz; **noise** white, coloured (low-pass) or with a slow offset wander;
- **effects**: pairs and triples of othersim's eight names (random kinds; parameters of
  :func:`hasel_bench.othersim.sample_foreign` scaled by 0.4-1.0, so one member is often much smaller
  than another) and an input-side voltage clip (an amplifier's hard limit) as ``saturation``;
- every effect must be visible: taking it out of the chain changes the noise-free output by at
  least ``MIN_VISIBLE`` times the noise rms, else the case is drawn again (a label nothing can see
  would only lower recall); a few single effects and effect-free logs of the same designs are
  mixed in, so that singles and false alarms are watched too.

Run ``python bench/tune_diag/combos.py --out DIR [--seed S] [--n N] [--only KIND,...]``; the output
format is ``cases.py``'s (one line per case, then the summary of top-1, pair/triple recall and
precision, false alarms, shrink and seconds per case; ``DIR/results.json``).
"""
from __future__ import annotations

import argparse
import json
import os
import sys

import numpy as np

from hasel import paper
from hasel_bench import othersim as o

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from cases import finish, run  # noqa: E402

F = o.ForeignEffect
DESIGNS = ("paper", "multisine", "prbs", "chirp", "cl_steps")
RATES = (200.0, 500.0, 1000.0, 2000.0, 5000.0)
NOISES = ("white", "coloured", "wander")
#: An effect is kept only if taking it out moves the noise-free output by this many noise rms.
MIN_VISIBLE = 1.5
#: Parameters that set an effect's size (scaled toward the nominal), per othersim kind.
_SIZE = {"power": ("exponent", 1.0), "knee": ("ratio", 1.0), "rate_limit": None, "switched_2nd": None,
         "screening": ("share", 0.0), "offset": ("offset_mm", 0.0), "slew": None, "soft_stroke": None,
         "pade": ("delay_s", 0.0), "shift": ("delay_s", 0.0), "quadratic": ("curvature_per_mm", 0.0),
         "exponential": None, "coupled": None, "heavier_mode": ("mass_ratio", 0.0),
         "prandtl_ishlinskii": ("share", 0.0), "duhem": ("share", 0.0)}


def _scaled(e: F, s: float) -> F:
    """``e`` with its size parameter moved toward no effect: ``ref + s (p - ref)``."""
    key = _SIZE.get(e.kind)
    if key is None:
        return e
    p = dict(e.params)
    p[key[0]] = key[1] + s * (p[key[0]] - key[1])
    return F(e.name, e.kind, p)


def _command(design: str, rng: np.random.Generator, rate: float, dur: float) -> np.ndarray:
    """The command (kV) of ``design``: othersim's designs, or a closed-loop step log's command."""
    if design == "cl_steps":
        n = int(round(dur * rate))
        u, _ = o._closed_loop(rng, rate, dur, np.zeros(n))
        return u
    if design == "multisine":  # wider than othersim's free multisine: the static maps need a range
        u = o._design_input("multisine", rng, rate, dur)
        return 4.0 + (u - u.mean()) * float(rng.uniform(1.5, 2.5))
    if design == "prbs":
        u = o._design_input("prbs", rng, rate, dur)
        return np.clip(u + rng.uniform(-0.5, 0.5), 0.2, 8.0)
    return o._design_input(design, rng, rate, dur)


def _voltage_clip(u: np.ndarray, rng: np.random.Generator) -> float:
    """An amplifier limit that the highest 2-8 % of the command reach (kV)."""
    return float(np.quantile(u, 1.0 - rng.uniform(0.02, 0.08)))


def _chain(u: np.ndarray, rate: float, effs: list[F], vclip: float | None) -> np.ndarray:
    return o.simulate(np.minimum(u, vclip) if vclip is not None else u, rate, effs)


def _draw_effects(rng: np.random.Generator, k: int) -> tuple[list[F], bool]:
    """``k`` distinct effect names (a voltage clip may stand for ``saturation``)."""
    names = list(o.EFFECT_KINDS)
    pick = [names[int(i)] for i in rng.choice(len(names), k, replace=False)]
    clip = "saturation" in pick and rng.random() < 0.5
    effs = [_scaled(o.sample_foreign(nm, rng), float(rng.uniform(0.4, 1.0)))
            for nm in pick if not (clip and nm == "saturation")]
    return effs, clip


def make(directory: str, seed: int = 21, n: int = 24, n_free: int = 4, n_single: int = 4) -> list[dict]:
    """Write ``n`` combination cases (pairs and triples alternating), ``n_single`` single effects and
    ``n_free`` effect-free logs to ``directory``; returns their labels (kept here, not in the files)."""
    plan = [("pair" if i % 2 == 0 else "triple") for i in range(n)] + ["single"] * n_single + ["free"] * n_free
    return [c for c in (make_case(directory, seed, i, kind) for i, kind in enumerate(plan)) if c is not None]


def make_case(directory: str, seed: int, i: int, kind: str) -> dict | None:
    """Case ``i`` of :func:`make` (``kind`` pair, triple, single or free; its draws depend on ``seed``
    and ``i`` only), written to ``directory``; None when nothing visible enough was drawn."""
    rng = np.random.default_rng([seed, i])
    design = DESIGNS[i % len(DESIGNS)]
    rate = RATES[int(rng.integers(len(RATES)))]
    dur = 40.0 if rate <= 1000.0 else 20.0
    if design == "paper":
        u, _ = o.excitation(rng, rate)
    else:
        u = _command(design, rng, rate, dur)
    noise_kind = NOISES[int(rng.integers(len(NOISES)))]
    sd = float(rng.uniform(0.003, 0.012))
    k = {"pair": 2, "triple": 3, "single": 1, "free": 0}[kind]
    for _ in range(12):
        effs, clip = _draw_effects(rng, k) if k else ([], False)
        vclip = _voltage_clip(u, rng) if clip else None
        z = _chain(u, rate, effs, vclip)
        if not np.all(np.isfinite(z)):
            continue
        vis = [float(np.std(z - _chain(u, rate, [e for e in effs if e is not x], vclip))) / sd for x in effs]
        if clip:
            vis.append(float(np.std(z - _chain(u, rate, effs, None))) / sd)
        if all(v >= MIN_VISIBLE for v in vis):
            break
    else:
        return None  # nothing visible enough drawn: no case
    nz = o._coloured(rng, u.size, rate, sd, noise_kind)
    y = np.round((z + nz) / o.LASER_LSB_MM) * o.LASER_LSB_MM
    num, den = paper.plant_tf()
    path = os.path.join(directory, f"combo_{i:02d}_{kind}.npz")
    np.savez_compressed(path, t_s=np.arange(u.size) / rate, voltage_kv=u, stroke_mm=y, num=num, den=den)
    labels = sorted({e.name for e in effs} | ({"saturation"} if clip else set()))
    return {"path": path, "kind": f"{kind}:{design}:{rate:g}:{noise_kind}", "labels": labels,
            "visible": [round(v, 1) for v in vis] if k else [],
            "truth": [f"{e.name}:{e.kind}:{ {a: round(b, 4) for a, b in e.params.items()} }" for e in effs]
            + ([f"voltage clip {vclip:.2f} kV"] if clip else [])}


def main(argv: list[str] | None = None) -> int:
    """``python bench/tune_diag/combos.py --out DIR [--seed S] [--n N] [--only SUBSTR,...]``."""
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--out", required=True)
    p.add_argument("--seed", type=int, default=21)
    p.add_argument("--n", type=int, default=24, help="pair and triple cases (default %(default)s)")
    p.add_argument("--single", type=int, default=4)
    p.add_argument("--free", type=int, default=4)
    p.add_argument("--only", default="", help="comma-separated substrings of case kinds or file names")
    p.add_argument("--list", action="store_true", help="write the cases and print their truth only")
    a = p.parse_args(argv)
    os.makedirs(a.out, exist_ok=True)
    cases = select(cached(os.path.join(a.out, f"cases_{a.seed}_{a.n}_{a.single}_{a.free}.json"),
                          lambda: make(a.out, a.seed, a.n, a.free, a.single)), a.only, a.list)
    if cases:
        finish(cases, run(cases, lambda m: (print(m), sys.stdout.flush())), a.out)
    return 0


def cached(index: str, build) -> list[dict]:
    """The cases listed in ``index`` (JSON) if it was written before with the same draws (the simulation
    takes minutes), else ``build()``'s, written there."""
    if os.path.exists(index):
        with open(index) as fh:
            return json.load(fh)
    cases = build()
    with open(index, "w") as fh:
        json.dump(cases, fh, indent=1)
    return cases


def select(cases: list[dict], only: str, list_only: bool) -> list[dict]:
    """The cases whose kind or file name holds one of the comma-separated ``only`` substrings (all when
    empty); with ``list_only`` their truth is printed and none is returned (nothing to run)."""
    if only:
        keys = only.split(",")
        cases = [c for c in cases if any(k in c["kind"] or k in os.path.basename(c["path"]) for k in keys)]
    if list_only:
        for c in cases:
            print(os.path.basename(c["path"]), c["kind"], c["labels"], c["visible"], c["truth"])
        return []
    return cases


def generator_parser(doc: str, seed: int) -> argparse.ArgumentParser:
    """The options every single-seed generator takes: ``--out DIR [--seed S] [--only SUBSTR,...] [--list]``."""
    p = argparse.ArgumentParser(description=doc.split("\n")[0])
    p.add_argument("--out", required=True)
    p.add_argument("--seed", type=int, default=seed)
    p.add_argument("--only", default="", help="comma-separated substrings of case kinds or file names")
    p.add_argument("--list", action="store_true", help="write the cases and print their truth only")
    return p


def generator_cases(p: argparse.ArgumentParser, argv: list[str] | None, make) -> tuple[argparse.Namespace, list[dict]]:
    """The parsed options and the selected cases (``make(out, seed)``, cached in ``out/cases_<seed>.json``)."""
    a = p.parse_args(argv)
    os.makedirs(a.out, exist_ok=True)
    return a, select(cached(os.path.join(a.out, f"cases_{a.seed}.json"), lambda: make(a.out, a.seed)), a.only, a.list)


def generator_main(argv: list[str] | None, doc: str, make, seed: int, extra=None, serial: bool = False) -> int:
    """The command line every single-seed generator shares: ``--out DIR [--seed S] [--only SUBSTR,...] [--list]``.

    The cases (``make(out, seed)``, cached in ``out/cases_<seed>.json``) are diagnosed one after the other
    (``serial``: the diagnosis's own pool set to one job as well) and summed up in ``out/results.json``
    (:func:`cases.finish`); ``extra(cases, rows)``, when given, adds entries to that summary (and prints them)."""
    a, cases = generator_cases(generator_parser(doc, seed), argv, make)
    if not cases:
        return 0
    if serial:
        from hasel.diagnose.pool import set_jobs

        set_jobs(1)
    rows = run(cases, lambda m: (print(m), sys.stdout.flush()))
    finish(cases, rows, a.out)
    if extra is not None:
        more = extra(cases, rows)
        print(json.dumps(more))
        with open(os.path.join(a.out, "results.json")) as fh:
            res = json.load(fh)
        res["summary"].update(more)
        with open(os.path.join(a.out, "results.json"), "w") as fh:
            json.dump(res, fh, indent=1, default=str)
    return 0


if __name__ == "__main__":
    sys.exit(main())
