"""Charge drifts in forms the diagnosis's one-time-constant drift does not take (a tuning set, not verification;
session 13, ``RESULT-h-trap.md``).

``charge_drift``'s generic form is one slow low-pass (at least 30 % of the log) of the voltage acting on the
gain and the offset. The drifts here are simulated by this file's own code (scipy's discretisation of P(s)
and ``multi2.py``'s filters; no hasel effect class, no othersim effect), started at rest with the first
command (as the plant) or from no charge:

- ``trap2``: charge trapped at two depths screening the voltage, ``v - a1 lp(v, t1) - a2 lp(v, t2)``
  (``a1``, ``a2`` 0.05-0.15, ``t1`` 1-4 s, ``t2`` 8-30 s), before P(s);
- ``fast1``: one fast trap, ``v - a lp(v, t)`` (``a`` 0.08-0.2, ``t`` 0.5-5 s), before P(s);
- ``sqv``: a creep of the stroke driven by ``V^2`` (the electrostatic pressure), ``z + c lp(v^2 / 16, t)``
  (``c`` 0.1-0.4 mm, either sign, ``t`` 2-10 s);
- ``gainonly``: a gain loss with the charge, ``z (1 - g lp0(v, t) / 8)`` (``g`` 0.08-0.25, ``t`` 3-40 s);
- ``offsetonly``: an offset with the charge, ``z + o lp0(v, t) / 8`` (``o`` 0.1-0.4 mm, either sign,
  ``t`` 3-40 s); these two from no charge (``lp0``: a fresh actuator), the others at rest with the first
  command;
- ``slow1``: the one-tau drift the diagnosis was built for (gain 2-6 % and offset 0.1-0.3 mm at 8 kV of
  charge, ``t`` 20-150 s), a control that must stay named;

12 singles (two each), 4 pairs (``trap2``/``fast1`` beside a delay ``delaylag`` or a load ``polepair`` of
``multi2.py``) and 4 effect-free logs. Designs: log chirp, closed-loop steps, multisine, PRBS (``combos.py``),
random levels (``multi2.py``), the paper's command; rates 200 Hz-5 kHz; white, AR(1)-coloured or wandering
noise 0.003-0.012 mm, 12-bit laser quantisation. Each drift is at least 3 noise rms (else drawn again).

Run ``python bench/tune_diag/drifts.py --out DIR [--seed S] [--only SUBSTR,...] [--list]``. Seed 1 is for
tuning. Each case is diagnosed in one process; the output is ``cases.py``'s (one line per case, the summary,
``DIR/results.json``) plus ``drift_named`` (cases with a drift whose names include ``charge_drift``) and the
fitted drift time constants per case.
"""
from __future__ import annotations

import os
import sys

import numpy as np

from hasel import paper

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from combos import _command, generator_main  # noqa: E402
from multi2 import LSB_MM, _levels, _linear, _lowpass, _noise, _plant, draw  # noqa: E402
from multi2 import chain as multi2_chain  # noqa: E402

RATES = (200.0, 500.0, 1000.0, 2000.0, 5000.0)
DESIGNS = ("chirp", "cl_steps", "multisine", "prbs", "levels", "paper")
NOISES = ("white", "coloured", "wander")
DRIFTS = ("trap2", "fast1", "sqv", "gainonly", "offsetonly", "slow1")
LABEL = {d: "charge_drift" for d in DRIFTS} | {"delaylag": "time_delay", "polepair": "load_mass"}
#: forms per case; () is an effect-free log
KINDS: tuple[tuple[str, ...], ...] = tuple((d,) for d in DRIFTS for _ in range(2)) + (
    ("trap2", "delaylag"), ("fast1", "polepair"), ("trap2", "polepair"), ("fast1", "delaylag"),
    (), (), (), ())
MIN_VISIBLE = 3.0  # noise rms a member must reach


def draw_drift(form: str, rng: np.random.Generator, s: float) -> dict:
    """Parameters of the drift ``form`` (see the module) at size ``s`` (1 full)."""
    sign = 1.0 if rng.random() < 0.6 else -1.0
    if form == "trap2":
        return {"a1": s * rng.uniform(0.05, 0.15), "t1": rng.uniform(1, 4), "a2": s * rng.uniform(0.05, 0.15),
                "t2": rng.uniform(8, 30)}
    if form == "fast1":
        return {"a": s * rng.uniform(0.08, 0.2), "t": rng.uniform(0.5, 5)}
    if form == "sqv":
        return {"c": sign * s * rng.uniform(0.1, 0.4), "t": rng.uniform(2, 10)}
    if form == "gainonly":
        return {"g": s * rng.uniform(0.08, 0.25), "t": rng.uniform(3, 40)}
    if form == "offsetonly":
        return {"o": sign * s * rng.uniform(0.1, 0.4), "t": rng.uniform(3, 40)}
    if form == "slow1":
        return {"g": s * rng.uniform(0.02, 0.06), "o": sign * s * rng.uniform(0.1, 0.3), "t": rng.uniform(20, 150)}
    raise ValueError(form)


def _lowpass0(x: np.ndarray, rate: float, tau: float) -> np.ndarray:
    """First-order lag of ``x`` (time constant ``tau`` s) from zero."""
    return _lowpass(np.concatenate([[0.0], np.asarray(x, float)]), rate, tau)[1:]


def chain(u: np.ndarray, rate: float, parts: list[tuple[str, dict]]) -> np.ndarray:
    """The noise-free stroke (mm) of command ``u`` (kV) through ``parts``: the drift of this file (before or
    after P(s) by its physics) with ``multi2.py``'s delay or load."""
    p = dict(parts)
    other = [(k, v) for k, v in parts if k not in DRIFTS]
    v = np.asarray(u, float)
    if "trap2" in p:
        k = p["trap2"]
        v = v - k["a1"] * _lowpass(v, rate, k["t1"]) - k["a2"] * _lowpass(v, rate, k["t2"])
    if "fast1" in p:
        k = p["fast1"]
        v = v - k["a"] * _lowpass(v, rate, k["t"])
    z = multi2_chain(v, rate, other) if other else _linear(v, rate, *_plant(None))
    if "sqv" in p:
        k = p["sqv"]
        z = z + k["c"] * _lowpass(np.asarray(u, float) ** 2 / 16.0, rate, k["t"])
    if "gainonly" in p:
        k = p["gainonly"]
        z = z * (1.0 - k["g"] * _lowpass0(u, rate, k["t"]) / 8.0)
    if "offsetonly" in p:
        k = p["offsetonly"]
        z = z + k["o"] * _lowpass0(u, rate, k["t"]) / 8.0
    if "slow1" in p:
        k = p["slow1"]
        q = _lowpass(np.asarray(u, float), rate, k["t"]) / 8.0
        z = z * (1.0 - k["g"] * q) + k["o"] * q
    return z


def make_case(directory: str, seed: int, i: int) -> dict | None:
    """Case ``i`` of :data:`KINDS` with draws from ``(seed, i)`` only, written to ``directory``; None when no
    visible draw was found in 12 tries."""
    forms = KINDS[i]
    rng = np.random.default_rng([seed, i])
    design = DESIGNS[i % len(DESIGNS)]
    rate = RATES[int(rng.integers(len(RATES)))]
    dur = 40.0 if rate <= 1000.0 else 20.0
    if design == "levels":
        u = _levels(rng, rate, dur)
    elif design == "paper":
        from hasel_bench import othersim as o
        u = o.excitation(rng, rate)[0]
    else:
        u = _command(design, rng, rate, dur)
    noise_kind = NOISES[int(rng.integers(len(NOISES)))]
    sd = float(rng.uniform(0.003, 0.012))
    z0 = _linear(u, rate, *_plant(None))
    for _ in range(12):
        parts = [(f, draw_drift(f, rng, 1.0) if f in DRIFTS else draw(f, rng, float(rng.uniform(0.6, 1.0)), u, z0,
                                                                      rate)) for f in forms]
        z = chain(u, rate, parts)
        if not np.all(np.isfinite(z)):
            continue
        vis = [float(np.std(z - chain(u, rate, [p for p in parts if p[0] != f]))) / sd for f in forms]
        if all(v >= MIN_VISIBLE for v in vis):
            break
    else:
        return None
    y = np.round((z + _noise(rng, u.size, rate, sd, noise_kind)) / LSB_MM) * LSB_MM
    num, den = paper.plant_tf()
    tag = "+".join(forms) or "free"
    path = os.path.join(directory, f"dr_{i:02d}_{tag}.npz")
    np.savez_compressed(path, t_s=np.arange(u.size) / rate, voltage_kv=u, stroke_mm=y, num=num, den=den)
    return {"path": path, "kind": f"{tag}:{design}:{rate:g}:{noise_kind}", "labels": sorted({LABEL[f] for f in forms}),
            "visible": [round(v, 1) for v in vis] if forms else [],
            "truth": [f"{f}:{ {a: round(float(b), 5) for a, b in k.items()} }" for f, k in parts] if forms else []}


def make(directory: str, seed: int = 1) -> list[dict]:
    """Every case of :data:`KINDS` (those with a visible draw) written to ``directory``; their labels."""
    return [c for c in (make_case(directory, seed, i) for i in range(len(KINDS))) if c is not None]


def drift_summary(cases: list[dict], rows: list[dict]) -> dict:
    """The drift cases named with a drift, T / S / false alarms over the set and each drift case's fitted drift."""
    dr = [r for r in rows if "charge_drift" in r["labels"]]
    return {"drift_named": f"{sum('charge_drift' in r['names'] for r in dr)}/{len(dr)}",
            "T": sum(len(set(r["labels"]) & set(r["names"])) for r in rows),
            "S": sum(len(set(r["names"]) - set(r["labels"])) for r in rows),
            "FA": f"{sum(bool(r['names']) for r in rows if not r['labels'])}/{sum(not r['labels'] for r in rows)}",
            "drift_fits": {r["kind"]: r.get("params", {}).get("charge_drift") for r in dr}}


def main(argv: list[str] | None = None) -> int:
    """``python bench/tune_diag/drifts.py --out DIR [--seed S] [--only SUBSTR,...] [--list]``."""
    return generator_main(argv, __doc__, make, 1, extra=drift_summary, serial=True)


if __name__ == "__main__":
    sys.exit(main())
