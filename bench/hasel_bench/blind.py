"""The blind withheld check of the diagnosis.

Each case draws no effect, one effect or a pair (random parameters, noise level and
seed), simulates the truth actuator (:class:`hasel.effects.TruthActuator`) on an
excitation a researcher would use on a HASEL, and writes the log to an ``.npz`` file
holding only ``t_s``, ``voltage_kv``, ``stroke_mm`` and the nominal model: no label.
The labels stay in the generating process. Each file is diagnosed in a separate
process (:mod:`hasel_bench.harness`: *spawn* start method) that receives only the
file's path. Then the labels are revealed and scored:

- **top-1** (single-effect and no-effect cases): the first named effect is the
  true one; for a no-effect case, nothing is named.
- **pair** (two-effect cases): the first two named effects are the true pair, in
  any order.
- **false alarm**: a no-effect case where something is named; **miss**: an effect
  case where nothing is named (a diagnosis that raised names nothing; ``errors``
  counts them).
- **shrink** (effect cases): ``(nrmse_nominal - nrmse_augmented) /
  (nrmse_nominal - noise_floor_nrmse)`` on held-out data: the share of the gap
  above the noise floor that the named augmentations remove (1 = down to noise).

Excitation (10 kHz command, kV): a reverse-charge hold at -1 kV, a slow 0.2 Hz sine
around 4 kV (hysteresis and level), exponential chirps 0.2-25 Hz of 1 kV around
DC offsets in random order, each repeated, and steps 2-4-6-4-2-0 kV (direction).

Run ``python -m hasel_bench.blind --cases 30`` (``--quick`` for the CI size).
"""
from __future__ import annotations

import argparse
import math
import os
import sys
import time
from collections import Counter
from dataclasses import dataclass

import numpy as np

from hasel import paper
from hasel.effects import EFFECT_NAMES, TruthActuator, sample_effect
from hasel.plant import amplifier_filter_tf
from hasel_bench.harness import case_directory, diagnose_files, result_line, say_stderr, write_json

__all__ = ["BlindCase", "excitation", "make_case", "run_blind", "score", "main"]

_NONE = "none"


@dataclass(frozen=True)
class BlindCase:
    """A generated case (the label lives only here)."""

    index: int
    seed: int
    labels: tuple[str, ...]
    params: dict
    noise_mm: float
    path: str


def _exp_chirp(t: np.ndarray, f0: float, f1: float, duration: float) -> np.ndarray:
    k = math.log(f1 / f0) / duration
    return np.sin(2 * np.pi * f0 * (np.expm1(k * t)) / k)


def excitation(rng: np.random.Generator, *, quick: bool = False, rate_hz: float = paper.PLANT_RATE_HZ) -> np.ndarray:
    """The command (kV) of one blind case at ``rate_hz``.

    Parameters
    ----------
    rng : numpy.random.Generator
        Draws the order of the DC offsets.
    quick : bool
        A short version (about 22 s instead of about 70 s).
    rate_hz : float
        Sample rate, Hz.
    """
    def hold(v: float, s: float) -> np.ndarray:
        return np.full(int(round(s * rate_hz)), float(v))

    def seg(s: float) -> np.ndarray:
        return np.arange(int(round(s * rate_hz))) / rate_hz

    parts = [hold(-1.0, 1.0), hold(0.0, 0.5)]
    n_slow = 1 if quick else 2
    ts = seg(n_slow / 0.2)
    parts.append(4.0 - 2.5 * np.cos(2 * np.pi * 0.2 * ts))  # starts at its minimum, 1.5 kV
    offsets = [2.5, 4.0, 5.5]
    rng.shuffle(offsets)
    if quick:
        offsets = offsets[:2]
    dur = 6.0 if quick else 8.0
    reps = 1 if quick else 2
    tc = seg(dur)
    ch = _exp_chirp(tc, 0.2, 25.0, dur)
    for v in offsets:
        parts.append(hold(v, 0.5))
        parts.append(v + np.tile(ch, reps))
    hold_s = 1.0 if quick else 1.5
    for v in (2.0, 4.0, 6.0, 4.0, 2.0, 0.0):
        parts.append(hold(v, hold_s))
    return np.concatenate(parts)


def make_case(index: int, seed: int, directory: str, *, quick: bool = False) -> BlindCase:
    """Draw and simulate one case; write its unlabelled log to ``directory``.

    A third of the cases have no effect, a third one effect and a third a pair
    (uniform over the names and over the pairs).
    """
    rng = np.random.default_rng(seed)
    kind = int(rng.integers(3))
    if kind == 0:
        names: tuple[str, ...] = ()
    elif kind == 1:
        names = (EFFECT_NAMES[int(rng.integers(len(EFFECT_NAMES)))],)
    else:
        a, b = rng.choice(len(EFFECT_NAMES), 2, replace=False)
        names = (EFFECT_NAMES[int(a)], EFFECT_NAMES[int(b)])
    effects = [sample_effect(n, rng) for n in names]
    noise = float(rng.uniform(0.003, 0.015))
    u = excitation(rng, quick=quick)
    act = TruthActuator(effects)
    act.reset(float(u[0]))
    out = act.run(u)
    meas = act.measure_mm(out.stroke_mm)
    lsb = paper.ADC_FULL_SCALE_V * paper.LASER_MM_PER_V / 2 ** paper.ADC_BITS
    y = np.round((meas + noise * rng.standard_normal(u.size)) / lsb) * lsb
    t = np.arange(u.size) / act.rate_hz
    # the researcher's nominal simulator: the amplifier's output filter and P(s)
    an, ad = amplifier_filter_tf(act.config.amp_filter_hz)
    num, den = np.polymul(an, paper.plant_tf()[0]), np.polymul(ad, paper.plant_tf()[1])
    path = os.path.join(directory, f"case_{index:03d}.npz")
    np.savez_compressed(path, t_s=t, voltage_kv=u, stroke_mm=y, num=num, den=den)
    return BlindCase(index, seed, tuple(names), {e.name: e.params() for e in effects}, noise, path)


def score(cases: list[BlindCase], results: dict[str, dict]) -> dict:
    """Reveal the labels and score the verdicts (see the module docstring)."""
    rows = []
    for c in cases:
        r = results[c.path]
        named = r["names"]
        truth = list(c.labels)
        first = named[0] if named else _NONE
        if not truth:
            ok = not named
        elif len(truth) == 1:
            ok = first == truth[0]
        else:
            ok = sorted(named[:2]) == sorted(truth)
        gap = r.get("nrmse_nominal", 0.0) - r.get("floor", 0.0)  # none when the diagnosis raised
        shrink = (r["nrmse_nominal"] - r["nrmse_augmented"]) / gap if truth and gap > 0 else None
        rows.append({"case": c.index, "seed": c.seed, "truth": truth, "named": named, "correct": bool(ok),
                     "shrink": shrink, "nrmse_nominal": r.get("nrmse_nominal"),
                     "nrmse_augmented": r.get("nrmse_augmented"), "floor": r.get("floor"), "seconds": r["seconds"],
                     "params": c.params, "noise_mm": c.noise_mm, "rounds": r.get("rounds", []),
                     "error": r.get("error")})
    single = [x for x in rows if len(x["truth"]) <= 1]
    pairs = [x for x in rows if len(x["truth"]) == 2]
    none = [x for x in rows if not x["truth"]]
    eff = [x for x in rows if x["truth"]]
    confusion: dict[str, Counter] = {}
    for x in single:
        t = x["truth"][0] if x["truth"] else _NONE
        confusion.setdefault(t, Counter())[x["named"][0] if x["named"] else _NONE] += 1
    shrinks = [x["shrink"] for x in eff if x["shrink"] is not None]
    return {
        "n_cases": len(rows),
        "top1_accuracy": (sum(x["correct"] for x in single) / len(single)) if single else None,
        "n_single_or_none": len(single),
        "pair_accuracy": (sum(x["correct"] for x in pairs) / len(pairs)) if pairs else None,
        "n_pairs": len(pairs),
        "pair_one_right": (sum(bool(set(x["named"][:2]) & set(x["truth"])) for x in pairs) / len(pairs)) if pairs else None,
        "false_alarms": sum(bool(x["named"]) for x in none), "n_none": len(none),
        "misses": sum(not x["named"] for x in eff), "n_effect_cases": len(eff),
        "errors": sum(bool(x["error"]) for x in rows),
        "median_shrink": float(np.median(shrinks)) if shrinks else None,
        "seconds_per_case": float(np.mean([x["seconds"] for x in rows])) if rows else None,
        "confusion": {k: dict(v) for k, v in confusion.items()},
        "cases": rows,
    }


def format_report(s: dict) -> str:
    """A plain-text summary: figures and the confusion matrix (rows truth, columns top-1)."""
    def pct(x):
        return "n/a" if x is None else f"{100 * x:.0f} %"

    names = [_NONE] + list(EFFECT_NAMES)
    short = {n: n[:6] for n in names}
    lines = [f"blind check: {s['n_cases']} cases",
             f"  top-1 (single effect or none): {pct(s['top1_accuracy'])} of {s['n_single_or_none']}",
             f"  right pair (two effects):      {pct(s['pair_accuracy'])} of {s['n_pairs']} "
             f"(at least one of the two right: {pct(s['pair_one_right'])})",
             f"  false alarms: {s['false_alarms']} of {s['n_none']} no-effect cases; misses: {s['misses']} of "
             f"{s['n_effect_cases']} effect cases",
             f"  median held-out shrink of the gap above noise: {pct(s['median_shrink'])}",
             f"  time per case: {s['seconds_per_case']:.1f} s" if s["seconds_per_case"] is not None else "",
             "  confusion (rows: truth, columns: first named):",
             "    " + " ".join(f"{short[n]:>7s}" for n in names)]
    for t in names:
        row = s["confusion"].get(t)
        if row is None:
            continue
        lines.append(f"    {short[t]:>6s} " + " ".join(f"{row.get(n, 0):7d}" for n in names))
    wrong = [x for x in s["cases"] if not x["correct"]]
    if wrong:
        lines.append("  wrong cases:")
        for x in wrong:
            lines.append(f"    #{x['case']} truth {x['truth'] or ['none']} named {x['named'] or ['none']}")
    return "\n".join(lines)


def run_blind(n_cases: int = 30, seed: int = 0, workers: int = 1, *, quick: bool = False,
              directory: str | None = None, progress=None) -> dict:
    """Generate, diagnose blind, and score ``n_cases`` cases.

    Parameters
    ----------
    n_cases : int
        Number of cases.
    seed : int
        Master seed (case ``i`` uses ``seed * 100003 + i``).
    workers : int
        Diagnosing processes (spawned; they see only the files).
    quick : bool
        Short excitations (CI).
    directory : str, optional
        Where the case files go (a temporary directory by default).
    progress : callable, optional
        Called with one-line messages.

    Returns
    -------
    dict
        See :func:`score`; plus ``"wall_s"``.
    """
    say = progress or (lambda m: None)
    t0 = time.perf_counter()
    with case_directory(directory, "hasel-blind-") as directory:
        cases = []
        for i in range(n_cases):
            cases.append(make_case(i, seed * 100003 + i, directory, quick=quick))
        say(f"generated {n_cases} cases in {time.perf_counter() - t0:.1f} s; diagnosing blind in "
            f"{workers} spawned process(es)")
        results = diagnose_files([(c.path, True) for c in cases], workers, lambda r: say(result_line(r)))
        s = score(cases, {r["path"]: r for r in results})
        s["wall_s"] = time.perf_counter() - t0
        return s


def main(argv: list[str] | None = None) -> int:
    """``python -m hasel_bench.blind [--cases N] [--seed S] [--workers W] [--quick] [--json FILE]``."""
    p = argparse.ArgumentParser(prog="python -m hasel_bench.blind", description=__doc__.split("\n")[0])
    p.add_argument("--cases", type=int, default=30, help="number of blind cases (default 30)")
    p.add_argument("--seed", type=int, default=0, help="master seed (default 0)")
    p.add_argument("--workers", type=int, default=1, help="diagnosing processes (default 1)")
    p.add_argument("--quick", action="store_true", help="short excitations (CI size)")
    p.add_argument("--json", help="write the full scores here")
    a = p.parse_args(argv)
    s = run_blind(a.cases, a.seed, a.workers, quick=a.quick, progress=say_stderr)
    print(format_report(s))
    write_json(s, a.json)
    return 0


if __name__ == "__main__":
    sys.exit(main())
