"""Generate the verify2 corpus: blind identification and diagnosis cases for `hasel`.

    python gen.py --out DIR [--seed N]

Writes DIR/cases/<id>/ (train.{csv|mat|mcap}, heldout.* and model.json for diagnosis
cases) and DIR/labels/<id>.json (the truth, read only by score.py). Independent of the
hasel package: its own simulator (plant.py), its own effect forms, its own protocols.
Units: s, kV, mm, Hz.
"""
from __future__ import annotations

import argparse
import copy
import json
import math
import os
import sys

import numpy as np
from scipy import io as sio

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import plant  # noqa: E402

NAMES = ["static_nonlinearity", "asymmetric_dynamics", "charge_drift", "saturation",
         "time_delay", "sensor_nonlinearity", "load_mass", "hysteresis"]

FORMS = {
    ("static_nonlinearity", "a"): "input map blended toward the electrostatic square law: "
                                  "v_eff = (1-a) v + a v|v|/v_ref",
    ("static_nonlinearity", "b"): "input power law (partial zipping): v_eff = v_ref sign(v)|v/v_ref|^p",
    ("static_nonlinearity", "c"): "input knee (zipping onset): slope g below v_knee, 1 above, smoothed",
    ("asymmetric_dynamics", "a"): "output direction-dependent first-order lag: tau_up (activation) "
                                  "< tau_down (relaxation)",
    ("asymmetric_dynamics", "b"): "input asymmetric RC drive: the amplifier charges the actuator "
                                  "fast (tau_up) and bleeds it slowly (tau_down)",
    ("asymmetric_dynamics", "c"): "output falling slew-rate limit (fluid back-flow), free rise",
    ("charge_drift", "a"): "stroke creep with the leaky integral of the voltage: "
                           "z += kappa q, q' = v - q/tau",
    ("charge_drift", "b"): "charge screening: v_eff = v - q, q' = (rho v - q)/tau",
    ("charge_drift", "c"): "field-driven charge injection lowers the gain: v_eff = v (1 - q), "
                           "q' = beta v^2 - q/tau",
    ("saturation", "a"): "hard end stop: stroke clipped at z_max",
    ("saturation", "b"): "amplifier rail: applied voltage clipped at v_max (logged command unclipped)",
    ("saturation", "c"): "two-sided hard stroke clip [z_min, z_max]",
    ("time_delay", "a"): "transport delay on the input (HV amplifier latency)",
    ("time_delay", "b"): "delay on the output (sensor read-out latency)",
    ("time_delay", "c"): "input delay of a non-integer number of log samples",
    ("sensor_nonlinearity", "a"): "quadratic sensor curve: y = z + a (z-z_c)^2 / z_span",
    ("sensor_nonlinearity", "b"): "cubic S-curve: y = z + b ((z-z_c)/z_span)^3 z_span",
    ("sensor_nonlinearity", "c"): "periodic calibration ripple: y = z + e sin(2 pi (z-z_c)/period)",
    ("load_mass", "a"): "added mass mu, same damper: both resonant pairs "
                        "s^2 + 230/(1+mu) s + w^2/(1+mu), static gain kept",
    ("load_mass", "b"): "added mass mu, same damping ratio: s^2 + 230/sqrt(1+mu) s + w^2/(1+mu)",
    ("load_mass", "c"): "added mass on one resonant pair and on the anti-resonance zeros",
    ("hysteresis", "a"): "play (backlash) operator on the input, half-width r",
    ("hysteresis", "b"): "Prandtl-Ishlinskii: w0 v + sum of play operators of radii r_i",
    ("hysteresis", "c"): "Bouc-Wen (n=1) on the input: v_eff = v - c h",
}


# ------------------------------------------------------------------ input designs

class Design:
    """A continuous-time input v(t) (kV) made of consecutive segments."""

    def __init__(self, name):
        self.name = name
        self.segs = []      # (t0, dur, fn(tau))
        self.t = 0.0
        self.info = {"design": name}

    def add(self, dur, fn):
        """Append a segment of dur seconds whose value is fn(tau), tau from 0."""
        self.segs.append((self.t, float(dur), fn))
        self.t += float(dur)

    def const(self, dur, v):
        """Append a constant segment (kV)."""
        self.add(dur, lambda tau, v=v: np.full(np.shape(tau), float(v)))

    def __call__(self, t):
        """v at the times t (s); after the end, the last segment's final value."""
        t = np.asarray(t, float)
        out = np.empty(t.shape)
        starts = np.array([s[0] for s in self.segs])
        idx = np.clip(np.searchsorted(starts, t, side="right") - 1, 0, len(self.segs) - 1)
        for i, (t0, dur, fn) in enumerate(self.segs):
            m = idx == i
            if np.any(m):
                out[m] = fn(np.minimum(t[m] - t0, dur))
        return out


def chirp_design(kind, offsets, reps, t_tot, amp=1.0, settle=0.5, precond=False):
    """Chirps on DC offsets. kind: 'paper' (phase 2 pi k tau^2, k=(20-0.001)/t_tot, so the
    sweep reaches ~40 Hz), 'linear' (0.05 -> 20 Hz), 'log' (0.1 -> 25 Hz)."""
    d = Design({"paper": "paper_chirp", "linear": "linear_chirp", "log": "log_chirp"}[kind]
               + ("_repeated" if reps > 1 else ""))
    for vs in offsets:
        if precond:
            d.const(1.0, -1.0)
        d.const(settle, vs)
        for _ in range(reps):
            if kind == "paper":
                k = (20.0 - 0.001) / t_tot
                fn = lambda tau, vs=vs, k=k: vs + amp * np.sin(2 * np.pi * k * tau ** 2)
            elif kind == "linear":
                f0, f1 = 0.05, 20.0
                fn = lambda tau, vs=vs: vs + amp * np.sin(
                    2 * np.pi * (f0 * tau + (f1 - f0) / (2 * t_tot) * tau ** 2))
            else:
                f0, f1 = 0.1, 25.0
                r = f1 / f0
                fn = lambda tau, vs=vs: vs + amp * np.sin(
                    2 * np.pi * f0 * t_tot / math.log(r) * (r ** (tau / t_tot) - 1))
            d.add(t_tot, fn)
    d.info.update(offsets_kv=list(offsets), reps=reps, t_chirp_s=t_tot, amp_kv=amp,
                  precondition=precond, settle_s=settle)
    return d


def multisine_design(rng, offsets, periods, tp=10.0, rms=0.6, settle=0.5):
    """Schroeder-phased multisine, lines log-spaced on the 1/tp grid over 0.1-20 Hz."""
    d = Design("multisine")
    ks = np.unique(np.round(np.logspace(np.log10(0.1 * tp), np.log10(20 * tp), 40)).astype(int))
    nk = len(ks)
    ph = -np.pi * np.arange(nk) * (np.arange(nk) + 1) / nk
    a = rms * math.sqrt(2.0 / nk)
    for vs in offsets:
        d.const(settle, vs)
        d.add(tp * periods, lambda tau, vs=vs: vs + a * np.sum(
            np.sin(2 * np.pi * np.outer(tau, ks) / tp + ph), axis=1)
            if np.ndim(tau) else vs)
    d.info.update(offsets_kv=list(offsets), periods=periods, period_s=tp, lines=int(nk))
    return d


def prbs_design(rng, offsets, dur_each, tc=0.02, amp=1.0, settle=0.5):
    """Random binary levels offset +- amp switched on a clock tc (s)."""
    d = Design("prbs")
    for vs in offsets:
        d.const(settle, vs)
        n = int(dur_each / tc)
        bits = rng.integers(0, 2, n) * 2 - 1
        d.add(n * tc, lambda tau, vs=vs, bits=bits: vs + amp * bits[
            np.minimum((np.asarray(tau) / tc).astype(int), n - 1)])
    d.info.update(offsets_kv=list(offsets), clock_s=tc, amp_kv=amp)
    return d


def random_steps_design(rng, dur, lo=1.0, hi=8.0, dmin=0.1, dmax=1.5):
    """Uniform random levels in [lo, hi] kV held for uniform random durations."""
    d = Design("random_steps")
    while d.t < dur:
        d.const(rng.uniform(dmin, dmax), rng.uniform(lo, hi))
    d.info.update(levels_kv=[lo, hi], hold_s=[dmin, dmax])
    return d


def voltage_steps_design(levels, hold, repeats=1):
    """A staircase of voltage steps (kV), each held hold seconds."""
    d = Design("voltage_steps")
    for _ in range(repeats):
        for v in levels:
            d.const(hold, v)
    d.info.update(levels_kv=list(levels), hold_s=hold, repeats=repeats)
    return d


# ------------------------------------------------------------------ noise

def make_noise(rng, n, fs, kind, sigma, wander):
    """Sensor noise (mm) at the log rate: 'white' or 'coloured' (first-order low-pass of
    white noise, corner 2-20 Hz, scaled to sigma rms); plus a slow offset wander of rms
    `wander` (sum of 3 sinusoids, periods 15-90 s, random phases) if wander > 0."""
    if kind == "white":
        e = rng.normal(0, sigma, n)
        fc = None
    else:
        fc = float(rng.uniform(2, 20))
        a = math.exp(-2 * np.pi * fc / fs)
        from scipy import signal
        w = rng.normal(0, 1, n + 2000)
        e = signal.lfilter([1 - a], [1, -a], w)[2000:]
        e *= sigma / e.std()
    t = np.arange(n) / fs
    if wander > 0:
        per = rng.uniform(15, 90, 3)
        ph = rng.uniform(0, 2 * np.pi, 3)
        wv = np.sum(np.sin(2 * np.pi * np.outer(t, 1 / per) + ph), axis=1)
        wv -= wv[0]
        e = e + wv * wander / max(wv.std(), 1e-12)
    return e, fc


# ------------------------------------------------------------------ effects

def default_effect(name, form, rng, ctx):
    """An effect dict of strength 1 with parameters from physics and the case's context
    (ctx: nominal train stroke/voltage percentiles, rate)."""
    p = {}
    zlo, zmed, zhi = ctx["z_p5"], ctx["z_p50"], ctx["z_p95"]
    zspan = max(zhi - zlo, 0.5)
    if name == "static_nonlinearity":
        p = {"a": {"a": 0.25, "v_ref_kv": 5.0}, "b": {"p": 1.25, "v_ref_kv": 5.0},
             "c": {"v_knee_kv": 3.5, "g_below": 0.6, "width_kv": 0.3}}[form]
    elif name == "hysteresis":
        p = {"a": {"r_kv": 0.25},
             "b": {"radii_kv": [0.1, 0.3, 0.6], "weights": [0.15, 0.15, 0.15], "w0": 0.55},
             "c": {"A": 1.0, "beta": 2.0, "gamma": 0.5, "c": 0.6}}[form]
    elif name == "saturation":
        p = {"a": {"q": 88.0}, "b": {"q": 90.0}, "c": {"q": 94.0}}[form]
    elif name == "asymmetric_dynamics":
        p = {"a": {"tau_up_s": 0.002, "tau_down_s": 0.03},
             "b": {"tau_up_s": 0.001, "tau_down_s": 0.025},
             "c": {"rate_down_mm_s": 25.0}}[form]
    elif name == "time_delay":
        p = {"a": {"delay_s": 0.004}, "b": {"delay_s": 0.006},
             "c": {"delay_s": 2.6 / ctx["fs"]}}[form]
    elif name == "charge_drift":
        p = {"a": {"kappa": 8e-4, "tau_s": 300.0}, "b": {"rho": 0.04, "tau_s": 40.0},
             "c": {"beta": 1.85e-5, "tau_s": 60.0}}[form]
    elif name == "sensor_nonlinearity":
        base = {"z_c_mm": zmed, "z_span_mm": zspan}
        p = dict(base, **{"a": {"a": 0.08}, "b": {"b": 0.3},
                          "c": {"e_mm": 0.06, "period_mm": 4.0}}[form])
    elif name == "load_mass":
        p = {"a": {"mu": 0.45}, "b": {"mu": 0.6}, "c": {"mu": 0.5}}[form]
    return {"name": name, "form": form, "form_desc": FORMS[(name, form)], "params": p,
            "strength": 1.0}


def resolve(e, s, ctx):
    """The effect at strength s (a copy), with context-derived levels made concrete."""
    e = copy.deepcopy(e)
    p = e["params"]
    n, f = e["name"], e["form"]
    e["strength"] = float(s)
    if n == "static_nonlinearity":
        if f == "a":
            p["a"] *= s
        elif f == "b":
            p["p"] = 1 + (p["p"] - 1) * s
        else:
            p["g_below"] = 1 - (1 - p["g_below"]) * s
    elif n == "hysteresis":
        if f == "a":
            p["r_kv"] *= s
        elif f == "b":
            p["weights"] = [w * s for w in p["weights"]]
            p["w0"] = 1.0 - sum(p["weights"])
        else:
            p["c"] *= s
    elif n == "saturation":
        q = 100 - (100 - p["q"]) * s
        if f == "a":
            p["z_max_mm"] = float(np.percentile(ctx["z_nom"], q))
        elif f == "b":
            p["v_max_kv"] = float(np.percentile(ctx["u_log"], q))
        else:
            p["z_max_mm"] = float(np.percentile(ctx["z_nom"], q))
            p["z_min_mm"] = float(np.percentile(ctx["z_nom"], 100 - q))
        p["q"] = q
    elif n == "asymmetric_dynamics":
        if f in ("a", "b"):
            p["tau_down_s"] = p["tau_up_s"] + (p["tau_down_s"] - p["tau_up_s"]) * s
        else:
            p["rate_down_mm_s"] /= max(s, 1e-9)
    elif n == "time_delay":
        p["delay_s"] *= s
    elif n == "charge_drift":
        key = {"a": "kappa", "b": "rho", "c": "beta"}[f]
        p[key] *= s
    elif n == "sensor_nonlinearity":
        key = {"a": "a", "b": "b", "c": "e_mm"}[f]
        p[key] *= s
    elif n == "load_mass":
        p["mu"] *= s
    return e


# ------------------------------------------------------------------ simulation wrappers

def fine_factor(fs):
    """Fine-grid steps per log sample (timing offsets and delays are resolved to 1/M)."""
    return 8 if fs <= 1000 else (4 if fs <= 5000 else 2)


def sim_open(effects, design, fs, conv, skew):
    """Noise-free open-loop log: (t, u_log, y_log, actual skew in samples)."""
    n = int(round(design.t * fs))
    t = np.arange(n) / fs
    u = design(t)
    y, sk = plant.simulate_open(effects, t, design, u, conv, skew, fine_factor(fs))
    return t, u, y, sk


def sim_closed(effects, fs, refs, holds, noise, ctrl_hz=200.0, u_init=None):
    """Closed loop with this corpus's own controller: a dual-gain PI with feedforward
    r/P(0), running at ctrl_hz on the measured (noisy) stroke of the previous log sample,
    command clamped to [0, 9] kV and held (ZOH) until the next controller tick.
    refs: stroke references (mm) each held holds[i] seconds. Returns (t, u_applied_log,
    y_meas (with noise), y_noise_free)."""
    nsub = int(round(fs / ctrl_hz))
    g0 = plant.dc_gain(*plant.paper_tf())
    dur = float(sum(holds))
    nper = int(round(dur * ctrl_hz))
    n = nper * nsub
    h = 1.0 / fs
    r_t = np.repeat(refs, [int(round(hh * ctrl_hz)) for hh in holds])[:nper]
    if len(r_t) < nper:
        r_t = np.concatenate([r_t, np.full(nper - len(r_t), refs[-1])])
    u0 = r_t[0] / g0 if u_init is None else u_init
    pl = plant.Plant(effects, h, u0)
    u_log = np.empty(n)
    y_nf = np.empty(n)
    integ = 0.0
    y_last = g0 * u0
    kp_up, ki_up, kp_dn, ki_dn = 0.35, 14.0, 0.45, 18.0
    Ts = 1.0 / ctrl_hz
    for j in range(nper):
        r = r_t[j]
        e = r - y_last
        kp, ki = (kp_up, ki_up) if e >= 0 else (kp_dn, ki_dn)
        integ_new = integ + ki * Ts * e
        v = r / g0 + kp * e + integ_new
        if 0.0 <= v <= 9.0:
            integ = integ_new
        v = min(max(v, 0.0), 9.0)
        sl = slice(j * nsub, (j + 1) * nsub)
        u_log[sl] = v
        y_nf[sl] = pl.run(np.full(nsub, v))
        y_last = y_nf[(j + 1) * nsub - 1] + noise[(j + 1) * nsub - 1]
    t = np.arange(n) * h
    return t, u_log, y_nf + noise[:n], y_nf


# ------------------------------------------------------------------ writers

def write_log(path_noext, fmt, t, u, y, topics=("/rig/voltage_kv", "/rig/stroke_mm")):
    """Write t_s, voltage_kv, stroke_mm as CSV, MAT (column vectors) or MCAP (ROS 2 CDR
    std_msgs/msg/Float64 on two topics, log time = sample time). Returns the file name."""
    if fmt == "csv":
        fn = path_noext + ".csv"
        np.savetxt(fn, np.column_stack([t, u, y]), delimiter=",",
                   header="t_s,voltage_kv,stroke_mm", comments="", fmt="%.7f")
    elif fmt == "mat":
        fn = path_noext + ".mat"
        sio.savemat(fn, {"t_s": t[:, None], "voltage_kv": u[:, None], "stroke_mm": y[:, None]})
    elif fmt == "mcap":
        from mcap_ros2.writer import Writer
        fn = path_noext + ".mcap"
        t0 = 1_764_000_000_000_000_000
        with open(fn, "wb") as fh:
            w = Writer(fh)
            sch = w.register_msgdef("std_msgs/msg/Float64", "float64 data")
            for ti, ui, yi in zip(t, u, y):
                ns = t0 + int(round(ti * 1e9))
                w.write_message(topics[0], sch, {"data": float(ui)}, log_time=ns, publish_time=ns)
                w.write_message(topics[1], sch, {"data": float(yi)}, log_time=ns, publish_time=ns)
            w.finish()
    else:
        raise ValueError(fmt)
    return os.path.basename(fn)


def io_args(fmt):
    """CLI arguments that say where the input and output are."""
    if fmt == "mcap":
        return ["--input", "/rig/voltage_kv.data", "--output", "/rig/stroke_mm.data"]
    return []


def rms(x):
    """Root mean square."""
    return float(np.sqrt(np.mean(np.square(x))))


# ------------------------------------------------------------------ case builders

def make_design(rng, name, budget_s):
    """A design of about budget_s seconds (diagnosis logs)."""
    if name == "paper_chirp":
        nof = max(1, int(budget_s // 20.5))
        offs = sorted(rng.choice([2, 3, 4, 5, 6, 7], nof, replace=False).tolist())
        return chirp_design("paper", offs, 1, 20.0, precond=bool(rng.integers(0, 2)))
    if name == "linear_chirp":
        return chirp_design("linear", [float(rng.choice([3, 4, 5]))], 1, budget_s - 0.5)
    if name == "log_chirp":
        nof = 2 if budget_s >= 30 else 1
        offs = sorted(rng.choice([3, 4, 5, 6], nof, replace=False).tolist())
        return chirp_design("log", offs, 1, budget_s / nof - 0.5)
    if name == "multisine":
        nof = 2 if budget_s >= 40 else 1
        offs = sorted(rng.choice([3, 4, 5, 6], nof, replace=False).tolist())
        return multisine_design(rng, offs, max(1, int(budget_s / nof // 10)))
    if name == "prbs":
        offs = sorted(rng.choice([2.5, 4.0, 5.5], 2, replace=False).tolist())
        return prbs_design(rng, offs, budget_s / 2 - 0.5, tc=float(rng.choice([0.01, 0.02, 0.04])))
    if name == "random_steps":
        return random_steps_design(rng, budget_s)
    if name == "voltage_steps":
        lv = [1, 3, 5, 7, 5, 3, 1, 2, 4, 6, 4, 2]
        hold = max(0.5, min(2.0, budget_s / len(lv)))
        return voltage_steps_design(lv, hold, max(1, int(round(budget_s / (hold * len(lv))))))
    raise ValueError(name)


HELD_DESIGNS = ["random_steps", "multisine", "log_chirp", "prbs", "voltage_steps"]
TRAIN_DESIGNS = ["paper_chirp", "linear_chirp", "log_chirp", "multisine", "prbs",
                 "random_steps"]


def cl_refs(rng, dur):
    """Closed-loop step references (mm): the paper's 2-4-6-4-2 then random levels in 1.5-7."""
    refs = [2.0, 4.0, 6.0, 4.0, 2.0]
    holds = [1.5] * 5
    while sum(holds) < dur:
        refs.append(float(rng.uniform(1.5, 7.0)))
        holds.append(float(rng.uniform(0.4, 2.0)))
    return refs, holds


class Builder:
    """Holds the output directory and writes cases and labels."""

    def __init__(self, out, seed):
        self.out = out
        self.rng = np.random.default_rng(seed)
        os.makedirs(os.path.join(out, "cases"), exist_ok=True)
        os.makedirs(os.path.join(out, "labels"), exist_ok=True)
        self.n = 0

    # -- diagnosis ---------------------------------------------------------------
    def diag(self, cid, category, effect_specs, fs, conv="zoh", skew=0.0, fmt="csv",
             noise_kind="white", sigma=0.01, wander=0.0, train="multisine", held="random_steps",
             train_s=40.0, held_s=20.0, closed=False, target_ratio=None, min_ratio=5.0):
        """One diagnosis case. effect_specs: list of (name, form). target_ratio: near-floor
        (effect rms / noise rms in [0.2, 1]); otherwise each effect alone is scaled up until
        its rms is at least min_ratio times the noise rms."""
        rng = self.rng
        d = os.path.join(self.out, "cases", cid)
        os.makedirs(d, exist_ok=True)
        num, den = plant.paper_tf()
        g0 = plant.dc_gain(num, den)
        if conv == "skew" and skew == 0.0:
            skew = 0.35
        # designs and noise
        if closed:
            refs, holds = cl_refs(rng, train_s)
            refs_h, holds_h = cl_refs(rng, held_s)
            n_tr = int(round(sum(holds) * 200)) * int(round(fs / 200))
            n_he = int(round(sum(holds_h) * 200)) * int(round(fs / 200))
            des_tr = des_he = None
        else:
            des_tr = make_design(rng, train, train_s)
            des_he = make_design(rng, held, held_s)
            n_tr = int(round(des_tr.t * fs))
            n_he = int(round(des_he.t * fs))
        e_tr, fc = make_noise(rng, n_tr, fs, noise_kind, sigma, wander)
        e_he, _ = make_noise(rng, n_he, fs, noise_kind, sigma, wander)
        noise_rms = rms(e_tr - e_tr.mean())

        def run(effs, which):
            if closed:
                rf, hd, ee = (refs, holds, e_tr) if which == "train" else (refs_h, holds_h, e_he)
                t, u, y, ynf = sim_closed(effs, fs, rf, hd, ee)
                # gap against the nominal model driven by the logged applied voltage
                ynom, _ = plant.simulate_open([], t, None, u, "zoh", 0.0, 1)
                return t, u, ynf, ynom, 0.0
            des = des_tr if which == "train" else des_he
            t, u, y, sk = sim_open(effs, des, fs, conv, skew)
            if effs:
                _, _, ynom, _ = sim_open([], des, fs, conv, skew)
            else:
                ynom = y
            return t, u, y, ynom, sk

        # context for effect parameters from the nominal train log
        t0_, u0_, y0_, _, _ = run([], "train")
        ctx = {"z_p5": float(np.percentile(y0_, 5)), "z_p50": float(np.percentile(y0_, 50)),
               "z_p95": float(np.percentile(y0_, 95)), "fs": fs, "z_nom": y0_, "u_log": u0_}
        effs = []
        alone = []
        for name, form in effect_specs:
            base = default_effect(name, form, rng, ctx)

            def ratio_at(s, base=base):
                e = resolve(base, s, ctx)
                _, _, y, ynom, _ = run([e], "train")
                return rms(y - ynom) / noise_rms

            s = 1.0
            r = ratio_at(s)
            if target_ratio is not None:
                lo, hi = 0.0, 1.0
                while r < target_ratio and hi < 64:
                    hi *= 2
                    r = ratio_at(hi)
                for _ in range(14):
                    mid = 0.5 * (lo + hi)
                    rm = ratio_at(mid)
                    if rm > target_ratio:
                        hi = mid
                    else:
                        lo = mid
                s = hi
                r = ratio_at(s)
            else:
                while r < min_ratio and s < 16:
                    s *= 1.5
                    r = ratio_at(s)
            e = resolve(base, s, ctx)
            e["effect_rms_over_noise_alone"] = r
            effs.append(e)
        # final logs
        if closed:
            t, u, ynf, ynom, sk = run(effs, "train")
            y = ynf + e_tr
            th, uh, ynfh, ynomh, _ = run(effs, "heldout")
            yh = ynfh + e_he
        else:
            t, u, ynf, ynom, sk = run(effs, "train")
            y = ynf + e_tr
            th, uh, ynfh, ynomh, _ = run(effs, "heldout")
            yh = ynfh + e_he
        eff_rms = rms(ynf - ynom)
        f_tr = write_log(os.path.join(d, "train"), fmt, t, u, y)
        f_he = write_log(os.path.join(d, "heldout"), fmt, th, uh, yh)
        with open(os.path.join(d, "model.json"), "w") as fh:
            json.dump({"num": num.tolist(), "den": den.tolist()}, fh)
        for e in effs:
            e["slot"] = plant.effect_slot(e)
            e["params"] = {k: v for k, v in e["params"].items()}
        args = [f_tr, "--heldout", f_he, "--model", "model.json"] + io_args(fmt)
        label = {
            "id": cid, "kind": "diagnose", "category": category, "closed_loop": closed,
            "effects": [{k: v for k, v in e.items()} for e in effs],
            "truth_names": sorted({e["name"] for e in effs}),
            "design_train": ({"design": "closed_loop_steps", "refs_mm": refs, "holds_s": holds,
                              "controller": "dual-gain PI + feedforward, 200 Hz"}
                             if closed else des_tr.info),
            "design_heldout": ({"design": "closed_loop_steps"} if closed else des_he.info),
            "rate_hz": fs, "train_s": len(t) / fs, "heldout_s": len(th) / fs,
            "noise": {"kind": noise_kind, "sigma_mm": sigma, "corner_hz": fc,
                      "wander_rms_mm": wander, "rms_mm": noise_rms},
            "convention": "zoh" if closed else conv,
            "timing_offset_samples": sk,
            "effect_rms_mm": eff_rms, "effect_rms_over_noise": eff_rms / noise_rms,
            "format": fmt, "files": {"train": f_tr, "heldout": f_he, "model": "model.json"},
            "args": args,
        }
        with open(os.path.join(self.out, "labels", cid + ".json"), "w") as fh:
            json.dump(label, fh, indent=1, default=float)
        self.n += 1
        print(f"{cid}: {category} {[e['name'] for e in effs]} fs={fs} conv={label['convention']} "
              f"ratio={label['effect_rms_over_noise']:.2f} n={len(t)}+{len(th)}", flush=True)

    # -- identification ---------------------------------------------------------
    def ident(self, cid, design_name, fs, fmt="csv", noise_kind="white", sigma=0.01,
              conv="zoh", extra_args=()):
        """One identification case (effect-free; the truth is P(s))."""
        rng = self.rng
        d = os.path.join(self.out, "cases", cid)
        os.makedirs(d, exist_ok=True)
        num, den = plant.paper_tf()
        if design_name == "closed_loop_steps":
            refs, holds = cl_refs(rng, 40.0)
            n = int(round(sum(holds) * 200)) * int(round(fs / 200))
            e, fc = make_noise(rng, n, fs, noise_kind, sigma, 0.0)
            t, u, y, _ = sim_closed([], fs, refs, holds, e)
            info = {"design": "closed_loop_steps", "refs_mm": refs, "holds_s": holds}
        else:
            des = {
                "paper_chirp": lambda: chirp_design("paper", [2, 3, 4, 5, 6, 7], 1, 20.0),
                "paper_chirp_repeated": lambda: chirp_design("paper", [2, 4, 6], 3, 20.0,
                                                             precond=True),
                "linear_chirp": lambda: chirp_design("linear", [3, 5], 1, 30.0),
                "log_chirp": lambda: chirp_design("log", [2, 4, 6], 1, 25.0),
                "multisine": lambda: multisine_design(rng, [3, 6], 3),
                "prbs": lambda: prbs_design(rng, [2.5, 4.5, 6.5], 20.0, tc=0.02),
                "random_steps": lambda: random_steps_design(rng, 60.0),
                "voltage_steps": lambda: voltage_steps_design(
                    [1, 3, 5, 7, 5, 3, 1, 2, 4, 6, 4, 2], 3.0, 1),
            }[design_name]()
            t, u, ynf, _ = sim_open([], des, fs, conv, 0.0)
            e, fc = make_noise(rng, len(t), fs, noise_kind, sigma, 0.0)
            y = ynf + e
            info = des.info
        f_tr = write_log(os.path.join(d, "train"), fmt, t, u, y)
        label = {"id": cid, "kind": "ident", "category": "ident", "design": info,
                 "design_name": design_name, "rate_hz": fs, "duration_s": len(t) / fs,
                 "noise": {"kind": noise_kind, "sigma_mm": sigma, "corner_hz": fc},
                 "convention": conv, "closed_loop": design_name == "closed_loop_steps",
                 "format": fmt, "truth": {"num": num.tolist(), "den": den.tolist(),
                                          "dc_gain_mm_per_kv": plant.dc_gain(num, den)},
                 "files": {"train": f_tr}, "args": [f_tr] + io_args(fmt) + list(extra_args)}
        with open(os.path.join(self.out, "labels", cid + ".json"), "w") as fh:
            json.dump(label, fh, indent=1, default=float)
        self.n += 1
        print(f"{cid}: ident {design_name} fs={fs} fmt={fmt} n={len(t)}", flush=True)


def build(out, seed=2, only=None):
    """Generate the whole corpus into out."""
    b = Builder(out, seed)
    rng = b.rng
    # ---- identification: every design at 200 Hz and 1 kHz, plus other rates
    designs = ["paper_chirp", "paper_chirp_repeated", "linear_chirp", "log_chirp", "multisine",
               "prbs", "random_steps", "voltage_steps", "closed_loop_steps"]
    fmts = ["csv", "mat", "mcap"]
    if only in (None, "ident"):
        i = 0
        for fs in (200, 1000):
            for dn in designs:
                fmt = fmts[i % 3] if fs == 200 else fmts[(i + 1) % 3]
                b.ident(f"id_{dn}_{fs}", dn, fs, fmt=fmt,
                        noise_kind="coloured" if i % 4 == 3 else "white")
                i += 1
        b.ident("id_paper_chirp_10000", "paper_chirp", 10000, fmt="csv")
        b.ident("id_log_chirp_5000", "log_chirp", 5000, fmt="mat")
        b.ident("id_multisine_500", "multisine", 500, fmt="mcap")
        b.ident("id_prbs_2000", "prbs", 2000, fmt="csv")
        b.ident("id_random_steps_100", "random_steps", 100, fmt="csv")
        b.ident("id_closed_loop_steps_500", "closed_loop_steps", 500, fmt="csv")
        b.ident("id_linear_chirp_1000_centred", "linear_chirp", 1000, fmt="csv", conv="centred",
                extra_args=["--input-hold", "centred"])
    if only == "ident":
        return b.n
    rates = [200, 500, 1000, 2000, 5000, 10000]

    def dur_for(fs):
        # keep the sample count modest: long logs at low rates, short at high
        return {200: (60, 30), 500: (50, 25), 1000: (40, 20), 2000: (30, 12),
                5000: (20, 8), 10000: (20, 6)}[fs]

    def fmt_for(k):
        return ["csv", "csv", "mat", "csv", "mcap", "csv"][k % 6]

    # ---- effect-free (22: 20 open loop, 2 closed loop)
    convs = ["zoh", "foh", "centred", "skew", "zoh", "skew"]
    noises = [("white", 0.0), ("coloured", 0.0), ("white", 1.0), ("coloured", 1.5)]
    for k in range(20):
        fs = rates[k % 6] if k < 12 else [200, 1000, 500, 2000][k % 4]
        tr_s, he_s = dur_for(fs)
        nk, wf = noises[k % 4]
        sigma = float(rng.choice([0.005, 0.01, 0.02]))
        conv = convs[k % 6]
        skew = float(rng.choice([-0.4, -0.25, 0.25, 0.4, 0.5])) if conv == "skew" else 0.0
        b.diag(f"free_{k:02d}", "effect_free", [], fs, conv=conv, skew=skew,
               fmt=fmt_for(k) if fs <= 2000 else "csv", noise_kind=nk, sigma=sigma,
               wander=wf * sigma, train=TRAIN_DESIGNS[k % 6],
               held=HELD_DESIGNS[k % 5], train_s=tr_s, held_s=he_s)
    for k in range(2):
        fs = [200, 1000][k]
        b.diag(f"free_cl_{k}", "effect_free", [], fs, closed=True, noise_kind=noises[k + 1][0],
               sigma=0.01, wander=0.01 * noises[k + 1][1], train_s=40, held_s=20)
    # ---- singles: 8 names x 3 forms, + 3 closed loop
    k = 0
    for name in NAMES:
        for form in "abc":
            fs = [200, 500, 1000, 2000, 200, 1000, 5000, 500][k % 8] if k % 7 != 6 else 10000
            tr_s, he_s = dur_for(fs)
            nk, wf = noises[k % 4]
            conv = ["zoh", "zoh", "foh", "zoh", "skew", "centred"][k % 6]
            b.diag(f"single_{name}_{form}", "single", [(name, form)], fs, conv=conv,
                   skew=0.3 if conv == "skew" else 0.0,
                   fmt=fmt_for(k) if fs <= 2000 else "csv", noise_kind=nk,
                   sigma=float(rng.choice([0.005, 0.01, 0.02])), wander=wf * 0.01,
                   train=TRAIN_DESIGNS[k % 6], held=HELD_DESIGNS[k % 5],
                   train_s=tr_s, held_s=he_s)
            k += 1
    for j, (name, form) in enumerate([("asymmetric_dynamics", "a"), ("sensor_nonlinearity", "b"),
                                      ("load_mass", "b")]):
        b.diag(f"single_cl_{name}_{form}", "single", [(name, form)], [200, 1000, 200][j],
               closed=True, noise_kind="white", sigma=0.01, train_s=40, held_s=20)
    # ---- near floor: one per name, effect rms 0.25-0.9 x noise
    for j, name in enumerate(NAMES):
        form = "abc"[j % 3]
        fs = [200, 500, 1000, 200, 2000, 500, 1000, 200][j]
        tr_s, he_s = dur_for(fs)
        nk, wf = noises[j % 4]
        b.diag(f"floor_{name}_{form}", "near_floor", [(name, form)], fs,
               conv=["zoh", "foh", "zoh", "centred"][j % 4], fmt="csv", noise_kind=nk,
               sigma=0.01, wander=wf * 0.01, train=TRAIN_DESIGNS[j % 6],
               held=HELD_DESIGNS[j % 5], train_s=tr_s, held_s=he_s,
               target_ratio=float(rng.uniform(0.25, 0.9)))

    # ---- pairs (12) and triples (8)
    def combo(m):
        while True:
            names = sorted(rng.choice(NAMES, m, replace=False).tolist())
            forms = [str(rng.choice(list("abc"))) for _ in names]
            slots = [plant.effect_slot({"name": n, "form": f}) for n, f in zip(names, forms)]
            if len(set(slots)) == m:
                return list(zip(names, forms))

    for j in range(12):
        fs = [200, 500, 1000, 2000, 200, 1000][j % 6]
        tr_s, he_s = dur_for(fs)
        nk, wf = noises[j % 4]
        b.diag(f"pair_{j:02d}", "pair", combo(2), fs, conv=["zoh", "foh", "skew"][j % 3],
               fmt=fmt_for(j) if fs <= 2000 else "csv", noise_kind=nk, sigma=0.01,
               wander=wf * 0.01, train=TRAIN_DESIGNS[j % 6], held=HELD_DESIGNS[j % 5],
               train_s=tr_s, held_s=he_s)
    for j in range(8):
        fs = [200, 500, 1000, 200, 5000, 1000, 500, 200][j]
        tr_s, he_s = dur_for(fs)
        nk, wf = noises[j % 4]
        closed = j == 7
        b.diag(f"triple_{j:02d}", "triple", combo(3), fs, conv=["zoh", "centred"][j % 2],
               fmt="csv", noise_kind=nk, sigma=0.01, wander=wf * 0.01,
               train=TRAIN_DESIGNS[j % 6], held=HELD_DESIGNS[j % 5], train_s=tr_s,
               held_s=he_s, closed=closed)
    # ---- the speed figure: a 120 s, 1 kHz log (a single effect)
    b.diag("speed_120s_1khz", "single", [("hysteresis", "a")], 1000, train="multisine",
           held="random_steps", train_s=120, held_s=20, noise_kind="white", sigma=0.01)
    return b.n


def main(argv=None):
    """CLI entry point."""
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", required=True)
    ap.add_argument("--seed", type=int, default=2)
    ap.add_argument("--only", choices=["ident", "diagnose"])
    a = ap.parse_args(argv)
    n = build(a.out, a.seed, a.only)
    print(f"{n} cases in {a.out}")


if __name__ == "__main__":
    main()
