"""Tuning cases of input-side static maps beside other effects, and triples with a small member (a tuning set,
not verification).

Two weaknesses of the diagnosis (issue 14; the second verification corpus showed them, this file is written
without reading it): an input-side static map (before the linear dynamics) beside another effect is named
``sensor_nonlinearity`` (an output-side curve), and triples lose their smaller members. Cases, on othersim's
chain (:mod:`hasel_bench.othersim`) with the nominal P(s):

- input maps of four shapes: ``power`` and ``knee`` (othersim's ``static_nonlinearity`` forms), ``softzone``
  (a dead-zone-like softening: below a level ``v_d`` the effective voltage's slope falls to ``1 - a``,
  smoothly over ``w``: ``f(v) = v - a w log(1 + exp((v_d - v) / w))``) and ``stiffen`` (a one-sided
  stiffening: above ``v_s`` the slope falls to ``1 - b``, ``f(v) = v - b w log(1 + exp((v - v_s) / w))``);
  ``softzone`` and ``stiffen`` act on the command before othersim's chain (a delay commutes with them;
  othersim's own maps sit after its slew limit and hysteresis);
- singles of each shape, and of a sensor curve (othersim's ``quadratic`` / ``exponential``) as controls;
- pairs of an input map beside a delay (``shift``, ``pade``), a drift (othersim's ``drift``, or ``creep``:
  ``loads.creep``), a load (``load``: othersim's ``heavier_mode``; ``zload``: ``loads.load_plant`` with the
  damping ratio kept), a hysteresis (``hyst``), a saturation (``slew``, ``soft_stroke``, ``vclip``: an
  amplifier limit the top 2-8 % of the command reach) or an asymmetric lag (``asym``); pairs of a sensor curve
  beside such effects as controls (a change that turns every map into an input map shows there);
- triples (a map and two others) in which one member (marked) is small: taking it out moves the noise-free
  output by 2-4 times the noise rms (the others at least ``combos.MIN_VISIBLE``).

Designs (othersim's excitation, multisine, PRBS, log chirp, closed-loop steps; ``combos.py``), rates
200 Hz-5 kHz, white, coloured or wandering noise 0.003-0.012 mm. Seed 41 for tuning; seed 42 held back.

Run ``python bench/tune_diag/maps.py --out DIR [--seed S] [--only KIND,...] [--list]``; the output is
``cases.py``'s (one line per case, the summary with pairs and triples apart, ``DIR/results.json``) plus
``input_map_named_2/3`` (share of pairs / triples with an input map whose names include
``static_nonlinearity``), ``input_map_as_sensor_2/3`` (... that name ``sensor_nonlinearity`` instead),
``sensor_named_2`` (sensor-curve pairs whose curve is named) and ``small_named_3`` (triples whose small
member is named).
"""
from __future__ import annotations

import os
import sys

import numpy as np

from hasel import paper
from hasel_bench import othersim as o

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from cases import _simulate  # noqa: E402
from combos import DESIGNS, MIN_VISIBLE, NOISES, _command, _scaled, generator_main  # noqa: E402
from loads import creep, load_plant  # noqa: E402

F = o.ForeignEffect
RATES = (200.0, 500.0, 1000.0, 2000.0, 5000.0)
MAPS = ("power", "knee", "softzone", "stiffen")
#: (map shape or "sensor", companions, index of the small member in (map,) + companions or -1), per case
KINDS: tuple[tuple[str, tuple[str, ...], int], ...] = (
    ("power", (), -1), ("knee", (), -1), ("softzone", (), -1), ("stiffen", (), -1), ("sensor", (), -1),
    ("sensor", (), -1),
    ("power", ("shift",), -1), ("knee", ("pade",), -1), ("softzone", ("drift",), -1), ("stiffen", ("load",), -1),
    ("power", ("hyst",), -1), ("knee", ("slew",), -1), ("softzone", ("soft_stroke",), -1),
    ("stiffen", ("creep",), -1), ("power", ("zload",), -1), ("knee", ("hyst",), -1), ("softzone", ("shift",), -1),
    ("stiffen", ("drift",), -1), ("power", ("vclip",), -1), ("knee", ("asym",), -1), ("softzone", ("load",), -1),
    ("stiffen", ("hyst",), -1),
    ("sensor", ("shift",), -1), ("sensor", ("hyst",), -1), ("sensor", ("load",), -1), ("sensor", ("drift",), -1),
    ("power", ("shift", "drift"), 2), ("knee", ("load", "hyst"), 0), ("softzone", ("pade", "slew"), 2),
    ("stiffen", ("hyst", "creep"), 2), ("power", ("load", "drift"), 1), ("knee", ("shift", "soft_stroke"), 0),
    ("softzone", ("hyst", "zload"), 1), ("stiffen", ("drift", "shift"), 2),
)
_LABEL = {"shift": "time_delay", "pade": "time_delay", "drift": "charge_drift", "creep": "charge_drift",
          "load": "load_mass", "zload": "load_mass", "hyst": "hysteresis", "slew": "saturation",
          "soft_stroke": "saturation", "vclip": "saturation", "asym": "asymmetric_dynamics",
          "sensor": "sensor_nonlinearity", **{m: "static_nonlinearity" for m in MAPS}}


def soft_map(u: np.ndarray, shape: str, p: dict) -> np.ndarray:
    """The command (kV) through the input map ``shape`` (``softzone`` or ``stiffen``, see the module) with
    parameters ``p`` (``a`` or ``b`` dimensionless, ``v_kv`` and ``w_kv`` kV); kV."""
    u = np.asarray(u, float)
    w = p["w_kv"]
    if shape == "softzone":
        return u - p["a"] * w * np.logaddexp(0.0, (p["v_kv"] - u) / w)
    return u - p["b"] * w * np.logaddexp(0.0, (u - p["v_kv"]) / w)


def _draw_map(shape: str, rng: np.random.Generator, u: np.ndarray, s: float) -> tuple[F | None, dict | None]:
    """A map of ``shape`` at size ``s`` (1: full): othersim's (an effect) or a command map (its parameters)."""
    if shape in ("power", "knee"):
        return _scaled(o.sample_foreign("static_nonlinearity", rng, shape), s), None
    if shape == "sensor":
        return _scaled(o.sample_foreign("sensor_nonlinearity", rng), s), None
    if shape == "softzone":
        return None, {"a": s * float(rng.uniform(0.5, 0.85)), "v_kv": float(np.quantile(u, rng.uniform(0.2, 0.4))),
                      "w_kv": float(rng.uniform(0.2, 0.5))}
    return None, {"b": s * float(rng.uniform(0.4, 0.7)), "v_kv": float(np.quantile(u, rng.uniform(0.6, 0.85))),
                  "w_kv": float(rng.uniform(0.15, 0.4))}


def _draw_companion(c: str, rng: np.random.Generator, u: np.ndarray, s: float) -> dict:
    """Companion ``c`` at size ``s``: {"eff": ForeignEffect} or {"creep_mm"}, {"vclip"}, {"zload"}."""
    if c in ("shift", "pade"):
        return {"eff": _scaled(o.sample_foreign("time_delay", rng, c), s)}
    if c == "drift":
        return {"eff": _scaled(o.sample_foreign("charge_drift", rng), s)}
    if c == "creep":
        return {"creep_mm": s * float(rng.uniform(0.15, 0.5)) * (1.0 if rng.random() < 0.5 else -1.0)}
    if c == "load":
        e = o.sample_foreign("load_mass", rng, "heavier_mode")
        return {"eff": F("load_mass", "heavier_mode", {"mass_ratio": s * e.params["mass_ratio"]})}
    if c == "zload":
        return {"zload": 1.0 - s * float(rng.uniform(0.15, 0.30))}
    if c == "hyst":
        return {"eff": _scaled(o.sample_foreign("hysteresis", rng), s)}
    if c in ("slew", "soft_stroke"):
        e = o.sample_foreign("saturation", rng, c)
        if c == "slew":  # a smaller slew effect is a higher limit
            return {"eff": F("saturation", "slew", {"slew_kv_s": e.params["slew_kv_s"] / max(s, 0.05)})}
        return {"eff": F("saturation", "soft_stroke", {"knee_mm": e.params["knee_mm"] + 2.0 * (1 - s),
                                                       "room_mm": e.params["room_mm"]})}
    if c == "vclip":
        return {"vclip": float(np.quantile(u, 1.0 - s * rng.uniform(0.02, 0.08)))}
    if c == "asym":
        e = o.sample_foreign("asymmetric_dynamics", rng)
        if e.kind == "rate_limit":
            return {"eff": F(e.name, e.kind, {"rate_mm_s": e.params["rate_mm_s"] / max(s, 0.05)})}
        return {"eff": e}
    raise ValueError(c)


def _chain(u: np.ndarray, rate: float, parts: list[dict]) -> np.ndarray:
    """The noise-free stroke (mm) of command ``u`` (kV) through ``parts`` (drawn members)."""
    v = np.asarray(u, float)
    for p in parts:
        if "vclip" in p:
            v = np.minimum(v, p["vclip"])
    for p in parts:
        if "cmd_map" in p:
            v = soft_map(v, p["shape"], p["cmd_map"])
    effs = [p["eff"] for p in parts if "eff" in p]
    k = next((p["zload"] for p in parts if "zload" in p), None)
    z = _simulate(v, rate, effs, load_plant("zeta_one", k) if k is not None else None)
    for p in parts:
        if "creep_mm" in p:
            z = z + creep(u, rate, p["creep_mm"])
    return z


def _describe(p: dict) -> str:
    if "eff" in p:
        e = p["eff"]
        return f"{e.name}:{e.kind}:{ {a: round(b, 4) for a, b in e.params.items()} }"
    if "cmd_map" in p:
        return f"static_nonlinearity:{p['shape']}:{ {a: round(b, 4) for a, b in p['cmd_map'].items()} }"
    if "creep_mm" in p:
        return f"charge_drift:creep {p['creep_mm']:+.3f} mm"
    if "vclip" in p:
        return f"saturation:voltage clip {p['vclip']:.2f} kV"
    return f"load_mass:zeta_one pole pair frequency x {p['zload']:.3f}"


def make_case(directory: str, seed: int, i: int) -> dict | None:
    """Case ``i`` of :data:`KINDS` with draws from ``(seed, i)`` only, written to ``directory``; None when no
    draw with every member visible (and the small one 2-4 noise rms) was found in 30 tries."""
    shape, comp, small = KINDS[i]
    rng = np.random.default_rng([seed, 4241, i])
    design = DESIGNS[i % len(DESIGNS)]
    rate = RATES[int(rng.integers(len(RATES)))]
    dur = 40.0 if rate <= 1000.0 else 20.0
    u = o.excitation(rng, rate)[0] if design == "paper" else _command(design, rng, rate, dur)
    noise_kind = NOISES[int(rng.integers(len(NOISES)))]
    sd = float(rng.uniform(0.003, 0.012))
    members = (shape,) + comp
    for _ in range(30):
        sizes = [float(rng.uniform(0.6, 1.0)) for _ in members]
        if small >= 0:
            sizes[small] = float(rng.uniform(0.1, 0.6))
        parts = []
        eff, cmd = _draw_map(shape, rng, u, sizes[0])
        parts.append({"eff": eff} if eff is not None else {"cmd_map": cmd, "shape": shape})
        parts += [_draw_companion(c, rng, u, s) for c, s in zip(comp, sizes[1:])]
        z = _chain(u, rate, parts)
        if not np.all(np.isfinite(z)):
            continue
        vis = [float(np.std(z - _chain(u, rate, [q for q in parts if q is not p]))) / sd for p in parts]
        if all(v >= MIN_VISIBLE for v in vis) and (small < 0 or 2.0 <= vis[small] <= 4.0):
            break
    else:
        return None
    y = np.round((z + o._coloured(rng, u.size, rate, sd, noise_kind)) / o.LASER_LSB_MM) * o.LASER_LSB_MM
    num, den = paper.plant_tf()
    tag = "+".join(members)
    path = os.path.join(directory, f"map_{i:02d}_{tag}.npz")
    np.savez_compressed(path, t_s=np.arange(u.size) / rate, voltage_kv=u, stroke_mm=y, num=num, den=den)
    labels = sorted({_LABEL[m] for m in members})
    return {"path": path, "kind": f"{tag}:{design}:{rate:g}:{noise_kind}", "labels": labels,
            "visible": [round(v, 1) for v in vis], "small": _LABEL[members[small]] if small >= 0 else None,
            "input_map": shape in MAPS, "truth": [_describe(p) for p in parts]}


def make(directory: str, seed: int = 41) -> list[dict]:
    """Every case of :data:`KINDS` (those with a visible draw) written to ``directory``; their labels."""
    return [c for c in (make_case(directory, seed, i) for i in range(len(KINDS))) if c is not None]


def _share(rows: list[dict], cases: list[dict], k: int, want, name: str) -> str | None:
    sub = [(r, c) for r, c in zip(rows, cases) if len(r["labels"]) == k and want(c)]
    return f"{sum(name in r['names'] for r, _ in sub)}/{len(sub)}" if sub else None


def extras(rows: list[dict], cases: list[dict]) -> dict:
    """The map-specific figures of the module's docstring."""
    out = {}
    for k in (1, 2, 3):
        out[f"input_map_named_{k}"] = _share(rows, cases, k, lambda c: c["input_map"], "static_nonlinearity")
        out[f"input_map_as_sensor_{k}"] = _share(rows, cases, k, lambda c: c["input_map"], "sensor_nonlinearity")
        out[f"sensor_named_{k}"] = _share(rows, cases, k, lambda c: not c["input_map"], "sensor_nonlinearity")
    sub = [(r, c) for r, c in zip(rows, cases) if c.get("small")]
    out["small_named_3"] = f"{sum(c['small'] in r['names'] for r, c in sub)}/{len(sub)}"
    out["ambiguous_map_sides"] = sum(any({"static_nonlinearity", "sensor_nonlinearity"} == {a, b}
                                         for a, b in r.get("ambiguous", [])) for r in rows)
    return out


def main(argv: list[str] | None = None) -> int:
    """``python bench/tune_diag/maps.py --out DIR [--seed S] [--only SUBSTR,...] [--list]``."""
    return generator_main(argv, __doc__, make, 41, extra=lambda cases, rows: extras(rows, cases))


if __name__ == "__main__":
    sys.exit(main())
