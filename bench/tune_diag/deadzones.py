"""Dead bands and thresholds of the input map, alone and beside other effects (a tuning set, not verification;
session 13, ``RESULT-h-dead.md``).

A HASEL actuator does not move until the field overcomes the film's stiffness and the liquid's resistance:
below a threshold voltage nothing happens, above it the stroke follows. ``multi2.py``'s ``deadzone`` (a
smooth symmetric dead band) was lost to a load's gain and a sensor curve on seed 21. Here, every form is
simulated by this file's own code (scipy's zero-order-hold P(s) and ``multi2.py``'s helpers for the
companions; no hasel effect class):

- ``hard``: a hard symmetric dead band ``g sign(v) max(|v| - d, 0)``;
- ``soft``: a soft one, the corner rounded over ``w`` = 0.1-0.4 kV
  (``g sign(v) w softplus((|v| - d) / w)``, ``multi2.py``'s form with a wider corner);
- ``onesided``: a one-sided threshold ``g max(v - d, 0)`` (a HASEL driven 0-9 kV; below 0 kV nothing);
- ``powdead``: a threshold with a power law above it, ``g max(v - d, 0)^p``, ``p`` 1.2-1.8 (the
  electrostatic pressure growing faster than the voltage once the pouch zips);

with ``d`` 0.2-2 kV and the gain ``g`` set so that the map meets the nominal line at the command's 90 %
quantile of ``|v|`` (a calibration at the working voltage). Companions: ``shift`` a transport delay of
4-15 ms before the map (the amplifier's), ``polepair`` an extra pole pair (a payload on a compliant mount,
``multi2.py``'s), ``trap2`` charge trapped with two time constants (``multi2.py``'s). Controls: a sensor's
``tanhsensor`` and ``cubic`` read-outs, ``pwpow`` a power law without a threshold (an input map the
polynomial already follows), a delay alone, and effect-free logs.

Commands that cross the thresholds (a HASEL is driven from 0 kV): ``chirp0`` a raised-cosine log chirp
0.2-20 Hz from 0 kV to 6-8 kV, ``steps0`` random levels 0-8 kV held 0.15-1.2 s (some at 0 kV) through the
amplifier's 2 ms edge, ``multisine0`` a multisine about 3-4 kV clipped at 0 kV, ``paper`` othersim's
researcher command. Rates 200 Hz-5 kHz, white, AR(1)-coloured or wandering noise (``multi2.py``'s) at
4-10x below the smallest member (at most 0.03 mm rms), 12-bit laser quantisation.

Run ``python bench/tune_diag/deadzones.py --out DIR [--seed S] [--only SUBSTR,...] [--list]``. Seed 1 is
for tuning. The output is ``cases.py``'s (one line per case, the summary, ``DIR/results.json``) plus
``dead_named`` (cases with a threshold map whose ``static_nonlinearity`` was named), ``dead_form`` (of
those, named with the ``input:dead`` form) and ``threshold_error_kv`` (fitted minus true threshold, per
case with the form).
"""
from __future__ import annotations

import os
import sys

import numpy as np

from hasel_bench import othersim as o

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import multi2 as m2  # noqa: E402
from combos import generator_main  # noqa: E402

RATES = (200.0, 500.0, 1000.0, 2000.0, 5000.0)
DESIGNS = ("chirp0", "steps0", "multisine0", "paper")
NOISES = ("white", "coloured", "wander")
DEAD_FORMS = ("hard", "soft", "onesided", "powdead")
LABEL = {"hard": "static_nonlinearity", "soft": "static_nonlinearity", "onesided": "static_nonlinearity",
         "powdead": "static_nonlinearity", "pwpow": "static_nonlinearity", "shift": "time_delay",
         "polepair": "load_mass", "trap2": "charge_drift", "tanhsensor": "sensor_nonlinearity",
         "cubic": "sensor_nonlinearity"}
#: the forms of each case; () is an effect-free log
KINDS: tuple[tuple[str, ...], ...] = (
    ("hard",), ("soft",), ("onesided",), ("powdead",), ("hard",), ("soft",), ("onesided",), ("powdead",),
    ("hard",), ("hard", "shift"), ("soft", "polepair"), ("onesided", "trap2"), ("powdead", "shift"),
    ("hard", "polepair"), ("soft", "shift"),
    ("tanhsensor",), ("cubic",), ("pwpow",), ("shift",),
    (), (), (),
)


def command(design: str, rng: np.random.Generator, rate: float, dur: float) -> np.ndarray:
    """The command (kV) of ``design`` (see the module), at ``rate`` Hz for ``dur`` s."""
    n = int(round(dur * rate))
    t = np.arange(n) / rate
    if design == "chirp0":
        f0, f1 = 0.2, 20.0
        ph = 2 * np.pi * f0 * dur / np.log(f1 / f0) * (np.exp(t / dur * np.log(f1 / f0)) - 1.0)
        return float(rng.uniform(6.0, 8.0)) * 0.5 * (1.0 - np.cos(ph))
    if design == "steps0":
        u = np.empty(n)
        k = 0
        while k < n:
            m = int(rng.uniform(0.15, 1.2) * rate)
            u[k:k + m] = 0.0 if rng.random() < 0.15 else rng.uniform(0.0, 8.0)
            k += m
        return m2._lowpass(u, rate, 2e-3)
    if design == "multisine0":
        fr = np.geomspace(0.1, 30.0, 24)
        u = sum(np.sin(2 * np.pi * f * t + rng.uniform(0, 2 * np.pi)) / np.sqrt(1 + f / 3.0) for f in fr)
        u = (u - u.mean()) / np.std(u)
        return np.clip(rng.uniform(3.0, 4.0) + rng.uniform(1.6, 2.2) * u, 0.0, 9.0)
    u = o.excitation(rng, rate)[0]
    return u[: int(min(u.size, 40.0 * rate))]


def draw(form: str, rng: np.random.Generator, u: np.ndarray, z0: np.ndarray, rate: float) -> dict:
    """Parameters of ``form`` for the command ``u`` (kV) and the nominal stroke ``z0`` (mm) at ``rate`` Hz."""
    v90 = float(np.quantile(np.abs(u), 0.9))
    if form in DEAD_FORMS:
        p = {"d": float(rng.uniform(0.2, 2.0)), "v90": v90}
        if form == "soft":
            p["w"] = float(rng.uniform(0.1, 0.4))
        if form == "powdead":
            p["p"] = float(rng.uniform(1.2, 1.8))
        return p
    if form == "shift":
        return {"d": float(rng.uniform(4e-3, 15e-3))}
    return m2.draw(form, rng, float(rng.uniform(0.6, 1.0)), u, z0, rate)


def dead(form: str, k: dict, v: np.ndarray) -> np.ndarray:
    """The effective voltage (kV) of the threshold map ``form`` with parameters ``k`` for the voltage ``v`` (kV)."""
    d, v90 = k["d"], k["v90"]
    a = np.abs(v)
    if form == "hard":
        return np.sign(v) * np.maximum(a - d, 0.0) * v90 / max(v90 - d, 1e-3)
    if form == "soft":
        w = k["w"]
        ref = w * np.logaddexp(0.0, (v90 - d) / w)
        return np.sign(v) * w * np.logaddexp(0.0, (a - d) / w) * v90 / ref
    if form == "onesided":
        return np.maximum(v - d, 0.0) * v90 / max(v90 - d, 1e-3)
    p = k["p"]
    return np.maximum(v - d, 0.0) ** p * v90 / max(v90 - d, 1e-3) ** p


def chain(u: np.ndarray, rate: float, parts: list[tuple[str, dict]]) -> np.ndarray:
    """The noise-free stroke (mm) of the command ``u`` (kV) through ``parts``: the delay (the amplifier's),
    the threshold map, then ``multi2.chain`` (input power law, trapped charge, P(s) with its load, sensor)."""
    p = dict(parts)
    v = np.asarray(u, float)
    if "shift" in p:
        v = m2._frac_delay(v, p["shift"]["d"] * rate)
    for f in DEAD_FORMS:
        if f in p:
            v = dead(f, p[f], v)
    return m2.chain(v, rate, [(f, k) for f, k in parts if f not in DEAD_FORMS and f != "shift"])


def make_case(directory: str, seed: int, i: int) -> dict | None:
    """Case ``i`` of :data:`KINDS`, its draws from ``(seed, i)`` only, written to ``directory``; None when no
    draw met the sizes in 40 tries (members within 6x of each other, noise 4-10x below the smallest, at most
    0.03 mm)."""
    forms = KINDS[i]
    rng = np.random.default_rng([seed, 3323, i])
    design = DESIGNS[i % len(DESIGNS)]
    rate = RATES[int(rng.integers(len(RATES)))]
    dur = 20.0 if rate <= 1000.0 else 12.0
    u = command(design, rng, rate, dur)
    noise_kind = NOISES[int(rng.integers(len(NOISES)))]
    z0 = chain(u, rate, [])
    sd = float(rng.uniform(0.003, 0.01))
    parts: list[tuple[str, dict]] = []
    vis: list[float] = []
    for _ in range(40):
        if not forms:
            break
        parts = [(f, draw(f, rng, u, z0, rate)) for f in forms]
        z = chain(u, rate, parts)
        if not np.all(np.isfinite(z)):
            continue
        raw = [float(np.std(z - chain(u, rate, [q for q in parts if q is not p]))) for p in parts]
        if len(raw) > 1 and max(raw) / min(raw) > 6.0:
            continue
        # noise 4-10x below the smallest member, at most the laser's 0.03 mm (a large map then stands far out)
        sd = min(min(raw) / float(rng.uniform(4.0, 10.0)), 0.03)
        if sd >= 0.0015:
            vis = [r / sd for r in raw]
            break
    else:
        return None
    z = chain(u, rate, parts)
    y = np.round((z + m2._noise(rng, u.size, rate, sd, noise_kind)) / m2.LSB_MM) * m2.LSB_MM
    num, den = m2.paper.plant_tf()
    tag = "+".join(forms) or "free"
    path = os.path.join(directory, f"dz_{i:02d}_{tag}.npz")
    np.savez_compressed(path, t_s=np.arange(u.size) / rate, voltage_kv=u, stroke_mm=y, num=num, den=den)
    return {"path": path, "kind": f"{tag}:{design}:{rate:g}:{noise_kind}", "labels": sorted({LABEL[f] for f in forms}),
            "visible": [round(v, 1) for v in vis], "sd_mm": sd,
            "threshold_kv": next((k["d"] for f, k in parts if f in DEAD_FORMS), None),
            "truth": [f"{f}:{ {a: round(float(b), 5) for a, b in k.items()} }" for f, k in parts]}


def make(directory: str, seed: int = 1) -> list[dict]:
    """Every case of :data:`KINDS` with a draw that met the sizes, written to ``directory``; their labels."""
    return [c for c in (make_case(directory, seed, i) for i in range(len(KINDS))) if c is not None]


def dead_summary(cases: list[dict], rows: list[dict]) -> dict:
    """Cases with a threshold map: how many had ``static_nonlinearity`` named, how many with the dead-band form,
    and the fitted minus true threshold (kV) of those."""
    sub = [(c, r) for c, r in zip(cases, rows) if c.get("threshold_kv") is not None]
    named = [(c, r) for c, r in sub if "static_nonlinearity" in r["names"]]
    form = [(c, r) for c, r in named if r.get("params", {}).get("static_nonlinearity", {}).get("variant") == "input:dead"]
    err = [round(r["params"]["static_nonlinearity"]["threshold"] - c["threshold_kv"], 3) for c, r in form]
    return {"dead_named": f"{len(named)}/{len(sub)}", "dead_form": f"{len(form)}/{len(named)}",
            "threshold_error_kv": err}


def main(argv: list[str] | None = None) -> int:
    """``python bench/tune_diag/deadzones.py --out DIR [--seed S] [--only SUBSTR,...] [--list]``."""
    return generator_main(argv, __doc__, make, 1, extra=dead_summary, serial=True)


if __name__ == "__main__":
    sys.exit(main())
