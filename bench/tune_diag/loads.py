"""Tuning cases of loads in other forms, alone and beside a delay, a drift or an input map (a tuning set, not verification).

``cases.py`` models a load as added inertia (``heavier_mode``, ``_double_pole_plant``): the double
pole pair's frequency and its damping ratio fall together. A load can also lower the frequency
with the damping ratio kept (a mass with its own proportional damping, a softer mount), and it can
sit on one mode or on the whole actuator. Here, with P(s)'s static gain kept:

- ``zeta_one``: one of the two (equal) mechanical pole pairs ``s^2 + 2 zeta w s + w^2`` has its
  frequency lowered 15-30 % (``w -> k w``, ``zeta`` kept);
- ``zeta_both``: both pairs lowered by the same factor (a mass on the whole actuator);
- ``mass_both``: both pairs with the inertia times ``1/k^2`` (``cases.py``'s form, frequency and
  damping ratio falling together), for comparison;

alone, and in pairs and triples beside:

- ``shift``: a transport delay (6-30 ms, othersim's ``time_delay:shift``);
- ``pade``: a 3rd-order Pade all-pass of such a delay (othersim's ``time_delay:pade``);
- ``creep``: a charge drift as a slow creep with the integral of the applied voltage,
  ``+c integral(u) dt`` through a leak of 300 s, reaching 0.15-0.5 mm (sign drawn) at the log's end
  at the mean command (not one of othersim's two drift kinds);
- ``map``: a static input map (othersim's ``static_nonlinearity``, a power law or a knee);

and two delays alone (``shift``, ``pade``) as controls: a change that turns delays into loads
shows there. Designs (othersim's excitation, multisine, PRBS, log chirp, closed-loop steps; see
``combos.py``), rates 200 Hz-2 kHz, noise white, coloured or with a slow wander, 0.003-0.012 mm.
Every member must be visible (``combos.MIN_VISIBLE`` noise rms), else the draw is repeated.

Run ``python bench/tune_diag/loads.py --out DIR [--seed S] [--only KIND,...]``; the output is
``cases.py``'s (one line per case, the summary with pairs and triples apart, ``DIR/results.json``)
plus ``load_recall_2`` / ``load_recall_3``: the share of pairs / triples with a load whose load
was named.
"""
from __future__ import annotations

import math
import os
import sys

import numpy as np

from hasel import paper
from hasel_bench import othersim as o

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from cases import _simulate  # noqa: E402
from combos import DESIGNS, MIN_VISIBLE, NOISES, _command, generator_main  # noqa: E402

F = o.ForeignEffect
RATES = (200.0, 500.0, 1000.0, 2000.0)
#: (load form or "", companions) per case; pairs and triples beside a delay, a drift, an input map
KINDS: tuple[tuple[str, tuple[str, ...]], ...] = (
    ("zeta_one", ()), ("zeta_both", ()), ("zeta_one", ()), ("zeta_both", ()),
    ("", ("shift",)), ("", ("pade",)),
    ("zeta_one", ("shift",)), ("zeta_one", ("pade",)), ("zeta_both", ("shift",)), ("zeta_both", ("pade",)),
    ("zeta_one", ("creep",)), ("zeta_both", ("creep",)), ("zeta_one", ("map",)), ("zeta_both", ("map",)),
    ("mass_both", ("shift",)), ("mass_both", ("pade",)),
    ("zeta_one", ("shift", "creep")), ("zeta_both", ("pade", "creep")), ("zeta_one", ("pade", "map")),
    ("zeta_both", ("shift", "map")), ("zeta_one", ("creep", "map")), ("zeta_both", ("shift", "creep")),
)
_LABEL = {"shift": "time_delay", "pade": "time_delay", "creep": "charge_drift", "map": "static_nonlinearity"}


def load_plant(form: str, k: float) -> tuple[np.ndarray, np.ndarray]:
    """P(s) with its mechanical pole pairs' frequency times ``k`` (< 1) in ``form`` (see the module), the
    numerator rescaled so that the static gain (mm/kV) is kept. Returns (num, den), descending powers of s."""
    num, den = paper.plant_tf()
    w = paper.P_NOTCH_RAD_S
    two_zw = 230.0  # 2 zeta w of P(s)'s pairs
    nominal = np.array([1.0, two_zw, w * w])
    if form == "mass_both":  # inertia times 1/k^2: (s^2/k^2 + 2 zeta w s + w^2), monic
        low = np.array([1.0, two_zw * k * k, (k * w) ** 2])
        pairs = (low, low)
    else:
        low = np.array([1.0, two_zw * k, (k * w) ** 2])  # zeta kept
        pairs = (nominal, low) if form == "zeta_one" else (low, low)
    den2 = np.polymul(np.polymul([1, 18.85], [1, 56.55]), np.polymul(*pairs))
    return num * (den2[-1] / den[-1]), den2


def creep(u: np.ndarray, rate: float, size_mm: float, tau_s: float = 300.0) -> np.ndarray:
    """A charge drift's creep (mm): ``c`` times the leaky integral (leak ``tau_s``) of the command ``u`` (kV),
    ``c`` set so that a constant command at ``u``'s mean would creep ``size_mm`` by the log's end."""
    dt = 1.0 / rate
    a = math.exp(-dt / tau_s)
    from scipy import signal

    q = signal.lfilter([dt], [1.0, -a], np.asarray(u, float))  # kV s
    t_end = u.size * dt
    ref = float(np.mean(u)) * tau_s * (1.0 - math.exp(-t_end / tau_s))
    return size_mm * q / ref if ref != 0 else np.zeros_like(q)


def _chain(u: np.ndarray, rate: float, form: str, k: float, effs: list[F], creep_mm: float) -> np.ndarray:
    plant = load_plant(form, k) if form else None
    z = _simulate(u, rate, effs, plant)
    return z + creep(u, rate, creep_mm) if creep_mm else z


def make_case(directory: str, seed: int, i: int) -> dict | None:
    """Case ``i`` of :data:`KINDS` with draws from ``(seed, i)`` only, written to ``directory``; None when no
    visible draw was found in 12 tries."""
    form, comp = KINDS[i]
    rng = np.random.default_rng([seed, i])
    design = DESIGNS[i % len(DESIGNS)]
    rate = RATES[int(rng.integers(len(RATES)))]
    dur = 40.0 if rate <= 1000.0 else 20.0
    u = o.excitation(rng, rate)[0] if design == "paper" else _command(design, rng, rate, dur)
    noise_kind = NOISES[int(rng.integers(len(NOISES)))]
    sd = float(rng.uniform(0.003, 0.012))
    for _ in range(12):
        k = 1.0 - float(rng.uniform(0.15, 0.30))
        effs = [o.sample_foreign("time_delay", rng, c) for c in comp if c in ("shift", "pade")]
        effs += [o.sample_foreign("static_nonlinearity", rng)] if "map" in comp else []
        creep_mm = (float(rng.uniform(0.15, 0.5)) * (1.0 if rng.random() < 0.5 else -1.0)) if "creep" in comp else 0.0
        z = _chain(u, rate, form, k, effs, creep_mm)
        if not np.all(np.isfinite(z)):
            continue
        vis = [float(np.std(z - _chain(u, rate, "", k, effs, creep_mm))) / sd] if form else []
        vis += [float(np.std(z - _chain(u, rate, form, k, [e for e in effs if e is not x], creep_mm))) / sd
                for x in effs]
        vis += [float(np.std(z - _chain(u, rate, form, k, effs, 0.0))) / sd] if creep_mm else []
        if all(v >= MIN_VISIBLE for v in vis):
            break
    else:
        return None
    y = np.round((z + o._coloured(rng, u.size, rate, sd, noise_kind)) / o.LASER_LSB_MM) * o.LASER_LSB_MM
    num, den = paper.plant_tf()
    tag = "+".join(([form] if form else []) + list(comp))
    path = os.path.join(directory, f"load_{i:02d}_{tag}.npz")
    np.savez_compressed(path, t_s=np.arange(u.size) / rate, voltage_kv=u, stroke_mm=y, num=num, den=den)
    labels = sorted(({"load_mass"} if form else set()) | {_LABEL[c] for c in comp})
    return {"path": path, "kind": f"{tag}:{design}:{rate:g}:{noise_kind}", "labels": labels,
            "visible": [round(v, 1) for v in vis],
            "truth": ([f"{form}: pole pair frequency x {k:.3f}"] if form else [])
            + [f"{e.name}:{e.kind}:{ {a: round(b, 4) for a, b in e.params.items()} }" for e in effs]
            + ([f"creep {creep_mm:+.3f} mm"] if creep_mm else [])}


def make(directory: str, seed: int = 3) -> list[dict]:
    """Every case of :data:`KINDS` (those with a visible draw) written to ``directory``; their labels."""
    return [c for c in (make_case(directory, seed, i) for i in range(len(KINDS))) if c is not None]


def load_recall(rows: list[dict], k: int) -> float | None:
    """Share of the ``k``-effect cases with a load in their truth whose names include ``load_mass``."""
    sub = [r for r in rows if len(r["labels"]) == k and "load_mass" in r["labels"]]
    return sum("load_mass" in r["names"] for r in sub) / len(sub) if sub else None


def main(argv: list[str] | None = None) -> int:
    """``python bench/tune_diag/loads.py --out DIR [--seed S] [--only SUBSTR,...] [--list]``."""
    return generator_main(argv, __doc__, make, 3, extra=lambda cases, rows: {
        "load_recall_2": load_recall(rows, 2), "load_recall_3": load_recall(rows, 3),
        "load_named_singles": load_recall(rows, 1)})


if __name__ == "__main__":
    sys.exit(main())
