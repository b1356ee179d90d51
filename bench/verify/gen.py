"""Generate the independent verification corpus (cases and hidden labels).

    python bench/verify/gen.py --out bench/verify/out [--seed 14] [--quick]

Writes OUT/cases/<id>/{train.*, heldout.*, model.json} (what the analysis sees) and
OUT/labels/<id>.json (the truth and the command-line selectors; only the scorer
reads it), plus OUT/index.json. Everything follows from the seed. Units: kV, mm, s.
"""
from __future__ import annotations

import argparse
import json
import warnings
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from scipy import signal
from scipy.io import savemat

try:  # plain script or package import
    from . import plant as pl
except ImportError:  # pragma: no cover
    import plant as pl

warnings.filterwarnings("ignore", category=signal.BadCoefficients)

NOISE_MM = 0.01
MCAP_IN, MCAP_OUT = "/hv/voltage", "/laser/stroke"


# ----------------------------------------------------------------------------- excitation
@dataclass
class Design:
    """How the input log is built: excitation `kind` repeated `repeats` times on each
    DC offset (kV) after an optional -1 kV pre-conditioning and a settle hold."""

    kind: str
    offsets: list
    seg_s: float = 20.0
    repeats: int = 1
    amp_kv: float = 1.0
    settle_s: float = 1.0
    precond_s: float = 0.0
    band_hz: tuple = (0.1, 25.0)


def _excite(kind: str, fs: float, seg_s: float, amp: float, band, rng) -> np.ndarray:
    """One zero-mean excitation segment (kV) of seg_s seconds at fs Hz."""
    n = int(round(seg_s * fs))
    t = np.arange(n) / fs
    f0, f1 = band
    f1 = min(f1, 0.2 * fs)
    if kind == "paper_chirp":
        # The paper's (4)-(5): sin(2 pi f(t) t), f(t) = (f_f - f_0) t / t_tot, f_f = 20 Hz.
        k = (20.0 - 0.001) / seg_s
        return amp * np.sin(2 * np.pi * k * t * t)
    if kind == "linear_chirp":
        return amp * signal.chirp(t, f0=f0, t1=seg_s, f1=f1, method="linear", phi=-90)
    if kind == "log_chirp":
        return amp * signal.chirp(t, f0=f0, t1=seg_s, f1=f1, method="logarithmic", phi=-90)
    if kind == "multisine":
        period = min(seg_s, 10.0)
        npd = int(round(period * fs))
        ks = np.arange(1, int(f1 * period) + 1)
        ks = ks[(ks % 2 == 1) & (ks / period >= f0)]
        ph = rng.uniform(0, 2 * np.pi, ks.size)
        tp = np.arange(npd) / fs
        x = np.sin(2 * np.pi * np.outer(tp, ks / period) + ph).sum(axis=1)
        x = np.tile(x, int(np.ceil(n / npd)))[:n]
        return amp * x / np.max(np.abs(x))
    if kind == "prbs":
        bit = max(1, int(round(fs / (2.5 * f1))))
        bits = rng.integers(0, 2, n // bit + 1) * 2 - 1
        return amp * np.repeat(bits, bit)[:n].astype(float)
    if kind == "random_steps":
        out = np.empty(n)
        i = 0
        while i < n:
            d = int(rng.uniform(0.08, 1.2) * fs)
            out[i:i + d] = rng.uniform(-amp, amp)
            i += d
        return out
    raise ValueError(kind)


def build_input(d: Design, fs: float, rng) -> np.ndarray:
    """The whole open-loop input log (kV) of a design."""
    parts = [np.zeros(int(0.5 * fs))]
    if d.kind == "voltage_steps":
        # A staircase through the listed levels, each held 1.2-2.5 s.
        if d.precond_s:
            parts.append(np.full(int(d.precond_s * fs), -1.0))
        for lvl in d.offsets:
            parts.append(np.full(int(rng.uniform(1.2, 2.5) * fs), float(lvl)))
        return np.concatenate(parts)
    for vs in d.offsets:
        if d.precond_s:
            parts.append(np.full(int(d.precond_s * fs), -1.0))
        parts.append(np.full(int(d.settle_s * fs), float(vs)))
        for _ in range(d.repeats):
            parts.append(vs + _excite(d.kind, fs, d.seg_s, d.amp_kv, d.band_hz, rng))
    parts.append(np.zeros(int(0.5 * fs)))
    return np.concatenate(parts)


# ----------------------------------------------------------------------------- effects
def _nominal_tf(effects) -> tuple[np.ndarray, np.ndarray]:
    """The plant's linear part: P(s) changed by load_mass / Pade-lag effects."""
    num, den = pl.paper_tf()
    for name, form, p in effects:
        if name == "load_mass":
            r = p["pole_scale"]
            num, den = pl.paper_tf(r)
            if form == "same_damper":
                # Extra mass, same damper: the s-term of each pole pair scales with r^2.
                quad = [1, 230.0 * r * r, (pl.P_W * r) ** 2]
                den = np.polymul(np.polymul([1, 18.85], [1, 56.55]), np.polymul(quad, quad))
                num = num * (den[-1] / num[-1]) * pl.dc_gain(*pl.paper_tf())
    for name, form, p in effects:
        if name == "time_delay" and form == "pade":
            T = p["delay_s"]
            num = np.polymul(num, [-T / 2, 1.0])
            den = np.polymul(den, [T / 2, 1.0])
    return num, den


def build_chain(fs: float, effects, convention="zoh", offset_frac=0.0, v0=0.0, y0=0.0,
                m: int | None = None) -> pl.Chain:
    """The plant chain for a list of (name, form, params) effects."""
    closed = m == 1
    if m is None:
        # A finer grid for other hold conventions, timing offsets and dead times that
        # are not whole samples; plain zero-order hold needs none.
        fine = convention != "zoh" or offset_frac or any(
            n == "time_delay" and f == "transport" for n, f, _ in effects)
        m = max(4, int(round(10000 / fs))) if fine else 1
    dt = 1.0 / (fs * m)
    num, den = _nominal_tf(effects)
    pre, post, ndel = [], [], 0
    for name, form, p in effects:
        if name == "static_nonlinearity":
            if form == "quadratic":
                b, vr = p["blend"], p["v_ref"]
                pre.append(pl.Map(lambda v, b=b, vr=vr: (1 - b) * v + b * v * np.abs(v) / vr))
            elif form == "knee":
                vk, s = p["knee_kv"], p["slope"]
                pre.append(pl.Map(lambda v, vk=vk, s=s: np.where(v > vk, vk + s * (v - vk), v)))
            elif form == "power":
                vr, e = p["v_ref"], p["exponent"]
                pre.append(pl.Map(lambda v, vr=vr, e=e: np.sign(v) * vr * (np.abs(v) / vr) ** e))
        elif name == "asymmetric_dynamics":
            if form == "dirlag_out":
                post.append(pl.DirLag(p["tau_up"], p["tau_down"], 1 / fs, y0))
            elif form == "dirlag_in":
                pre.append(pl.DirLag(p["tau_up"], p["tau_down"], 1 / fs, v0))
            elif form == "slew_down":
                post.append(pl.Slew(1e9, p["down_mm_s"], 1 / fs, y0))
        elif name == "charge_drift":
            if form == "creep_integral":
                post.append(pl.Creep(p["c_mm_per_kvs"], p["tau_s"], 1 / fs))
            elif form == "charge_gain":
                pre.append(pl.ChargeGain(p["c"], p["tau_s"], 1 / fs))
        elif name == "saturation":
            if form == "clip_stroke":
                post.append(pl.Map(lambda y, c=p["max_mm"]: np.minimum(y, c)))
            elif form == "endstop_smooth":
                yk, w = p["knee_mm"], p["width_mm"]
                post.append(pl.Map(lambda y, yk=yk, w=w: np.where(y > yk, yk + w * np.tanh((y - yk) / w), y)))
            elif form == "volt_clip":
                pre.append(pl.Map(lambda v, c=p["max_kv"]: np.minimum(v, c)))
            elif form == "amp_slew":
                pre.append(pl.Slew(p["kv_s"], p["kv_s"], 1 / fs, v0))
        elif name == "time_delay" and form == "transport":
            ndel = int(round(p["delay_s"] / dt))
        elif name == "sensor_nonlinearity":
            if form == "quadratic":
                a, off = p["a_per_mm"], p["offset_mm"]
                post.append(pl.Map(lambda y, a=a, off=off: off + y + a * y * y))
            elif form == "exponential":
                Y = p["scale_mm"]
                post.append(pl.Map(lambda y, Y=Y: Y * np.expm1(y / Y)))
            elif form == "log":
                Y = p["scale_mm"]
                post.append(pl.Map(lambda y, Y=Y: Y * np.log1p(np.maximum(y, -0.9 * Y) / Y)))
        elif name == "hysteresis":
            if form == "play":
                pre.append(pl.Play([p["r_kv"]], [1.0], v0))
            elif form == "pi":
                pre.append(pl.Play(p["radii"], p["weights"], v0))
            elif form == "asym_pi":
                pre.append(pl.Play(p["radii"], p["weights"], v0, up_scale=p["up_scale"]))
            elif form == "duhem":
                pre.append(pl.Duhem(p["alpha"], p["scale_kv"], v0))
    lin = pl.Linear(num, den, dt, mode="sos" if closed else "fir")
    return pl.Chain(fs=fs, m=m, lin=lin, delay=pl.Delay(ndel, v0), pre=pre, post=post,
                    convention=convention, offset_fine=int(round(offset_frac * m)))


def run_open(fs, u, effects, convention="zoh", offset_frac=0.0) -> np.ndarray:
    """Noise-free output (mm) of the plant with effects for an input log (kV)."""
    return build_chain(fs, effects, convention, offset_frac, v0=float(u[0])).run(u)


# ----------------------------------------------------------------------------- noise
def make_noise(kind: str, n: int, fs: float, rng) -> np.ndarray:
    """Measurement noise (mm): 'white', 'coloured' (low-passed at 3 Hz) or 'wander'
    (white plus a slow offset wander of about 0.03 mm rms below 0.05 Hz)."""
    w = rng.normal(0, NOISE_MM, n)
    if kind == "white":
        return w
    if kind == "coloured":
        b, a = signal.butter(1, 3.0 / (fs / 2))
        c = signal.lfilter(b, a, rng.normal(0, 1, n))
        return 0.5 * w + 0.015 * c / np.std(c)
    if kind == "wander":
        t = np.arange(n) / fs
        f = rng.uniform(0.005, 0.05, 4)
        ph = rng.uniform(0, 2 * np.pi, 4)
        drift = np.sin(2 * np.pi * np.outer(t, f) + ph).sum(axis=1)
        return w + 0.03 * drift / np.std(drift)
    raise ValueError(kind)


# ----------------------------------------------------------------------------- closed loop
def run_closed(fs, effects, ref_mm: np.ndarray, rng, noise_kind="white",
               ctrl_hz=200.0) -> tuple[np.ndarray, np.ndarray]:
    """A PI(D) loop of my own around the plant: returns (applied kV, measured mm).

    The controller runs at ctrl_hz on the noisy measurement, holds its command
    (zero-order hold), clamps it to [0, 9] kV and uses a static feed-forward r / G(0)."""
    n = ref_mm.size
    per = int(round(fs / ctrl_hz))
    chain = build_chain(fs, effects, "zoh", 0.0, v0=0.0, y0=0.0, m=1)
    noise = make_noise(noise_kind, n, fs, rng)
    g0 = pl.dc_gain(*pl.paper_tf())
    kp, ki, kd, tc = 0.5, 18.0, 0.002, 1.0 / ctrl_hz
    integ, e_prev = 0.0, 0.0
    u = np.zeros(n)
    y = np.zeros(n)
    ym = 0.0
    for k0 in range(0, n, per):
        r = ref_mm[k0]
        e = r - ym
        v_unsat = r / g0 + kp * e + ki * (integ + e * tc) + kd * (e - e_prev) / tc
        v = min(9.0, max(0.0, v_unsat))
        if v == v_unsat:  # conditional integration as anti-windup
            integ += e * tc
        e_prev = e
        k1 = min(n, k0 + per)
        u[k0:k1] = v
        y[k0:k1] = chain.run(u[k0:k1])
        ym = y[k1 - 1] + noise[k1 - 1]
    return u, y + noise


def closed_ref(fs: float, rng, dur_s: float) -> np.ndarray:
    """Reference (mm): the 2-4-6-4-2 mm step test, then random levels 1.5-7 mm."""
    parts = [np.full(int(2.0 * fs), lvl) for lvl in (2, 4, 6, 4, 2)]
    n = int(dur_s * fs)
    while sum(p.size for p in parts) < n:
        parts.append(np.full(int(rng.uniform(0.3, 2.0) * fs), rng.uniform(1.5, 7.0)))
    return np.concatenate(parts)[:n]


# ----------------------------------------------------------------------------- writers
def write_log(path: Path, fs: float, u: np.ndarray, y: np.ndarray, fmt: str) -> dict:
    """Write a log as CSV, MAT or MCAP; returns the selectors the CLI needs."""
    t = np.arange(u.size) / fs
    if fmt == "csv":
        p = path.with_suffix(".csv")
        np.savetxt(p, np.column_stack([t, u, y]), delimiter=",", header="t_s,voltage_kv,stroke_mm",
                   comments="", fmt=["%.7f", "%.6f", "%.6f"])
        return {"file": p.name, "args": []}
    if fmt == "mat":
        p = path.with_suffix(".mat")
        savemat(p, {"t_s": t[:, None], "voltage_kv": u[:, None], "stroke_mm": y[:, None]})
        return {"file": p.name, "args": []}
    if fmt == "mcap":
        from mcap_ros2.writer import Writer

        p = path.with_suffix(".mcap")
        t0 = 1_700_000_000_000_000_000
        with open(p, "wb") as fh:
            w = Writer(fh)
            sch = w.register_msgdef("std_msgs/msg/Float64", "float64 data")
            for i in range(u.size):
                ns = t0 + int(round(t[i] * 1e9))
                w.write_message(MCAP_IN, sch, {"data": float(u[i])}, log_time=ns, publish_time=ns, sequence=i)
                w.write_message(MCAP_OUT, sch, {"data": float(y[i])}, log_time=ns, publish_time=ns, sequence=i)
            w.finish()
        return {"file": p.name, "args": ["--input", MCAP_IN + ".data", "--output", MCAP_OUT + ".data"]}
    raise ValueError(fmt)


# ----------------------------------------------------------------------------- corpus
@dataclass
class Case:
    """One case of the corpus (what to simulate and how to write it)."""

    id: str
    kind: str  # 'diagnose' or 'ident'
    category: str  # effect_free, single, near_floor, pair, triple, ident
    fs: float
    fmt: str
    train: Design | None
    heldout: Design | None = None
    effects: list = field(default_factory=list)
    noise: str = "white"
    convention: str = "zoh"
    offset_frac: float = 0.0
    closed_loop: bool = False
    cl_dur_s: float = 40.0


# Effect forms with a clear ("strong") and a near-floor ("weak") size; the names are
# the contract's, the forms are this corpus's own.
FORMS = {
    "static_nonlinearity": [
        ("quadratic", {"blend": 0.6, "v_ref": 4.5}, {"blend": 0.006, "v_ref": 4.5}),
        ("knee", {"knee_kv": 4.0, "slope": 0.55}, {"knee_kv": 6.6, "slope": 0.96}),
        ("power", {"v_ref": 4.5, "exponent": 1.35}, {"v_ref": 4.5, "exponent": 1.01}),
    ],
    "asymmetric_dynamics": [
        ("dirlag_out", {"tau_up": 0.004, "tau_down": 0.06}, {"tau_up": 0.001, "tau_down": 0.0025}),
        ("dirlag_in", {"tau_up": 0.003, "tau_down": 0.05}, {"tau_up": 0.001, "tau_down": 0.002}),
        ("slew_down", {"down_mm_s": 22.0}, {"down_mm_s": 80.0}),
    ],
    "charge_drift": [
        ("creep_integral", {"c_mm_per_kvs": 0.004, "tau_s": 300.0}, {"c_mm_per_kvs": 0.000025, "tau_s": 300.0}),
        ("charge_gain", {"c": 0.25, "tau_s": 20.0}, {"c": 0.0015, "tau_s": 20.0}),
    ],
    "saturation": [
        ("clip_stroke", {"max_mm": None}, {"max_mm": None}),
        ("endstop_smooth", {"knee_mm": None, "width_mm": 0.3}, {"knee_mm": None, "width_mm": 1.5}),
        ("volt_clip", {"max_kv": None}, {"max_kv": None}),
        ("amp_slew", {"kv_s": 60.0}, {"kv_s": 200.0}),
    ],
    "time_delay": [
        ("transport", {"delay_s": 0.015}, {"delay_s": 0.0004}),
        ("pade", {"delay_s": 0.025}, {"delay_s": 0.0008}),
    ],
    "sensor_nonlinearity": [
        ("quadratic", {"a_per_mm": 0.04, "offset_mm": 0.1}, {"a_per_mm": 0.0003, "offset_mm": 0.0}),
        ("exponential", {"scale_mm": 9.0}, {"scale_mm": 400.0}),
        ("log", {"scale_mm": 8.0}, {"scale_mm": 400.0}),
    ],
    "load_mass": [
        ("pole_shift", {"pole_scale": 0.72}, {"pole_scale": 0.97}),
        ("same_damper", {"pole_scale": 0.75}, {"pole_scale": 0.96}),
    ],
    "hysteresis": [
        ("play", {"r_kv": 0.3}, {"r_kv": 0.012}),
        ("pi", {"radii": [0.0, 0.15, 0.3, 0.5], "weights": [0.4, 0.25, 0.2, 0.15]},
         {"radii": [0.0, 0.005, 0.01], "weights": [0.9, 0.05, 0.05]}),
        ("asym_pi", {"radii": [0.05, 0.2, 0.4], "weights": [0.3, 0.4, 0.3], "up_scale": 2.0},
         {"radii": [0.003, 0.006], "weights": [0.5, 0.5], "up_scale": 2.0}),
        ("duhem", {"alpha": 1.0, "scale_kv": 0.25}, {"alpha": 1.0, "scale_kv": 0.005}),
    ],
}


def _fill_levels(effects, u, y_nom):
    """Set levels that depend on the log (clip stroke/voltage, end-stop knee)."""
    out = []
    for name, form, p in effects:
        p = dict(p)
        if form == "clip_stroke" and p["max_mm"] is None:
            p["max_mm"] = round(float(np.quantile(y_nom, p.pop("_q", 0.85))), 3)
        if form == "endstop_smooth" and p["knee_mm"] is None:
            p["knee_mm"] = round(float(np.quantile(y_nom, p.pop("_q", 0.6))), 3)
        if form == "volt_clip" and p["max_kv"] is None:
            p["max_kv"] = round(float(np.quantile(u, p.pop("_q", 0.85))), 3)
        p.pop("_q", None)
        out.append((name, form, p))
    return out


def _eff(name, i, weak=False):
    f = FORMS[name][i % len(FORMS[name])]
    p = dict(f[2] if weak else f[1])
    if weak and name == "saturation":
        p["_q"] = 0.98
    return (name, f[0], p)


def corpus(rng, quick=False) -> list[Case]:
    """The list of cases, deterministic for the generator's random state."""
    C: list[Case] = []
    fmts = ["csv", "mat", "mcap"]
    rates = [200, 500, 1000, 2000, 1000, 200, 5000, 1000, 10000, 500]
    kinds = ["paper_chirp", "multisine", "prbs", "linear_chirp", "log_chirp", "random_steps"]

    def dtrain(kind, fs, i):
        offs = [[2, 4, 6], [3, 5], [2, 3.5, 5, 6.5], [2.5, 5]][i % 4]
        seg = 12.0 if fs >= 5000 else 16.0
        return Design(kind, offs, seg_s=seg, repeats=1, amp_kv=1.0,
                      settle_s=float(rng.choice([0.3, 1.0, 2.0])), precond_s=[0.0, 1.0][i % 2])

    def dheld(i):
        if i % 2 == 0:
            return Design("voltage_steps", [float(x) for x in rng.uniform(1.5, 7.0, 10).round(2)])
        return Design(kinds[(i + 3) % len(kinds)], [3.5, 5.5], seg_s=10.0, amp_kv=0.7, settle_s=0.5)

    def fmt_for(fs, i):
        return "mat" if fs >= 5000 else fmts[i % 3] if fs <= 1000 else fmts[i % 2]

    # Effect-free diagnose logs: noise x convention x timing offset x design x rate.
    noises = ["white", "coloured", "wander"]
    convs = [("zoh", 0.0), ("foh", 0.0), ("centred", 0.0), ("zoh", 0.3), ("zoh", 0.5), ("foh", 0.7)]
    for i in range(24):
        fs = rates[i % len(rates)]
        conv, off = convs[i % len(convs)]
        C.append(Case(f"free{i:02d}", "diagnose", "effect_free", fs, fmt_for(fs, i),
                      dtrain(kinds[i % len(kinds)], fs, i), dheld(i) if i % 6 != 5 else None,
                      noise=noises[(i // 2) % 3], convention=conv, offset_frac=off))
    # Single effects: two or more forms per name.
    i = 0
    for name, forms in FORMS.items():
        for j in range(min(3, len(forms))):
            fs = rates[(i + 3) % len(rates)]
            C.append(Case(f"single{i:02d}_{name}", "diagnose", "single", fs, fmt_for(fs, i),
                          dtrain(kinds[i % len(kinds)], fs, i), dheld(i), [_eff(name, j)],
                          noise="white" if i % 4 else "coloured"))
            i += 1
    # Near-floor: an effect under the noise; "none" or the right name are acceptable.
    for i, name in enumerate(FORMS):
        fs = rates[(i + 5) % len(rates)]
        C.append(Case(f"near{i:02d}_{name}", "diagnose", "near_floor", fs, fmt_for(fs, i),
                      dtrain(kinds[(i + 2) % len(kinds)], fs, i), dheld(i), [_eff(name, i + 1, weak=True)],
                      noise=noises[i % 3]))
    # Pairs and triples.
    pairs = [("static_nonlinearity", "time_delay"), ("hysteresis", "sensor_nonlinearity"),
             ("charge_drift", "load_mass"), ("asymmetric_dynamics", "saturation"),
             ("time_delay", "load_mass"), ("static_nonlinearity", "charge_drift"),
             ("hysteresis", "asymmetric_dynamics")]
    for i, (a, b) in enumerate(pairs):
        fs = rates[(i + 2) % len(rates)]
        C.append(Case(f"pair{i:02d}_{a}+{b}", "diagnose", "pair", fs, fmt_for(fs, i),
                      dtrain(kinds[(i + 1) % len(kinds)], fs, i), dheld(i), [_eff(a, i + 1), _eff(b, i)],
                      noise="white"))
    triples = [("static_nonlinearity", "charge_drift", "sensor_nonlinearity"),
               ("asymmetric_dynamics", "time_delay", "hysteresis"),
               ("load_mass", "saturation", "static_nonlinearity"),
               ("charge_drift", "hysteresis", "time_delay")]
    for i, tri in enumerate(triples):
        fs = [1000, 500, 2000, 200][i]
        C.append(Case(f"triple{i:02d}_" + "+".join(tri), "diagnose", "triple", fs, fmt_for(fs, i),
                      dtrain(kinds[(i + 4) % len(kinds)], fs, i), dheld(i),
                      [_eff(n, i + k) for k, n in enumerate(tri)], noise=["white", "coloured"][i % 2]))
    # Closed loop (applied voltage in, stroke out): two effect-free, two with an effect.
    for i, eff in enumerate([[], [], [_eff("static_nonlinearity", 0)], [_eff("asymmetric_dynamics", 1)]]):
        fs = [1000, 200, 1000, 200][i]
        cat = "effect_free" if not eff else "single"
        C.append(Case(f"closed{i:02d}" + ("_" + eff[0][0] if eff else ""), "diagnose", cat, fs,
                      ["csv", "mcap", "mat", "csv"][i], None, None, eff,
                      noise=["white", "coloured", "white", "wander"][i], closed_loop=True, cl_dur_s=45.0))

    # Identification: every design at 1 kHz and 200 Hz, a few at 100 Hz and 10 kHz.
    designs = [("paper_chirp", 1), ("paper_chirp", 3), ("linear_chirp", 1), ("linear_chirp", 3),
               ("log_chirp", 1), ("log_chirp", 3), ("multisine", 1), ("prbs", 1),
               ("random_steps", 1), ("voltage_steps", 1), ("closed_loop", 1)]
    offsets_sets = [[2, 3, 4, 5, 6, 7], [2, 4, 6], [3, 5, 7], [2, 3, 4, 5], [2.5, 4.5, 6.5]]
    plan = [(d, fs) for fs in (1000, 200) for d in designs]
    plan += [(("paper_chirp", 1), 100), (("multisine", 1), 100), (("paper_chirp", 3), 10000), (("prbs", 1), 10000)]
    for i, ((kind, rep), fs) in enumerate(plan):
        offs = offsets_sets[i % len(offsets_sets)]
        if rep == 3 or fs == 10000:
            offs = offs[:3] if fs < 10000 else [3, 6]
        settle = [0.5, 2.0, 5.0, 0.1, 1.0][i % 5]
        pre = [0.0, 1.0][(i // 2) % 2]
        if kind == "voltage_steps":
            d = Design(kind, [float(x) for x in rng.uniform(1.0, 7.5, 24).round(2)], precond_s=pre)
        elif kind == "closed_loop":
            d = None
        else:
            d = Design(kind, offs, seg_s=20.0, repeats=rep, settle_s=settle, precond_s=pre)
        fmt = "mat" if fs == 10000 else ["csv", "mcap"][i % 2] if fs <= 1000 else "csv"
        C.append(Case(f"id{i:02d}_{kind}{'x3' if rep == 3 else ''}_{fs}hz", "ident", "ident", fs, fmt, d,
                      closed_loop=d is None, cl_dur_s=60.0))
    # Cheap extra LTI multi-offset logs for the offset test's false-rejection rate.
    for i in range(22):
        kind = ["paper_chirp", "multisine", "linear_chirp", "prbs", "log_chirp"][i % 5]
        fs = [200, 500, 1000][i % 3]
        offs = sorted(rng.choice([2, 3, 4, 5, 6, 7], size=int(rng.integers(3, 5)), replace=False).tolist())
        d = Design(kind, offs, seg_s=12.0, settle_s=float(rng.choice([0.3, 1.0])), precond_s=[0.0, 1.0][i % 2])
        C.append(Case(f"lti{i:02d}_{kind}_{fs}hz", "ident", "ident_lti", fs, "csv", d))
    if quick:
        keep = ["free00", "free03", "single00", "single09", "near00", "pair00", "triple00", "closed00",
                "id00", "id09"]
        C = [c for c in C if any(c.id.startswith(k) for k in keep)]
    return C


def generate_case(c: Case, root: Path, seed: int) -> dict:
    """Simulate one case, write its files and its label; returns the label."""
    # A stable per-case stream (str hash() is salted per process).
    rng = np.random.default_rng([seed] + [ord(ch) for ch in c.id])
    cdir = root / "cases" / c.id
    cdir.mkdir(parents=True, exist_ok=True)
    label = {"id": c.id, "kind": c.kind, "category": c.category, "fs": c.fs, "format": c.fmt,
             "noise": c.noise, "convention": c.convention, "timing_offset_s": c.offset_frac / c.fs,
             "closed_loop": c.closed_loop, "noise_mm": NOISE_MM}
    if c.closed_loop:
        ref = closed_ref(c.fs, rng, c.cl_dur_s)
        label["design"] = "closed_loop_steps"
        u_tr, y_tr = run_closed(c.fs, c.effects, ref, rng, c.noise)
        eff = c.effects
        y_nom_tr = run_open(c.fs, u_tr, [])
        held = None
        if c.kind == "diagnose":
            ref2 = closed_ref(c.fs, np.random.default_rng(rng.integers(1 << 30)), 25.0)[::-1].copy()
            held = run_closed(c.fs, c.effects, ref2, rng, c.noise)
    else:
        u_tr = build_input(c.train, c.fs, rng)
        label["design"] = c.train.kind + (f"x{c.train.repeats}" if c.train.repeats > 1 else "")
        label["offsets_kv"] = c.train.offsets if c.train.kind != "voltage_steps" else []
        label["precond"] = bool(c.train.precond_s)
        label["settle_s"] = c.train.settle_s
        y_nom_tr = run_open(c.fs, u_tr, [])
        eff = _fill_levels(c.effects, u_tr, y_nom_tr)
        y_tr = run_open(c.fs, u_tr, eff, c.convention, c.offset_frac) + make_noise(c.noise, u_tr.size, c.fs, rng)
        held = None
        if c.heldout is not None:
            u_h = build_input(c.heldout, c.fs, rng)
            y_h = run_open(c.fs, u_h, eff, c.convention, c.offset_frac) + make_noise(c.noise, u_h.size, c.fs, rng)
            held = (u_h, y_h)
            label["heldout_design"] = c.heldout.kind
    # How big the effects are against the noise, on the training input.
    if c.effects:
        y_eff = run_open(c.fs, u_tr, eff)
        label["effect_rms_mm"] = float(np.sqrt(np.mean((y_eff - y_nom_tr) ** 2)))
    label["effects"] = [{"name": n, "form": f, "params": p} for n, f, p in eff]
    label["train"] = write_log(cdir / "train", c.fs, u_tr, y_tr, c.fmt)
    label["n_samples"] = int(u_tr.size)
    if held is not None:
        label["heldout"] = write_log(cdir / "heldout", c.fs, held[0], held[1], c.fmt)
    num, den = pl.paper_tf()
    (cdir / "model.json").write_text(json.dumps({"num": num.tolist(), "den": den.tolist()}))
    return label


def main(argv=None) -> int:
    """Command line: write the corpus under --out."""
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", default=str(Path(__file__).parent / "out"))
    ap.add_argument("--seed", type=int, default=14)
    ap.add_argument("--quick", action="store_true", help="only a ~10-case subset")
    ap.add_argument("--only", default="", help="comma-separated case id prefixes")
    a = ap.parse_args(argv)
    root = Path(a.out)
    (root / "labels").mkdir(parents=True, exist_ok=True)
    cases = corpus(np.random.default_rng(a.seed), a.quick)
    if a.only:
        cases = [c for c in cases if any(c.id.startswith(p) for p in a.only.split(","))]
    index = []
    for c in cases:
        lab = generate_case(c, root, a.seed)
        (root / "labels" / f"{c.id}.json").write_text(json.dumps(lab, indent=1))
        index.append(c.id)
        er = lab.get("effect_rms_mm")
        print(f"{c.id:60s} {c.fs:6.0f} Hz {lab['n_samples']:8d} samples {c.fmt:4s}"
              + (f"  effect rms {er:.4f} mm" if er is not None else ""), flush=True)
    (root / "index.json").write_text(json.dumps({"seed": a.seed, "cases": index}, indent=1))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
