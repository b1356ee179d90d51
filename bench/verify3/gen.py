"""Generate the third blind verification corpus (bench/verify3).

    python gen.py --out DIR [--seed N] [--only PREFIX,...] [--no-mcap]

Writes DIR/cases/<id>/{train,heldout}.{csv,mat,mcap}, model.json (the exact
nominal P(s), kV -> mm), case.json (how to run the case: task, data format,
MCAP topics; no truth) and DIR/labels/<id>.json (the truth, for the scorer only).
Units: time s, voltage kV, stroke mm.  Written without reading the project's
analysis code.
"""
from __future__ import annotations

import argparse
import json
import math
import os
import sys
import time

import numpy as np
from scipy import io as sio
from scipy import signal

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import plant as P  # noqa: E402

IN_TOPIC, OUT_TOPIC = "/rig3/voltage_kv", "/rig3/stroke_mm"
MCAP_T0_NS = 1_790_000_000_000_000_000  # an arbitrary wall-clock origin (ns)

# ====================================================================== designs
# Every design returns the logged voltage v (kV) at rate fs (Hz).


def _hold(level, dur, fs):
    return np.full(int(round(dur * fs)), float(level))


def paper_chirp(fs, offsets=(2, 3, 4, 5, 6, 7), reps=1, settle=0.5, pre_neg=0.0, amp=1.0,
                f0=0.001, ff=20.0, ttot=20.0):
    """The paper's test input (3)-(5): per offset an optional -1 kV reversal of
    pre_neg s, settle s at the offset, then reps chirps v_s + A sin(2 pi f(t) t),
    f(t) = (ff - f0)/ttot t (instantaneous frequency reaches 2 ff)."""
    parts = []
    t = np.arange(int(round(ttot * fs))) / fs
    ch = amp * np.sin(2 * np.pi * ((ff - f0) / ttot * t) * t)
    for vs in offsets:
        if pre_neg > 0:
            parts.append(_hold(-1.0, pre_neg, fs))
        parts.append(_hold(vs, settle, fs))
        for _ in range(reps):
            parts.append(vs + ch)
    return np.concatenate(parts)


def lin_chirp(fs, offsets=(4.0,), f0=0.05, f1=20.0, dur=30.0, amp=1.0, settle=1.0):
    """Textbook linear chirp, instantaneous frequency f0 -> f1 over dur s, on each offset."""
    t = np.arange(int(round(dur * fs))) / fs
    ch = amp * np.sin(2 * np.pi * (f0 * t + (f1 - f0) * t * t / (2 * dur)))
    return np.concatenate([np.concatenate([_hold(vs, settle, fs), vs + ch]) for vs in offsets])


def log_chirp(fs, offsets=(4.5,), f0=0.05, f1=25.0, dur=40.0, amp=1.0, settle=1.0):
    """Logarithmic chirp f0 -> f1 over dur s on each offset."""
    t = np.arange(int(round(dur * fs))) / fs
    ch = amp * signal.chirp(t, f0, dur, f1, method="logarithmic", phi=-90)
    return np.concatenate([np.concatenate([_hold(vs, settle, fs), vs + ch]) for vs in offsets])


def multisine(fs, offsets=(4.5,), period=10.0, periods=3, fmin=0.1, fmax=25.0, nlines=40,
              amp=1.0, settle=1.0, rng=None):
    """Periodic multisine, log-spaced lines between fmin and fmax on the 1/period
    grid, Schroeder phases, peak amplitude amp (kV), periods whole periods per offset."""
    n = int(round(period * fs))
    t = np.arange(n) / fs
    k = np.unique(np.round(np.geomspace(fmin * period, fmax * period, nlines)).astype(int))
    ph = -np.pi * np.arange(len(k)) * (np.arange(len(k)) + 1) / len(k)
    if rng is not None:
        ph = ph + rng.uniform(-0.3, 0.3, len(k))
    x = np.sum(np.sin(2 * np.pi * np.outer(k / period, t) + ph[:, None]), axis=0)
    x = amp * x / np.max(np.abs(x))
    return np.concatenate([np.concatenate([_hold(vs, settle, fs), np.tile(vs + x, periods)])
                           for vs in offsets])


def prbs(fs, rng, offset=4.0, amp=1.0, bit=0.012, dur=30.0, settle=1.0):
    """Random binary sequence +-amp (kV) around offset with bit time bit (s)."""
    nb = int(dur / bit)
    bits = rng.integers(0, 2, nb) * 2 - 1
    v = offset + amp * np.repeat(bits, int(round(bit * fs)))
    return np.concatenate([_hold(offset, settle, fs), v])


def rand_levels(fs, rng, lo=1.0, hi=8.0, dur=30.0, hold=(0.05, 1.5)):
    """Random level steps uniform in [lo, hi] kV held for random durations (s)."""
    parts, tot = [], 0.0
    while tot < dur:
        d = rng.uniform(*hold)
        parts.append(_hold(rng.uniform(lo, hi), d, fs))
        tot += d
    return np.concatenate(parts)


def steps(fs, levels=(1, 3, 5, 7, 8, 6, 4, 2, 1), hold=2.5):
    """Voltage staircase: each level (kV) held hold s."""
    return np.concatenate([_hold(v, hold, fs) for v in levels])


def chained(*parts):
    """Concatenate designs."""
    return np.concatenate(parts)


# ====================================================================== closed loop
CPLUS = (1.15, 25.0, 1.74e-5)
CMINUS = (1.25, 26.0, 3.2e-5)


def closed_loop(fs, plant, refs, hold, rng, noise_kw, ctrl_hz=200.0, v_lim=(0.0, 9.0)):
    """Simulate the paper's dual-mode PID (14)-(15) at ctrl_hz on the plant at fs.

    refs: stroke references (mm), each held hold s.  Feedback is the measured
    stroke through a 40 Hz 2nd-order Butterworth low-pass; the command (kV) is
    clipped to v_lim and held between controller ticks.  Returns (v, y): the
    applied voltage as logged and the measured stroke (mm)."""
    ratio = int(round(fs / ctrl_hz))
    ts_c = ratio / fs
    r = np.concatenate([np.full(int(round(hold * fs)), x) for x in refs])
    n = len(r)
    e_noise = P.noise(n, fs, rng, **noise_kw)
    b, a = signal.butter(2, 40.0 / (ctrl_hz / 2))
    zi = signal.lfilter_zi(b, a)
    v0 = refs[0] / 1.351
    plant.reset(v0)
    zf = zi * refs[0]
    integ, e_prev, u = v0, 0.0, v0
    v = np.empty(n)
    y = np.empty(n)
    z = None
    for i in range(n):
        if i % ratio == 0:
            meas = (z if z is not None else refs[0]) + e_noise[i - 1 if i else 0]
            fb, zf = signal.lfilter(b, a, [meas], zi=zf)
            e = r[i] - fb[0]
            kp, ki, kd = CPLUS if e >= 0 else CMINUS
            integ += ki * ts_c / 2 * (e + e_prev)
            integ = min(max(integ, -2.0), 10.0)
            u = kp * e + integ + kd * (e - e_prev) / ts_c
            u = min(max(u, v_lim[0]), v_lim[1])
            e_prev = e
        v[i] = u
        z = plant.step(u)
        y[i] = z
    return v, y + e_noise


# ====================================================================== effects
# Every form: (family, tool names accepted besides the family, builder(ts, s) ->
# pieces); s scales the strength (1 = the listed parameters).


def _pieces(pre=(), post=(), drift=None, tf=None, delay=0.0, lag=0.0, params=None):
    return dict(pre=list(pre), post=list(post), drift=drift, tf=tf, delay=delay, lag=lag,
                params=params or {})


FORMS = {
    "stat_twoslope": ("static_nonlinearity", [], lambda ts, s: _pieces(
        pre=[P.TwoSlopeMap(4.5, 1 - 0.25 * s, 1 + 0.3 * s, 0.35)],
        params=dict(v_c=4.5, g_lo=1 - 0.25 * s, g_hi=1 + 0.3 * s))),
    "stat_threshold": ("static_nonlinearity", [], lambda ts, s: _pieces(
        pre=[P.ThresholdMap(0.9 * s, 0.4 * s)], params=dict(v0=0.9 * s, blend=0.4 * s))),
    "stat_ripple": ("static_nonlinearity", [], lambda ts, s: _pieces(
        pre=[P.RippleMap(0.22 * s, 2.6)], params=dict(a_kv=0.22 * s, period_kv=2.6))),
    "hyst_boucwen": ("hysteresis", [], lambda ts, s: _pieces(
        pre=[P.BoucWen(0.6 * s, 1.5, 0.4)], params=dict(A=0.6 * s, beta=1.5, gamma=0.4))),
    "hyst_asympi": ("hysteresis", [], lambda ts, s: _pieces(
        pre=[P.AsymPI(w=(0.25 * s, 0.2 * s, 0.15 * s))],
        params=dict(r_up=[0.15, 0.4, 0.8], r_dn=[0.05, 0.2, 0.5], w=[0.25 * s, 0.2 * s, 0.15 * s]))),
    "hyst_outplay": ("hysteresis", [], lambda ts, s: _pieces(
        post=[P.OutputPlay(0.12 * s)], params=dict(r_mm=0.12 * s))),
    "sat_tanhstop": ("saturation", [], lambda ts, s: _pieces(
        post=[P.TanhEndStop(7.6 + 2 * (1 - s), 0.7)], params=dict(z0_mm=7.6 + 2 * (1 - s), w_mm=0.7))),
    "sat_hardstop": ("saturation", [], lambda ts, s: _pieces(
        post=[P.HardStop(8.2 + 2 * (1 - s))], params=dict(z_max_mm=8.2 + 2 * (1 - s)))),
    "sat_ampclip": ("saturation", ["static_nonlinearity"], lambda ts, s: _pieces(
        pre=[P.AmpClip(6.9 + 2 * (1 - s))], params=dict(v_max_kv=6.9 + 2 * (1 - s)))),
    "sens_quad": ("sensor_nonlinearity", [], lambda ts, s: _pieces(
        post=[P.QuadSensor(0.07 * s)], params=dict(b=0.07 * s))),
    "sens_sqrt": ("sensor_nonlinearity", [], lambda ts, s: _pieces(
        post=[P.SqrtSensor(28.0 / max(s, 1e-3))], params=dict(s_mm=28.0 / max(s, 1e-3)))),
    "asym_chargelag": ("asymmetric_dynamics", [], lambda ts, s: _pieces(
        pre=[P.AsymChargeLag(ts, 0.002 * s, 0.030 * s)],
        params=dict(tau_up_s=0.002 * s, tau_dn_s=0.030 * s))),
    "asym_relax": ("asymmetric_dynamics", [], lambda ts, s: _pieces(
        post=[P.AsymRelax(ts, 0.045 * s)], params=dict(tau_s=0.045 * s))),
    "asym_slew": ("asymmetric_dynamics", [], lambda ts, s: _pieces(
        pre=[P.AsymSlew(ts, 70.0 / s, 22.0 / s)], params=dict(up_kv_s=70.0 / s, dn_kv_s=22.0 / s))),
    "drift_leaky": ("charge_drift", [], lambda ts, s: _pieces(
        drift=P.Drift(ts, "leaky", a=0.004 * s), params=dict(a=0.004 * s, b0=0.02, b1=0.004, g=1.0))),
    "drift_trap": ("charge_drift", [], lambda ts, s: _pieces(
        drift=P.Drift(ts, "trap", k=0.02 * s), params=dict(k=0.02 * s, v_th=2.5, tau=60.0, c=1.5))),
    "delay_pure": ("time_delay", [], lambda ts, s: _pieces(
        delay=0.0093 * s, params=dict(delay_s=0.0093 * s))),
    "delay_mixed": ("time_delay", [], lambda ts, s: _pieces(
        delay=0.004 * s, lag=0.008 * s, params=dict(delay_s=0.004 * s, lag_s=0.008 * s))),
    "load_mass": ("load_mass", [], lambda ts, s: _pieces(
        tf=P.loaded_tf(1.5 * s, 2), params=dict(mu=1.5 * s, pairs=2))),
    "load_third": ("load_mass", [], lambda ts, s: _pieces(
        tf=P.third_pair_tf(31.0 / math.sqrt(s), 0.22),
        params=dict(f_hz=31.0 / math.sqrt(s), zeta=0.22))),
    "load_onepair": ("load_mass", [], lambda ts, s: _pieces(
        tf=P.loaded_tf(2.5 * s, 1), params=dict(mu=2.5 * s, pairs=1))),
}


def build_plant(fs, forms=(), strength=None, convention="zoh", skew=0.0):
    """Compose a Plant at fs (Hz) from effect form names (each at strength
    strength[form], default 1).  Returns (plant, effect label list)."""
    ts = 1.0 / fs
    strength = strength or {}
    pre, post, drift, tf, delay, lag, labels = [], [], None, None, 0.0, 0.0, []
    for f in forms:
        fam, alt, b = FORMS[f]
        s = strength.get(f, 1.0)
        pc = b(ts, s)
        pre += pc["pre"]
        post += pc["post"]
        drift = pc["drift"] or drift
        tf = pc["tf"] or tf
        delay += pc["delay"]
        lag += pc["lag"]
        labels.append(dict(family=fam, form=f, accept=[fam] + alt, strength=s, params=pc["params"]))
    # output-side order: dynamics-like first, then end stops, play, sensor curve last
    order = {P.AsymRelax: 0, P.TanhEndStop: 1, P.HardStop: 1, P.OutputPlay: 2,
             P.QuadSensor: 3, P.SqrtSensor: 3}
    post.sort(key=lambda b: order.get(type(b), 1))
    num, den = tf if tf is not None else P.paper_tf()
    if lag > 0:
        den = np.polymul(den, [lag, 1.0])
    return P.Plant(ts, num, den, convention, skew, delay, pre, post, drift), labels


# ====================================================================== writing
def write_csv(path, t, v, y):
    """CSV with header t_s,voltage_kv,stroke_mm."""
    with open(path, "w") as fh:
        fh.write("t_s,voltage_kv,stroke_mm\n")
        np.savetxt(fh, np.column_stack([t, v, y]), fmt="%.7f,%.7g,%.7g")


def write_mat(path, t, v, y):
    """MAT (v5) with column vectors t_s, voltage_kv, stroke_mm."""
    sio.savemat(path, dict(t_s=t[:, None], voltage_kv=v[:, None], stroke_mm=y[:, None]))


def write_mcap(path, t, v, y):
    """ROS 2 MCAP: one std_msgs/msg/Float64 per sample on IN_TOPIC and OUT_TOPIC,
    log and publish time = MCAP_T0_NS + t (no header: Float64 has none)."""
    from mcap_ros2.writer import Writer
    with open(path, "wb") as fh:
        w = Writer(fh)
        sch = w.register_msgdef("std_msgs/msg/Float64", "float64 data")
        tn = MCAP_T0_NS + np.round(t * 1e9).astype(np.int64)
        for i in range(len(t)):
            ti = int(tn[i])
            w.write_message(IN_TOPIC, sch, {"data": float(v[i])}, log_time=ti, publish_time=ti,
                            sequence=i)
            w.write_message(OUT_TOPIC, sch, {"data": float(y[i])}, log_time=ti, publish_time=ti,
                            sequence=i)
        w.finish()


def write_log(base, t, v, y, mcap=True):
    """Write one log as base.csv, base.mat and (optionally) base.mcap."""
    write_csv(base + ".csv", t, v, y)
    write_mat(base + ".mat", t, v, y)
    if mcap:
        write_mcap(base + ".mcap", t, v, y)


# ====================================================================== the cases
NOISE_W = dict(white=0.01)


def _design(name, fs, rng):
    """Named designs used by the case table (voltage in kV at fs)."""
    d = {
        "paper1x6": lambda: paper_chirp(fs),
        "paper3x6_pre": lambda: paper_chirp(fs, reps=3, pre_neg=2.0, settle=1.0),
        "paper1x3": lambda: paper_chirp(fs, offsets=(3, 5, 7), settle=2.0),
        "paper1x2": lambda: paper_chirp(fs, offsets=(3, 6), settle=0.5),
        "paper1x2_pre": lambda: paper_chirp(fs, offsets=(2.5, 6.5), settle=1.5, pre_neg=1.0),
        "paper1x1": lambda: paper_chirp(fs, offsets=(4,), settle=0.5),
        "lin2": lambda: lin_chirp(fs, offsets=(3.0, 5.5), dur=25.0),
        "lin4": lambda: lin_chirp(fs, offsets=(2.0, 3.5, 5.0, 6.5), dur=15.0, f0=0.1),
        "lin1s": lambda: lin_chirp(fs, offsets=(4.0,), dur=10.0, f0=0.1, settle=0.5),
        "log1": lambda: log_chirp(fs),
        "log2": lambda: log_chirp(fs, offsets=(3.0, 6.0), dur=20.0, f0=0.08),
        "log3": lambda: log_chirp(fs, offsets=(2.5, 4.5, 6.5), dur=14.0, f0=0.1),
        "ms1": lambda: multisine(fs, periods=4, rng=rng),
        "ms3": lambda: multisine(fs, offsets=(2.5, 4.5, 6.5), periods=2, rng=rng),
        "ms1s": lambda: multisine(fs, period=5.0, periods=2, fmin=0.2, rng=rng, settle=0.5),
        "prbs": lambda: prbs(fs, rng),
        "prbs_hi": lambda: chained(prbs(fs, rng, offset=3.0, dur=15.0), prbs(fs, rng, offset=6.0, dur=15.0)),
        "rlev": lambda: rand_levels(fs, rng),
        "rlev_s": lambda: rand_levels(fs, rng, dur=18.0, hold=(0.03, 1.0)),
        "steps": lambda: steps(fs),
        "steps_s": lambda: steps(fs, levels=(2, 4, 6, 8, 5, 3, 1, 7), hold=2.0),
        "mix_rlev_ms": lambda: chained(rand_levels(fs, rng, dur=8.0),
                                       multisine(fs, offsets=(5.0,), period=5.0, periods=2, rng=rng)),
        "mix_steps_lin": lambda: chained(steps(fs, levels=(1.5, 4, 7, 3), hold=2.0),
                                         lin_chirp(fs, offsets=(5.0,), dur=10.0, f0=0.2)),
    }
    return d[name]()


CL_REFS = {
    "paper": [2, 4, 6, 4, 2, 4, 6, 4, 2],
    "rand": None,  # drawn per case
}


# Each row: id, task, design, heldout design (or None), fs, forms, options
def case_table():
    """The case list: dicts with id, task, cat, design, held, fs, forms, and options."""
    C = []

    def add(cid, task, cat, design, fs, forms=(), held=None, **kw):
        C.append(dict(id=cid, task=task, cat=cat, design=design, held=held, fs=fs,
                      forms=list(forms), **kw))

    # ---------------- identification, effect-free (20)
    add("id01", "identify", "ident", "paper1x6", 1000)
    add("id02", "identify", "ident", "paper3x6_pre", 200)
    add("id03", "identify", "ident", "paper1x3", 500, fmt="mcap")
    add("id04", "identify", "ident", "paper1x6", 200, noise=dict(white=0.02))
    add("id05", "identify", "ident", "lin2", 1000)
    add("id06", "identify", "ident", "lin4", 200, fmt="mcap")
    add("id07", "identify", "ident", "log1", 1000)
    add("id08", "identify", "ident", "log2", 200)
    add("id09", "identify", "ident", "ms1", 1000, fmt="mcap")
    add("id10", "identify", "ident", "ms3", 200)
    add("id11", "identify", "ident", "prbs", 1000)
    add("id12", "identify", "ident", "prbs_hi", 200)
    add("id13", "identify", "ident", "rlev", 1000, fmt="mcap")
    add("id14", "identify", "ident", "rlev", 200)
    add("id15", "identify", "ident", "steps", 1000)
    add("id16", "identify", "ident", "steps", 200)
    add("id17", "identify", "ident", "cl_paper", 1000, cl=True)
    add("id18", "identify", "ident", "cl_rand", 200, cl=True, fmt="mcap")
    add("id19", "identify", "ident", "lin1s", 5000, conv="foh")
    add("id20", "identify", "ident", "ms1s", 10000, conv="centred")
    add("id21", "identify", "ident", "log2", 2000, noise=dict(white=0.006, colour=0.01, colour_hz=1.5))
    add("id22", "identify", "ident", "rlev", 100)

    # ---------------- diagnosis, effect-free (20)
    free = [
        ("paper1x2", 1000, "rlev_s", {}, {}),
        ("lin2", 200, "steps_s", {}, {}),
        ("log2", 1000, "ms1s", dict(conv="foh"), {}),
        ("ms3", 500, "rlev_s", dict(conv="centred"), {}),
        ("prbs_hi", 1000, "steps_s", dict(skew=-0.3), {}),
        ("rlev", 200, "mix_rlev_ms", dict(skew=0.4), {}),
        ("steps", 1000, "rlev_s", {}, dict(white=0.004, colour=0.012, colour_hz=0.8)),
        ("paper1x2_pre", 200, "steps_s", {}, dict(white=0.008, wander=0.04, wander_hz=0.03)),
        ("mix_steps_lin", 2000, "rlev_s", {}, dict(white=0.01, colour=0.008, colour_hz=3.0)),
        ("log3", 500, "rlev_s", {}, dict(white=0.005, wander=0.06, wander_hz=0.02)),
        ("cl_paper", 1000, "cl_rand", dict(cl=True), {}),
        ("cl_rand", 200, "cl_paper", dict(cl=True), dict(white=0.01, colour=0.01, colour_hz=2.0)),
        ("ms1", 1000, "steps_s", {}, dict(white=0.02)),
        ("lin4", 1000, "ms1s", dict(skew=-0.5), dict(white=0.01, quant=9.9 / 4096)),
        ("prbs", 2000, "rlev_s", dict(conv="foh"), dict(white=0.003, colour=0.006, colour_hz=5.0,
                                                           wander=0.03, wander_hz=0.05)),
        ("paper1x1", 5000, "lin1s", {}, {}),
        ("lin1s", 10000, "ms1s", dict(conv="centred"), dict(white=0.015)),
        ("rlev", 500, "paper1x1", {}, dict(white=0.006, wander=0.05, wander_hz=0.01)),
        ("log1", 200, "rlev_s", dict(skew=0.25), dict(white=0.01, colour=0.015, colour_hz=0.5)),
        ("paper1x3", 1000, "mix_rlev_ms", {}, dict(white=0.01, wander=0.03, wander_hz=0.04)),
    ]
    for i, (d, fs, h, kw, nz) in enumerate(free, 1):
        add(f"fr{i:02d}", "diagnose", "free", d, fs, held=h, noise=nz or None, **kw)

    # ---------------- singles: 8 families, 2-3 forms each (20)
    singles = [
        ("stat_twoslope", "ms3", 1000, "rlev_s"), ("stat_threshold", "rlev", 500, "steps_s"),
        ("stat_ripple", "lin4", 200, "rlev_s"),
        ("hyst_boucwen", "paper1x3", 1000, "steps_s"), ("hyst_asympi", "rlev", 200, "ms1s"),
        ("hyst_outplay", "log2", 1000, "rlev_s"),
        ("sat_tanhstop", "paper1x2", 1000, "steps_s"), ("sat_hardstop", "rlev", 2000, "mix_rlev_ms"),
        ("sat_ampclip", "steps", 500, "rlev_s"),
        ("sens_quad", "prbs_hi", 1000, "steps_s"), ("sens_sqrt", "mix_steps_lin", 200, "rlev_s"),
        ("asym_chargelag", "prbs", 1000, "steps_s"), ("asym_relax", "rlev", 1000, "ms1s"),
        ("asym_slew", "lin2", 500, "rlev_s"),
        ("drift_leaky", "paper1x2_pre", 200, "steps_s"), ("drift_trap", "steps", 1000, "rlev_s"),
        ("delay_pure", "log2", 1000, "steps_s"), ("delay_mixed", "prbs_hi", 200, "rlev_s"),
        ("load_mass", "paper1x2", 1000, "rlev_s"), ("load_third", "prbs", 2000, "ms1s"),
    ]
    for i, (f, d, fs, h) in enumerate(singles, 1):
        add(f"si{i:02d}", "diagnose", "single", d, fs, forms=[f], held=h)

    # ---------------- closed-loop singles (4) and one effect-free already above
    add("cl01", "diagnose", "single_cl", "cl_paper", 1000, forms=["asym_relax"], held="cl_rand", cl=True)
    add("cl02", "diagnose", "single_cl", "cl_rand", 200, forms=["delay_pure"], held="cl_paper", cl=True)
    add("cl03", "diagnose", "single_cl", "cl_rand", 1000, forms=["sens_quad"], held="cl_paper", cl=True)
    add("cl04", "diagnose", "single_cl", "cl_paper", 500, forms=["load_onepair"], held="cl_rand", cl=True)

    # ---------------- near-floor (8): effect rms about 0.4-0.9 x the white noise std
    nf = [
        ("stat_ripple", "lin4", 1000, "rlev_s", 0.5), ("hyst_boucwen", "rlev", 200, "steps_s", 0.7),
        ("sens_quad", "ms3", 500, "rlev_s", 0.6), ("drift_leaky", "steps", 1000, "rlev_s", 0.5),
        ("load_mass", "prbs", 1000, "ms1s", 0.8), ("delay_pure", "log2", 200, "steps_s", 0.6),
        ("asym_chargelag", "prbs_hi", 1000, "steps_s", 0.5), ("load_third", "ms1", 2000, "rlev_s", 0.7),
    ]
    for i, (f, d, fs, h, tgt) in enumerate(nf, 1):
        add(f"nf{i:02d}", "diagnose", "near_floor", d, fs, forms=[f], held=h, target=tgt)

    # ---------------- pairs (8)
    pairs = [
        (["stat_twoslope", "delay_pure"], "lin4", 1000, "rlev_s"),
        (["hyst_asympi", "sens_sqrt"], "rlev", 500, "steps_s"),
        (["load_mass", "drift_trap"], "prbs_hi", 1000, "steps_s"),
        (["sat_tanhstop", "asym_chargelag"], "paper1x2", 1000, "steps_s"),
        (["sens_quad", "delay_mixed"], "lin4", 200, "rlev_s"),
        (["hyst_boucwen", "load_third"], "prbs_hi", 2000, "ms1s"),
        (["stat_threshold", "asym_relax"], "rlev", 1000, "ms1s"),
        (["drift_leaky", "sat_hardstop"], "paper1x2_pre", 200, "steps_s"),
    ]
    for i, (fo, d, fs, h) in enumerate(pairs, 1):
        add(f"pa{i:02d}", "diagnose", "pair", d, fs, forms=fo, held=h)

    # ---------------- triples (5)
    triples = [
        (["stat_twoslope", "load_mass", "drift_leaky"], "mix_rlev_ms", 1000, "steps_s"),
        (["hyst_boucwen", "delay_pure", "sens_quad"], "paper1x3", 500, "rlev_s"),
        (["asym_slew", "sat_tanhstop", "load_onepair"], "rlev", 1000, "ms1s"),
        (["stat_ripple", "asym_relax", "delay_mixed"], "paper1x2", 200, "rlev_s"),
        (["sens_sqrt", "hyst_outplay", "drift_trap"], "steps", 1000, "mix_rlev_ms"),
    ]
    for i, (fo, d, fs, h) in enumerate(triples, 1):
        add(f"tr{i:02d}", "diagnose", "triple", d, fs, forms=fo, held=h)
    # closed-loop pair
    add("cl05", "diagnose", "pair_cl", "cl_rand", 1000, forms=["hyst_boucwen", "drift_leaky"],
        held="cl_paper", cl=True)
    return C


def _cl_refs(name, rng):
    if name == "cl_paper":
        return CL_REFS["paper"], 2.0
    return list(np.round(rng.uniform(1.5, 7.0, 16), 2)), 1.5


def simulate(case, which, rng, strength=None):
    """Simulate one log of a case: which = 'train' or 'heldout'.

    Returns (t, v, y, meta) with t in s, v in kV, y in mm."""
    fs = case["fs"]
    design = case["design"] if which == "train" else case["held"]
    nkw = dict(NOISE_W)
    nkw.update(case.get("noise") or {})
    quant = nkw.pop("quant", 0.0)
    plant, labels = build_plant(fs, case["forms"], strength, case.get("conv", "zoh"),
                                case.get("skew", 0.0))
    if design.startswith("cl_"):
        refs, hold = _cl_refs(design, rng)
        v, y = closed_loop(fs, plant, refs, hold, rng, nkw)
        z = None
    else:
        v = _design(design, fs, rng)
        z = plant.run(v)
        y = z + P.noise(len(v), fs, rng, **nkw)
    y = P.quantise(y, quant)
    t = np.arange(len(v)) / fs
    return t, v, y, dict(design=design, labels=labels, z=z, noise=dict(nkw, quant=quant))


def effect_rms(case, rng_seed, strength):
    """RMS (mm) of the noise-free output change the case's effects cause on its
    training design (open loop designs only)."""
    fs = case["fs"]
    v = _design(case["design"], fs, np.random.default_rng(rng_seed))
    p0, _ = build_plant(fs, (), None, case.get("conv", "zoh"), case.get("skew", 0.0))
    p1, _ = build_plant(fs, case["forms"], strength, case.get("conv", "zoh"), case.get("skew", 0.0))
    return float(np.sqrt(np.mean((p1.run(v) - p0.run(v)) ** 2)))


def gen_case(out, case, seed, mcap=True):
    """Generate one case into out/cases/<id> and out/labels/<id>.json."""
    cid = case["id"]
    cdir = os.path.join(out, "cases", cid)
    os.makedirs(cdir, exist_ok=True)
    os.makedirs(os.path.join(out, "labels"), exist_ok=True)
    base_seed = seed * 1000 + sum(ord(c) * (i + 1) for i, c in enumerate(cid))
    strength = None
    ratio = None
    if case["cat"] == "near_floor":
        f = case["forms"][0]
        sigma = 0.01
        s = 1.0
        for _ in range(4):
            r = effect_rms(case, base_seed, {f: s}) / sigma
            if r <= 0:
                break
            s_new = s * case["target"] / r
            if abs(s_new - s) / s < 0.05:
                s = s_new
                break
            s = s_new
        strength = {f: s}
        ratio = effect_rms(case, base_seed, strength) / sigma
    elif case["forms"] and not case.get("cl"):
        ratio = effect_rms(case, base_seed, None) / 0.01
    each = None
    if case["forms"] and not case.get("cl"):
        each = {f: effect_rms(dict(case, forms=[f]), base_seed, strength) / 0.01
                for f in case["forms"]}
    rng = np.random.default_rng(base_seed)
    t, v, y, meta = simulate(case, "train", rng, strength)
    write_log(os.path.join(cdir, "train"), t, v, y, mcap)
    held = None
    if case["task"] == "diagnose":
        rng2 = np.random.default_rng(base_seed + 7)
        th, vh, yh, mh = simulate(case, "heldout", rng2, strength)
        write_log(os.path.join(cdir, "heldout"), th, vh, yh, mcap)
        held = dict(design=mh["design"], n=len(th), dur_s=float(th[-1] + 1 / case["fs"]))
    num, den = P.paper_tf()
    with open(os.path.join(cdir, "model.json"), "w") as fh:
        json.dump({"num": list(map(float, num)), "den": list(map(float, den))}, fh)
    fmt = case.get("fmt")
    if fmt is None:
        fmt = ["csv", "mat", "mcap"][sum(map(ord, cid)) % 3]
        if case["task"] == "identify" and fmt == "mat":
            fmt = "csv"  # identify reads .mcap or .csv (hasel identify --help)
    with open(os.path.join(cdir, "case.json"), "w") as fh:
        json.dump(dict(id=cid, task=case["task"], format=fmt, input_topic=IN_TOPIC + ".data",
                       output_topic=OUT_TOPIC + ".data", time_col="t_s", input_col="voltage_kv",
                       output_col="stroke_mm"), fh, indent=1)
    label = dict(id=cid, task=case["task"], category=case["cat"], fs=case["fs"],
                 design=case["design"], heldout=held, n=len(t), dur_s=float(len(t) / case["fs"]),
                 convention=case.get("conv", "zoh"), skew_samples=case.get("skew", 0.0),
                 closed_loop=bool(case.get("cl")), noise=meta["noise"], effects=meta["labels"],
                 effect_rms_over_white_sigma=ratio, each_effect_rms_over_0p01mm=each, format=fmt, seed=seed,
                 chirp_formula=("paper (3)-(5): f(t)=(ff-f0)/ttot*t, sweeps to 2 ff" if
                                case["design"].startswith("paper") else None))
    with open(os.path.join(out, "labels", cid + ".json"), "w") as fh:
        json.dump(label, fh, indent=1)
    return label


def main(argv=None):
    """CLI: generate the corpus."""
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--out", required=True)
    ap.add_argument("--seed", type=int, default=3)
    ap.add_argument("--only", default="", help="comma-separated id prefixes")
    ap.add_argument("--no-mcap", action="store_true", help="skip the MCAP files (faster)")
    a = ap.parse_args(argv)
    pref = [p for p in a.only.split(",") if p]
    t0 = time.time()
    rows = []
    for case in case_table():
        if pref and not any(case["id"].startswith(p) for p in pref):
            continue
        t1 = time.time()
        lab = gen_case(a.out, case, a.seed, not a.no_mcap)
        rows.append(lab)
        print(f"{lab['id']:5s} {lab['category']:11s} {lab['design']:14s} {lab['fs']:6d} Hz "
              f"{lab['dur_s']:6.1f} s  {','.join(e['form'] for e in lab['effects']) or '-':40s}"
              f" {time.time() - t1:5.1f} s", flush=True)
    with open(os.path.join(a.out, "corpus.json"), "w") as fh:
        json.dump(dict(seed=a.seed, n=len(rows), generator="bench/verify3/gen.py",
                       seconds=time.time() - t0), fh, indent=1)
    print(f"{len(rows)} cases in {time.time() - t0:.0f} s")


if __name__ == "__main__":
    main()
