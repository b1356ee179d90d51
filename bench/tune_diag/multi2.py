"""Pairs and triples of effects in physical forms the project's generators do not use (a tuning set, not
verification; session 11, ``RESULT-h-triples.md``).

Independent checks lose members of pairs and especially triples while the project's own tuning sets
(``combos.py``, ``maps.py``, ``other_pairs.py``, all built on othersim's forms) do not: those forms are too
close to the diagnosis's own effect shapes. Every effect here is simulated by this file's own code
(scipy's discretisation of P(s) only; no hasel effect class, no othersim effect), from the physics of a
HASEL actuator, its amplifier and its sensor:

- ``static_nonlinearity``: ``pwpow`` an electrostatic piecewise power law (``(v/v_b)^p1`` below ``v_b``,
  ``p1`` 1.3-1.8, a softer power ``p2`` 0.4-0.8 above, slope continuous, normalised to the command's
  median); ``deadzone`` a symmetric dead zone of 0.3-1.2 kV (smoothed over 0.03 kV), gain restored at
  the command's 90 % quantile;
- ``sensor_nonlinearity``: ``tanhsensor`` a compressing read-out ``L tanh(z / L)``; ``cubic`` a cubic
  term about the stroke's mid level;
- ``saturation``: ``expstop`` a one-sided soft end stop on the stroke (``knee + room (1 - exp(-(z - knee)
  / room))`` above the knee); ``softclip`` an amplifier soft clip (``v_k + r tanh((v - v_k)/r)`` above
  ``v_k``); ``slewrc`` a current-limited amplifier (rate limit ``S / (1 + v / 4 kV)``: the film's
  capacitance grows as it zips);
- ``hysteresis``: ``boucwen`` a Bouc-Wen loop on the voltage (``n = 1``, ``beta = gamma``, loop
  half-width 0.1-0.4 kV); ``backlash`` a play on the stroke after the dynamics (0.02-0.12 mm);
- ``asymmetric_dynamics``: ``rcamp`` an amplifier that charges through a small and discharges through a
  large resistance (tau up 0.3-2 ms, down 8-40 ms); ``releaselag`` a stroke that follows a rise at once
  and a fall through a first-order lag (10-40 ms: the liquid flows back slowly);
- ``charge_drift``: ``trap2`` charge trapped with two time constants (1-4 s and 8-30 s) screening the
  voltage; ``sqdrive`` a creep of the stroke driven by ``V^2`` through a 2-10 s lag;
- ``load_mass``: ``polepair`` an extra pole pair (a payload on a compliant mount) at 1.5-5x the
  resonance, damping 0.15-0.4; ``damping`` the resonance pair's damping ratio moved (x0.35-0.6 or
  x1.8-2.5) and its frequency lowered up to 15 %, static gain kept;
- ``time_delay``: ``delaylag`` part pure delay (2-10 ms) part first-order lag (2-8 ms); ``frac`` a pure
  delay of 1.3-4.7 samples (fractional, by linear interpolation).

Cases: 4 singles (controls), 12 pairs, 14 triples (most with one member 3-10x smaller than the largest,
still 3-5 noise rms visible), 4 effect-free logs. Designs: the paper's researcher command, multisine,
PRBS, log chirp, closed-loop steps (commands of ``combos._command``) and random levels (this file's).
Rates 200 Hz-5 kHz, white, AR(1)-coloured or wandering noise, 12-bit laser quantisation.

Run ``python bench/tune_diag/multi2.py --out DIR [--seed S] [--only SUBSTR,...] [--list]``. Seed 21 is for
tuning; seed 22 is held back. Each case is diagnosed with ``DiagnoseOptions(jobs=1)`` (one process); the
progress lines go to ``DIR/trace_NN.txt``; per lost member the stage where it was lost is classified
(:func:`where_lost`) and tabulated in ``DIR/results.json``.
"""
from __future__ import annotations

import json
import os
import sys
import time

import numpy as np
from scipy import signal

from hasel import paper

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from combos import _command, generator_cases, generator_parser  # noqa: E402

RATES = (200.0, 500.0, 1000.0, 2000.0, 5000.0)
DESIGNS = ("paper", "multisine", "prbs", "chirp", "cl_steps", "levels")
NOISES = ("white", "coloured", "wander")
LSB_MM = 10.0 * 3.0 / 4096  # the laser's 12-bit ADC (10 V full scale, 3 mm/V)

LABEL = {"pwpow": "static_nonlinearity", "deadzone": "static_nonlinearity",
         "tanhsensor": "sensor_nonlinearity", "cubic": "sensor_nonlinearity",
         "expstop": "saturation", "softclip": "saturation", "slewrc": "saturation",
         "boucwen": "hysteresis", "backlash": "hysteresis",
         "rcamp": "asymmetric_dynamics", "releaselag": "asymmetric_dynamics",
         "trap2": "charge_drift", "sqdrive": "charge_drift",
         "polepair": "load_mass", "damping": "load_mass",
         "delaylag": "time_delay", "frac": "time_delay"}

#: (forms, index of the small member or -1) per case; () is an effect-free log
KINDS: tuple[tuple[tuple[str, ...], int], ...] = (
    (("deadzone",), -1), (("boucwen",), -1), (("trap2",), -1), (("polepair",), -1),
    (("pwpow", "trap2"), 1), (("deadzone", "polepair"), 1), (("expstop", "rcamp"), -1),
    (("boucwen", "damping"), 0), (("delaylag", "sqdrive"), -1), (("tanhsensor", "backlash"), -1),
    (("softclip", "frac"), -1), (("pwpow", "damping"), -1), (("releaselag", "sqdrive"), 1),
    (("deadzone", "delaylag"), -1), (("cubic", "polepair"), 1), (("slewrc", "trap2"), -1),
    (("expstop", "rcamp", "polepair"), 0), (("pwpow", "polepair", "trap2"), 1),
    (("deadzone", "sqdrive", "delaylag"), 1), (("boucwen", "damping", "pwpow"), 0),
    (("backlash", "polepair", "delaylag"), 0), (("softclip", "releaselag", "damping"), 2),
    (("tanhsensor", "trap2", "frac"), 2), (("pwpow", "boucwen", "sqdrive"), 2),
    (("expstop", "rcamp", "trap2"), 1), (("deadzone", "polepair", "backlash"), 2),
    (("cubic", "delaylag", "damping"), 2), (("slewrc", "pwpow", "polepair"), 1),
    (("rcamp", "boucwen", "delaylag"), 2), (("pwpow", "damping", "trap2"), -1),
    ((), -1), ((), -1), ((), -1), ((), -1),
)


# ---------------------------------------------------------------------------------------------- the plant
def _plant(form: dict | None) -> tuple[np.ndarray, np.ndarray]:
    """P(s) (kV -> mm), or P(s) with the load ``form`` ({"polepair": (w rad/s, zeta)} or {"damping":
    (frequency factor, damping factor)}); static gain kept."""
    num, den = paper.plant_tf()
    if not form:
        return num, den
    w0 = paper.P_NOTCH_RAD_S
    if "polepair" in form:
        w, z = form["polepair"]
        return np.polymul(num, [w * w]), np.polymul(den, [1.0, 2 * z * w, w * w])
    f, m = form["damping"]
    z0 = 230.0 / (2 * w0)
    w = f * w0
    quad = [1.0, 2 * z0 * m * w, w * w]
    den2 = np.polymul(np.polymul([1, 18.85], [1, 56.55]), np.polymul(quad, quad))
    return num * (w / w0) ** 4, den2


def _linear(x: np.ndarray, rate: float, num, den) -> np.ndarray:
    """``x`` through num/den, zero-order hold at ``rate``, started at rest at ``x[0]``."""
    b, a, _ = signal.cont2discrete((num, den), 1.0 / rate, method="zoh")
    b = np.ravel(b)
    zi = signal.lfilter_zi(b, a) * x[0]
    return signal.lfilter(b, a, x, zi=zi)[0]


def _lowpass(x: np.ndarray, rate: float, tau: float) -> np.ndarray:
    """First-order lag of ``x`` (time constant ``tau`` s), exact for a held input, started at ``x[0]``."""
    a = np.exp(-1.0 / (rate * tau))
    zi = np.array([a * x[0]])
    return signal.lfilter([1 - a], [1, -a], x, zi=zi)[0]


def _frac_delay(x: np.ndarray, n: float) -> np.ndarray:
    """``x`` delayed by ``n`` samples (fractional: linear interpolation), the first value held."""
    i = np.arange(x.size) - n
    return np.interp(i, np.arange(x.size), x, left=x[0])


def _play(x: np.ndarray, r: float) -> np.ndarray:
    """Backlash (play) of half-width ``r`` on ``x``."""
    y = np.empty_like(x)
    p = x[0]
    for k, v in enumerate(x):
        p = min(max(p, v - r), v + r)
        y[k] = p
    return y


def _boucwen(v: np.ndarray, h_max: float) -> np.ndarray:
    """Bouc-Wen variable (n = 1, A = 1, beta = gamma = 1 / (2 h_max)) driven by ``v``; bounded by h_max."""
    h = np.empty_like(v)
    c = 1.0 / (2 * h_max)
    hk = 0.0
    sub = 8
    for k in range(v.size):
        dv = (v[k] - v[k - 1]) / sub if k else 0.0
        for _ in range(sub):
            hk += dv * (1.0 - (c * np.sign(dv * hk) + c) * abs(hk))
        h[k] = hk
    return h


def _asym_lag(x: np.ndarray, rate: float, tau_up: float, tau_down: float) -> np.ndarray:
    """A lag with one time constant rising and another falling (exact per held step)."""
    au, ad = np.exp(-1.0 / (rate * tau_up)) if tau_up > 0 else 0.0, np.exp(-1.0 / (rate * tau_down))
    y = np.empty_like(x)
    p = x[0]
    for k, v in enumerate(x):
        a = au if v > p else ad
        p = a * p + (1 - a) * v
        y[k] = p
    return y


def _slew(x: np.ndarray, rate: float, s0: float) -> np.ndarray:
    """``x`` through a rate limit ``s0 / (1 + x / 4)`` kV/s (a current limit into a growing capacitance)."""
    y = np.empty_like(x)
    p = x[0]
    for k, v in enumerate(x):
        lim = s0 / (1.0 + max(p, 0.0) / 4.0) / rate
        p += min(max(v - p, -lim), lim)
        y[k] = p
    return y


# ---------------------------------------------------------------------------------------------- the chain
def draw(form: str, rng: np.random.Generator, s: float, u: np.ndarray, z0: np.ndarray, rate: float) -> dict:
    """Parameters of ``form`` at size ``s`` (1 full, toward 0 no effect); ``u`` the command (kV), ``z0``
    the nominal stroke (mm), for levels; ``rate`` Hz."""
    q = lambda x, a, b: float(np.quantile(x, rng.uniform(a, b)))  # noqa: E731
    if form == "pwpow":
        return {"vb": q(u, 0.3, 0.6), "p1": 1 + s * rng.uniform(0.3, 0.8), "p2": 1 - s * rng.uniform(0.2, 0.6),
                "vref": float(np.median(u))}
    if form == "deadzone":
        return {"d": s * rng.uniform(0.3, 1.2), "v90": float(np.quantile(np.abs(u), 0.9))}
    if form == "tanhsensor":
        return {"L": float(np.max(np.abs(z0))) * rng.uniform(0.9, 1.6) / max(s, 0.05)}
    if form == "cubic":
        span = float(np.ptp(z0))
        return {"zc": float(np.median(z0)), "c": s * rng.uniform(0.15, 0.35) * (1 if rng.random() < 0.5 else -1)
                / max(span / 2, 1e-6) ** 2}
    if form == "expstop":
        return {"knee": q(z0, 0.95 - 0.25 * s, 0.97 - 0.2 * s), "room": rng.uniform(0.15, 0.5)}
    if form == "softclip":
        return {"vk": q(u, 0.97 - 0.17 * s, 0.99 - 0.14 * s), "r": rng.uniform(0.3, 0.8)}
    if form == "slewrc":
        du = np.abs(np.diff(u)) * rate
        return {"s0": float(np.quantile(du, 0.999)) * rng.uniform(0.15, 0.5) / max(s, 0.05)}
    if form == "boucwen":
        return {"h": s * rng.uniform(0.1, 0.4)}
    if form == "backlash":
        return {"r": s * rng.uniform(0.02, 0.12)}
    if form == "rcamp":
        return {"up": s * rng.uniform(0.3e-3, 2e-3), "down": s * rng.uniform(8e-3, 40e-3)}
    if form == "releaselag":
        return {"tau": s * rng.uniform(10e-3, 40e-3)}
    if form == "trap2":
        return {"a1": s * rng.uniform(0.05, 0.15), "t1": rng.uniform(1, 4), "a2": s * rng.uniform(0.05, 0.15),
                "t2": rng.uniform(8, 30)}
    if form == "sqdrive":
        return {"c": s * rng.uniform(0.1, 0.4) * (1 if rng.random() < 0.6 else -1), "tau": rng.uniform(2, 10)}
    if form == "polepair":
        return {"w": paper.P_NOTCH_RAD_S * 1.5 / max(s, 0.3), "z": rng.uniform(0.15, 0.4)}
    if form == "damping":
        m = rng.uniform(0.35, 0.6) if rng.random() < 0.5 else rng.uniform(1.8, 2.5)
        return {"f": 1 - s * rng.uniform(0.0, 0.15), "m": 1 + s * (m - 1)}
    if form == "delaylag":
        return {"d": s * rng.uniform(2e-3, 10e-3), "tau": s * rng.uniform(2e-3, 8e-3)}
    if form == "frac":
        return {"n": s * rng.uniform(1.3, 4.7)}
    raise ValueError(form)


def chain(u: np.ndarray, rate: float, parts: list[tuple[str, dict]]) -> np.ndarray:
    """The noise-free stroke (mm) of command ``u`` (kV) through ``parts`` ((form, parameters)) in the
    physical order: amplifier (clip, slew, RC), delay, input map, hysteresis, trapped charge, P(s) with
    its load, end stop, output play, release lag, stroke creep, sensor curve."""
    p = dict(parts)
    v = np.asarray(u, float).copy()
    if "softclip" in p:
        k = p["softclip"]
        v = np.where(v > k["vk"], k["vk"] + k["r"] * np.tanh((v - k["vk"]) / k["r"]), v)
    if "slewrc" in p:
        v = _slew(v, rate, p["slewrc"]["s0"])
    if "rcamp" in p:
        v = _asym_lag(v, rate, p["rcamp"]["up"], p["rcamp"]["down"])
    if "delaylag" in p:
        v = _lowpass(_frac_delay(v, p["delaylag"]["d"] * rate), rate, p["delaylag"]["tau"])
    if "frac" in p:
        v = _frac_delay(v, p["frac"]["n"])
    if "pwpow" in p:
        k = p["pwpow"]
        vb, p1, p2 = k["vb"], k["p1"], k["p2"]

        def f(x):
            x = np.maximum(x, 0.0)
            return np.where(x < vb, vb * (x / vb) ** p1, vb + (p1 / p2) * vb * ((x / vb) ** p2 - 1))
        neg = np.minimum(v, 0.0)
        v = (f(v) + neg) * k["vref"] / float(f(np.array([k["vref"]]))[0])
    if "deadzone" in p:
        k = p["deadzone"]
        w = 0.03
        a = np.abs(v)
        v = np.sign(v) * w * np.logaddexp(0.0, (a - k["d"]) / w) * k["v90"] / max(k["v90"] - k["d"], 1e-3)
    if "boucwen" in p:
        v = v - _boucwen(v, p["boucwen"]["h"])
    if "trap2" in p:
        k = p["trap2"]
        v = v - k["a1"] * _lowpass(v, rate, k["t1"]) - k["a2"] * _lowpass(v, rate, k["t2"])
    load = ({"polepair": (p["polepair"]["w"], p["polepair"]["z"])} if "polepair" in p else
            {"damping": (p["damping"]["f"], p["damping"]["m"])} if "damping" in p else None)
    z = _linear(v, rate, *_plant(load))
    if "expstop" in p:
        k = p["expstop"]
        z = np.where(z > k["knee"], k["knee"] + k["room"] * (1 - np.exp(-(z - k["knee"]) / k["room"])), z)
    if "backlash" in p:
        z = _play(z, p["backlash"]["r"])
    if "releaselag" in p:
        z = _asym_lag(z, rate, 0.0, p["releaselag"]["tau"])
    if "sqdrive" in p:
        k = p["sqdrive"]
        z = z + k["c"] * _lowpass(np.asarray(u, float) ** 2 / 16.0, rate, k["tau"])
    if "tanhsensor" in p:
        L = p["tanhsensor"]["L"]
        z = L * np.tanh(z / L)
    if "cubic" in p:
        k = p["cubic"]
        z = z + k["c"] * (z - k["zc"]) ** 3
    return z


def _levels(rng: np.random.Generator, rate: float, dur: float) -> np.ndarray:
    """Random levels 0.5-7.5 kV held 0.15-1.2 s, through the amplifier's 2 ms edge."""
    n = int(round(dur * rate))
    u = np.empty(n)
    k = 0
    while k < n:
        m = int(rng.uniform(0.15, 1.2) * rate)
        u[k:k + m] = rng.uniform(0.5, 7.5)
        k += m
    return _lowpass(u, rate, 2e-3)


def _noise(rng: np.random.Generator, n: int, rate: float, sd: float, kind: str) -> np.ndarray:
    """White, AR(1)-coloured (pole at 20 Hz) or wandering (white plus a 0.05 Hz random wander) noise, rms ~sd."""
    w = rng.standard_normal(n)
    if kind == "coloured":
        a = np.exp(-2 * np.pi * 20.0 / rate)
        x = signal.lfilter([1.0], [1, -a], w)
        return sd * x / np.std(x)
    if kind == "wander":
        x = _lowpass(np.cumsum(rng.standard_normal(n)), rate, 2.0)
        x = x - np.linspace(x[0], x[-1], n) * 0.0
        x = (x - x.mean()) / max(np.std(x), 1e-12)
        return sd * (0.9 * w + 0.45 * x)
    return sd * w


def make_case(directory: str, seed: int, i: int) -> dict | None:
    """Case ``i`` of :data:`KINDS`, its draws from ``(seed, i)`` only, written to ``directory``; None when no
    draw met the sizes in 60 tries (every member >= 4 noise rms, the small one 3-5 and 3-10x below the
    largest; comparable members within 6x of each other)."""
    forms, small = KINDS[i]
    rng = np.random.default_rng([seed, 5322, i])
    design = DESIGNS[i % len(DESIGNS)]
    rate = RATES[int(rng.integers(len(RATES)))]
    dur = 20.0 if rate <= 1000.0 else 12.0
    if design == "paper":
        from hasel_bench import othersim as o
        u = o.excitation(rng, rate)[0]
        u = u[: int(min(u.size, 40.0 * rate))]
    elif design == "levels":
        u = _levels(rng, rate, dur)
    else:
        u = _command(design, rng, rate, dur)
    noise_kind = NOISES[int(rng.integers(len(NOISES)))]
    z0 = chain(u, rate, [])
    vis: list[float] = []
    sd = float(rng.uniform(0.003, 0.01))
    parts: list[tuple[str, dict]] = []
    for _ in range(60):
        sizes = [float(rng.uniform(0.6, 1.0)) for _ in forms]
        if small >= 0:
            sizes[small] = float(rng.uniform(0.15, 0.5))
        parts = [(f, draw(f, rng, s, u, z0, rate)) for f, s in zip(forms, sizes)]
        z = chain(u, rate, parts)
        if not np.all(np.isfinite(z)):
            continue
        if not forms:
            break
        raw = [float(np.std(z - chain(u, rate, [q for q in parts if q is not p]))) for p in parts]
        if small >= 0:
            big = max(r for j, r in enumerate(raw) if j != small)
            if not 3.0 <= big / max(raw[small], 1e-12) <= 10.0:
                continue
            sd = raw[small] / float(rng.uniform(3.0, 5.0))
            ok = all(r / sd >= 4.0 for j, r in enumerate(raw) if j != small)
        else:
            if len(raw) > 1 and max(raw) > 6.0 * min(raw):  # a member with no visible part (min 0) too
                continue
            sd = min(raw) / float(rng.uniform(4.0, 10.0))
            ok = True
        if ok and 0.0015 <= sd <= 0.03:
            vis = [r / sd for r in raw]
            break
    else:
        return None
    y = np.round((z + _noise(rng, u.size, rate, sd, noise_kind)) / LSB_MM) * LSB_MM
    num, den = paper.plant_tf()
    tag = "+".join(forms) or "free"
    path = os.path.join(directory, f"m2_{i:02d}_{tag}.npz")
    np.savez_compressed(path, t_s=np.arange(u.size) / rate, voltage_kv=u, stroke_mm=y, num=num, den=den)
    return {"path": path, "kind": f"{tag}:{design}:{rate:g}:{noise_kind}", "labels": sorted({LABEL[f] for f in forms}),
            "visible": [round(v, 1) for v in vis], "small": LABEL[forms[small]] if small >= 0 else None,
            "sd_mm": sd, "truth": [f"{f}:{ {a: round(float(b), 5) for a, b in k.items()} }" for f, k in parts]}


def make(directory: str, seed: int = 21) -> list[dict]:
    """Every case of :data:`KINDS` with a draw that met the sizes, written to ``directory``; their labels."""
    return [c for c in (make_case(directory, seed, i) for i in range(len(KINDS))) if c is not None]


# ---------------------------------------------------------------------------------------------- scoring
def where_lost(name: str, rounds: list[dict], names: list[str]) -> str:
    """Where the true effect ``name`` was lost, read from a verdict's ``rounds``: ``backward`` (named, then
    dropped by the backward check), ``raised`` (a raised-resonance load taken out), ``replaced`` (accepted,
    then gone otherwise: a swap or the map-side check), ``rejected:<gates>`` (the best of a round that
    failed acceptance; the failed gates), ``outscored`` (a candidate, never a round's best while a round
    was accepted), ``not_proposed`` (never a candidate)."""
    def has(r):
        return name in str(r.get("best", "")).split(" + ")
    for r in rounds:
        if r.get("backward_check") and r.get("best") == name and not r.get("accepted"):
            return "raised" if r.get("raised_resonance") else "backward"
    if any(r.get("accepted") and has(r) for r in rounds):
        return "replaced"
    for r in rounds:
        if not r.get("accepted") and has(r) and not r.get("backward_check"):
            return "rejected:" + ",".join(r.get("failed", [])) if r.get("failed") else "rejected"
    if any(name in c["name"].split(" + ") for r in rounds for c in r.get("candidates", [])):
        return "outscored"
    return "not_proposed"


_ORACLE: dict = {}


def _install_oracle() -> None:
    """Wrap the forward selection: after it, the true families (``_ORACLE["labels"]``) are fitted in every order,
    alternated and refined jointly, and the best set by training error is scored beside the chosen one
    (validation NRMSE of both; per true member, the share of the others' refitted residual it removes and
    its held-out block score / coloured z, as the backward check would judge it). Read-only: the selection
    goes on unchanged. For the loss table only (is the true set within the families' reach?)."""
    from itertools import permutations

    from hasel.diagnose import core
    from hasel.diagnose.augment import fit_family, joint_refine
    from hasel.diagnose.checks import _refit_rest
    from hasel.diagnose.context import _fixed, _without

    orig = core._forward_selection

    def wrapped(ctx, st):
        orig(ctx, st)
        labels = _ORACLE.get("labels") or []
        if len(labels) < 2:
            return
        fixed = {k: v for k, v in st.current.items() if _fixed(k, v)}
        best = None
        for order in permutations(labels):
            e = dict(fixed)
            for n in order:
                f = fit_family(ctx.pipe, e, n)
                if f is not None:
                    e[n] = f
            e = core._alternate(ctx, e, [n for n in order if n in e])
            e = joint_refine(ctx.pipe, e, max_nfev=ctx.opts.joint_refine_nfev)
            sc = ctx.scores(e)
            if best is None or sc[0] < best[1][0]:
                best = (e, sc)
        e, (m_tr, m_ho, e_ho) = best
        members = {}
        for n in labels:
            if n not in e:
                members[n] = None
                continue
            _, _, m_r, e_r = _refit_rest(ctx, _without(e, n))
            t_blk, z_col = ctx.held_out(e_r, e_ho)
            members[n] = {"gain": round((m_r - m_ho) / m_r, 3) if m_r > 0 else 0.0, "t": round(t_blk, 1),
                          "z": round(z_col, 1)}
        _ORACLE["result"] = {"truth_nrmse": ctx.to_nrmse(m_ho), "chosen_nrmse": ctx.to_nrmse(st.mse_ho),
                             "floor": ctx.floor_va, "members": members}

    core._forward_selection = wrapped


def run(cases: list[dict], out: str, say=print, oracle: bool = False) -> list[dict]:
    """Diagnose each case (nominal model P(s), one process); one row per case with where each lost member was
    lost; the progress lines in ``out/trace_NN.txt``; with ``oracle`` the true set's fit beside the chosen one
    (:func:`_install_oracle`)."""
    from hasel.diagnose.core import DiagnoseOptions, diagnose
    from hasel.diagnose.pool import set_jobs

    set_jobs(1)
    if oracle:
        _install_oracle()
    rows = []
    for c in cases:
        _ORACLE.clear()
        _ORACLE["labels"] = c["labels"]
        d = np.load(c["path"])
        lines: list[str] = []
        opts = DiagnoseOptions(progress=lines.append)
        t0 = time.perf_counter()
        try:
            v = diagnose(d["t_s"], d["voltage_kv"], d["stroke_mm"],
                         model={"num": d["num"].tolist(), "den": d["den"].tolist()}, units=("kV", "mm"), options=opts)
            rounds = v.rounds
            for r in rounds:  # the gates the diagnosis recorded as failed (hasel.diagnose.core.failed_gates), by key
                r["failed"] = [g["gate"] for g in r.get("failed", [])]
            r = {"names": v.names, "nominal": v.heldout["nrmse_nominal"], "augmented": v.heldout["nrmse_augmented"],
                 "floor": v.noise_floor_nrmse,
                 "rounds": [{k: x.get(k) for k in ("round", "best", "gain", "gap_share", "nominal_gap_share",
                                                   "t_block", "z_coloured", "delta_bic", "over_floor", "accepted",
                                                   "backward_check", "raised_resonance", "failed")} for x in rounds]}
            r["lost"] = {n: where_lost(n, rounds, v.names) for n in c["labels"] if n not in v.names}
        except Exception as err:  # noqa: BLE001 - a crash is a result
            r = {"names": [], "error": f"{type(err).__name__}: {err}", "lost": {n: "error" for n in c["labels"]}}
        r.update(kind=c["kind"], labels=c["labels"], small=c.get("small"), seconds=time.perf_counter() - t0)
        if "result" in _ORACLE:
            r["oracle"] = _ORACLE["result"]
        with open(os.path.join(out, f"trace_{os.path.basename(c['path'])[3:5]}.txt"), "w") as fh:
            fh.write("\n".join(lines) + "\n")
        rows.append(r)
        say(f"{os.path.basename(c['path']):40s} truth {','.join(c['labels']) or 'none':50s} named "
            f"{','.join(r['names']) or 'none':50s} {r['seconds']:.1f} s lost {r['lost']} {r.get('error', '')}"
            + (f" oracle {r['oracle']}" if "oracle" in r else ""))
    return rows


def summary(rows: list[dict]) -> dict:
    """Singles top-1, pairs and triples recall/precision, pairs+triples, false alarms, small members named,
    median seconds, and the count of lost members per stage."""
    def rp(sub):
        tp = sum(len(set(r["labels"]) & set(r["names"])) for r in sub)
        return (tp, sum(len(r["labels"]) for r in sub), sum(len(r["names"]) for r in sub))
    s = {}
    for k, key in ((2, "pairs"), (3, "triples")):
        tp, nl, nn = rp([r for r in rows if len(r["labels"]) == k])
        s[key] = {"recall": f"{tp}/{nl} = {tp / max(nl, 1):.3f}", "precision": f"{tp}/{nn} = {tp / max(nn, 1):.3f}"}
    tp, nl, nn = rp([r for r in rows if len(r["labels"]) > 1])
    s["multi"] = {"recall": f"{tp}/{nl} = {tp / max(nl, 1):.3f}", "precision": f"{tp}/{nn} = {tp / max(nn, 1):.3f}"}
    single = [r for r in rows if len(r["labels"]) == 1]
    s["singles_top1"] = f"{sum(bool(r['names']) and r['names'][0] == r['labels'][0] for r in single)}/{len(single)}"
    free = [r for r in rows if not r["labels"]]
    s["false_alarms"] = f"{sum(bool(r['names']) for r in free)}/{len(free)}"
    sm = [r for r in rows if r.get("small") and len(r["labels"]) > 1]
    s["small_named"] = f"{sum(r['small'] in r['names'] for r in sm)}/{len(sm)}"
    s["seconds_median"] = float(np.median([r["seconds"] for r in rows]))
    stages: dict[str, int] = {}
    for r in rows:
        if len(r["labels"]) > 1:
            for w in r["lost"].values():
                key = w.split(":")[0]
                stages[key] = stages.get(key, 0) + 1
    s["lost_at"] = stages
    return s


def main(argv: list[str] | None = None) -> int:
    """``python bench/tune_diag/multi2.py --out DIR [--seed S] [--only SUBSTR,...] [--list]``."""
    p = generator_parser(__doc__, 21)
    p.add_argument("--oracle", action="store_true", help="also fit the true families (slower; the loss table)")
    a, cases = generator_cases(p, argv, make)
    if not cases:
        return 0
    rows = run(cases, a.out, lambda m: (print(m), sys.stdout.flush()), oracle=a.oracle)
    s = summary(rows)
    print(json.dumps(s, indent=1))
    with open(os.path.join(a.out, "results.json"), "w") as fh:
        json.dump({"summary": s, "rows": rows, "cases": cases}, fh, indent=1, default=str)
    return 0


if __name__ == "__main__":
    sys.exit(main())
