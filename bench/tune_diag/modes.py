"""Tuning cases of an added mode: a load on a compliant mount adds a lightly damped pole pair above the
resonance (a tuning set, not verification; session 13, ``RESULT-h-pole.md``).

``multi2.py``'s ``polepair`` load multiplies P(s) by ``w^2 / (s^2 + 2 z w s + w^2)``: the static gain is kept,
the magnitude rises below ``w`` (a resonant peak for a small ``z``) and falls above it, and the phase lags by
up to 180 degrees more. Within the excited band the lag can pass for a delay; the magnitude cannot. Here:

- ``mode``: P(s) times such a pair, ``w`` 1.2-4x P(s)'s resonance (19.4 Hz), ``z`` 0.1-0.5;

alone, beside ``loads.py``'s companions (``shift`` a transport delay, ``pade`` its Pade all-pass, ``creep`` a
charge creep, ``map`` an input map), and as controls two delays alone and two effect-free logs (a change
that names a load on those shows there). Designs: othersim's excitation, multisine, PRBS, log chirp and
closed-loop steps (``combos._command``); rates 200 Hz-5 kHz; white, coloured or wandering noise 0.003-0.012
mm, quantised to the laser's LSB. The mode is at least ``MODE_VISIBLE`` noise rms, the companions at least
``combos.MIN_VISIBLE``, else the draw is repeated.

Run ``python bench/tune_diag/modes.py --out DIR [--seed S] [--only SUBSTR,...] [--list]``; seed 1 is for
tuning. The output is ``cases.py``'s (one line per case, the summary, ``DIR/results.json``) plus
``mode_named`` (cases with a mode whose names include ``load_mass``), ``mode_form`` (those whose load is of
the ``model:mode`` form) and ``mode_hz_error`` (per such case: the fitted over the true mode frequency - 1).
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
from loads import creep  # noqa: E402

F = o.ForeignEffect
RATES = (200.0, 500.0, 1000.0, 2000.0, 5000.0)
#: Least visibility (noise rms) of the added mode: a load the data hardly show is not this set's question.
MODE_VISIBLE = 3.0
#: (mode or "", companions) per case
KINDS: tuple[tuple[str, tuple[str, ...]], ...] = (
    ("mode", ()), ("mode", ()), ("mode", ()), ("mode", ()), ("mode", ()), ("mode", ()),
    ("", ("shift",)), ("", ("pade",)), ("", ()), ("", ()),
    ("mode", ("shift",)), ("mode", ("pade",)), ("mode", ("creep",)), ("mode", ("map",)),
    ("mode", ("shift", "creep")), ("mode", ("pade", "map")),
)
_LABEL = {"shift": "time_delay", "pade": "time_delay", "creep": "charge_drift", "map": "static_nonlinearity"}


def mode_plant(ratio: float, zeta: float) -> tuple[np.ndarray, np.ndarray]:
    """P(s) times ``w^2 / (s^2 + 2 zeta w s + w^2)``, ``w = ratio`` times P(s)'s resonance (rad/s); the static
    gain (mm/kV) kept. Returns (num, den), descending powers of s."""
    num, den = paper.plant_tf()
    w = ratio * paper.P_NOTCH_RAD_S
    return np.polymul(num, [w * w]), np.polymul(den, [1.0, 2.0 * zeta * w, w * w])


def _chain(u: np.ndarray, rate: float, mode: tuple[float, float] | None, effs: list[F], creep_mm: float) -> np.ndarray:
    z = _simulate(u, rate, effs, mode_plant(*mode) if mode else None)
    return z + creep(u, rate, creep_mm) if creep_mm else z


def make_case(directory: str, seed: int, i: int) -> dict | None:
    """Case ``i`` of :data:`KINDS` with draws from ``(seed, i)`` only, written to ``directory``; None when no
    visible draw was found in 12 tries."""
    form, comp = KINDS[i]
    rng = np.random.default_rng([seed, 7711, i])
    design = DESIGNS[i % len(DESIGNS)]
    rate = RATES[int(rng.integers(len(RATES)))]
    dur = 40.0 if rate <= 1000.0 else 20.0 if rate <= 2000.0 else 12.0
    u = o.excitation(rng, rate)[0] if design == "paper" else _command(design, rng, rate, dur)
    u = u[: int(min(u.size, 40.0 * rate))]
    noise_kind = NOISES[int(rng.integers(len(NOISES)))]
    sd = float(rng.uniform(0.003, 0.012))
    for _ in range(12):
        mode = (float(rng.uniform(1.2, 4.0)), float(rng.uniform(0.1, 0.5))) if form else None
        effs = [o.sample_foreign("time_delay", rng, c) for c in comp if c in ("shift", "pade")]
        effs += [o.sample_foreign("static_nonlinearity", rng)] if "map" in comp else []
        creep_mm = (float(rng.uniform(0.15, 0.5)) * (1.0 if rng.random() < 0.5 else -1.0)) if "creep" in comp else 0.0
        z = _chain(u, rate, mode, effs, creep_mm)
        if not np.all(np.isfinite(z)):
            continue
        vis = [float(np.std(z - _chain(u, rate, None, effs, creep_mm))) / sd] if form else []
        vis += [float(np.std(z - _chain(u, rate, mode, [e for e in effs if e is not x], creep_mm))) / sd
                for x in effs]
        vis += [float(np.std(z - _chain(u, rate, mode, effs, 0.0))) / sd] if creep_mm else []
        if (not form or vis[0] >= MODE_VISIBLE) and all(v >= MIN_VISIBLE for v in vis):
            break
    else:
        return None
    y = np.round((z + o._coloured(rng, u.size, rate, sd, noise_kind)) / o.LASER_LSB_MM) * o.LASER_LSB_MM
    num, den = paper.plant_tf()
    tag = "+".join(([form] if form else []) + list(comp)) or "free"
    path = os.path.join(directory, f"mode_{i:02d}_{tag}.npz")
    np.savez_compressed(path, t_s=np.arange(u.size) / rate, voltage_kv=u, stroke_mm=y, num=num, den=den)
    labels = sorted(({"load_mass"} if form else set()) | {_LABEL[c] for c in comp})
    f_res = paper.P_NOTCH_RAD_S / (2 * math.pi)
    return {"path": path, "kind": f"{tag}:{design}:{rate:g}:{noise_kind}", "labels": labels,
            "visible": [round(v, 1) for v in vis],
            "mode_hz": mode[0] * f_res if mode else None, "mode_zeta": mode[1] if mode else None,
            "truth": ([f"mode: {mode[0] * f_res:.2f} Hz ({mode[0]:.2f} x resonance), zeta {mode[1]:.3f}"] if mode else [])
            + [f"{e.name}:{e.kind}:{ {a: round(b, 4) for a, b in e.params.items()} }" for e in effs]
            + ([f"creep {creep_mm:+.3f} mm"] if creep_mm else [])}


def make(directory: str, seed: int = 1) -> list[dict]:
    """Every case of :data:`KINDS` (those with a visible draw) written to ``directory``; their labels."""
    return [c for c in (make_case(directory, seed, i) for i in range(len(KINDS))) if c is not None]


def mode_summary(cases: list[dict], rows: list[dict]) -> dict:
    """``mode_named``, ``mode_form`` (``"k/n"`` of the cases with a mode) and ``mode_hz_error`` (the fitted over
    the true mode frequency - 1, per case with a ``model:mode`` load named, rounded)."""
    sub = [(c, r) for c, r in zip(cases, rows) if c.get("mode_hz")]
    named = [(c, r) for c, r in sub if "load_mass" in r["names"]]
    form = [(c, r) for c, r in named if "mode_hz" in (r.get("params", {}).get("load_mass") or {})]
    return {"mode_named": f"{len(named)}/{len(sub)}", "mode_form": f"{len(form)}/{len(sub)}",
            "mode_hz_error": [round(r["params"]["load_mass"]["mode_hz"] / c["mode_hz"] - 1.0, 3) for c, r in form]}


def main(argv: list[str] | None = None) -> int:
    """``python bench/tune_diag/modes.py --out DIR [--seed S] [--only SUBSTR,...] [--list]``."""
    return generator_main(argv, __doc__, make, 1, extra=mode_summary)


if __name__ == "__main__":
    sys.exit(main())
