"""Effect-free logs from a simulator of its own, with sensor noise forms the diagnosis was not calibrated on
(a tuning set, not verification).

The plant is the paper's continuous P(s) (17), written out here from its numbers (``paper-numbers.md``), not
read from :mod:`hasel.paper`, and simulated without any of hasel's simulators (``LinearSim``, ``lti``,
``plant``): scipy's exact zero-order-hold discretisation on a grid ``FINE`` times finer than the log, driven by
the command held (or, for ``foh``, linearly interpolated) on that grid; the log's output samples are taken from
the fine grid at the convention's instant:

- ``zoh``: the output at ``t_k`` (the command ``u_k`` starts there);
- ``centred``: at ``t_k + dt/2``;
- ``skew``: at ``t_k + s dt``, ``s`` drawn in -0.45..0.45 (rounded to the fine grid);
- ``foh``: the command linearly interpolated between samples (not for closed loop: a controller holds).

Designs: ``paper`` (the paper's chirp protocol (3)-(5): DC offsets among 2..7 kV, ascending or in a random order,
1-3 chirps per offset with the paper's phase ``2 pi k t^2``, 1 kV amplitude, short chirps of 2-4 s so that a log
stays short, settle segments of 0.3-3 s, with or without the -1 kV pre-conditioning reversal before each offset),
``linchirp`` / ``logchirp`` (textbook sweeps 0.2-20 Hz around 2-4 offsets), ``multisine``, ``prbs``, ``levels``
(random levels held 0.05-1 s), ``steps`` (voltage steps held 0.5-3 s) and ``closed_loop`` (a dual-mode PI on the
measured stroke tracking steps in 2-6 mm, the applied voltage recorded). Rates 100 Hz-10 kHz, 15-60 s.

Noise forms (the white part 2-12 um unless said), reasoned from real sensors:

- ``quant``: output quantisation, 10-16 bits over a range of 9.9 (the laser: 3 mm/V x 3.3 V), 12.2 or 20 mm,
  with white noise of 0.15-1 step (so the step is comparable to or larger than the noise);
- ``hetero``: white noise whose sd grows with the stroke (x1 at 0, x2-5 at full scale);
- ``ar1``: AR(1) with a correlation time of 0.1-3 s (a thermal or mechanical sensor drift) plus white;
- ``walk``: a random-walk offset (peak 1-5x the white rms);
- ``wander``: a slow offset whose timescale matches the design's level changes (a sine whose period is two
  level segments, or a warm-up ``1 - exp(-t/tau)`` over the log: level and time confounded), 1-5x white;
- ``pink``: 1/f noise (0.01 Hz to Nyquist);
- ``spikes``: white plus rare spikes (0.05-0.3 % of samples, 5-20x white);
- ``hum``: mains 50 or 60 Hz (+-0.2 Hz) and its third harmonic sampled at the log's rate (aliased below it);
- ``vnoise`` / ``vquant``: the recorded voltage is noisy (10-40 V rms) or quantised (10-12 bits over 0-10 kV),
  the plant saw the clean command;
- ``jitter``: the sampling instants jitter by 5-30 % of a sample (recorded stamps nominal), or the stamps jitter
  (samples exact);
- ``mix_*``: quantisation beside wander, hetero beside AR(1), walk beside coarse quantisation.

Some logs get a held-out log of another design (same rate, noise and convention).

Run ``python bench/tune_diag/free_indep.py --out DIR --seed 11 [--only SUBSTR,...] [--list]``: one line per log,
each round's best candidate with its block score t, coloured z and over_floor, a table of false alarms by name,
design, rate, form and convention, and ``DIR/results.json``. Seed 11 is for tuning; seed 12 is held back.
"""
from __future__ import annotations

import argparse
import json
import math
import os
import sys
import time
from collections import Counter

import numpy as np
from scipy import signal

#: P(s) (17) of the paper, kV -> mm: K (s+50.27)(s+62.83)(s+628.3)(s^2+w^2) / [(s+18.85)(s+56.55)(s^2+230s+w^2)^2]
_K, _W = 10.836, 122.2
NUM = _K * np.polymul(np.polymul(np.polymul([1.0, 50.27], [1.0, 62.83]), [1.0, 628.3]), [1.0, 0.0, _W ** 2])
DEN = np.polymul(np.polymul([1.0, 18.85], [1.0, 56.55]), np.polymul([1.0, 230.0, _W ** 2], [1.0, 230.0, _W ** 2]))
G0 = float(NUM[-1] / DEN[-1])  # static gain, mm/kV

RATES = (100.0, 200.0, 500.0, 1000.0, 2000.0, 5000.0, 10000.0)
DESIGNS = ("paper", "paper_pre", "logchirp", "linchirp", "multisine", "prbs", "levels", "steps", "closed_loop")
CONVS = ("zoh", "foh", "centred", "skew")
FORMS = ("quant", "hetero", "ar1", "walk", "wander", "pink", "spikes", "hum", "vnoise", "vquant", "jitter",
         "mix_quant_wander", "mix_hetero_ar1", "mix_walk_quant")
N_LOGS = 36


def fine_factor(rate_hz: float) -> int:
    """Fine-grid factor of the simulation for a log rate (Hz): 20 up to 2 kHz, 10 above."""
    return 20 if rate_hz <= 2000.0 else 10


def simulate(u: np.ndarray, rate_hz: float, conv: str, skew: float = 0.0, jitter: np.ndarray | None = None
             ) -> np.ndarray:
    """P(s)'s noise-free stroke (mm) at the log's sample instants for command ``u`` (kV) at ``rate_hz``.

    The command is held (``foh``: linearly interpolated) on a grid ``fine_factor`` times finer, simulated with
    the exact zero-order-hold discretisation of P(s) there (scipy), started at rest at the first command's
    steady state; the output is read at ``t_k + offset`` (``offset`` from ``conv`` and ``skew``, fractions of a
    sample, plus ``jitter`` per sample) rounded to the fine grid."""
    m = fine_factor(rate_hz)
    n = u.size
    if conv == "foh":
        fine = np.interp(np.arange(n * m) / m, np.arange(n), u)
    else:
        fine = np.repeat(u, m)
    # start at rest at u[0]: the deviation from u[0] through the fine grid's exact ZOH impulse response
    # (every mode has decayed by 1e-14 within 2 s), convolved by FFT
    yf = signal.fftconvolve(fine - u[0], impulse(rate_hz * m))[:fine.size] + G0 * u[0]
    off = {"zoh": 0.0, "foh": 0.0, "centred": 0.5, "skew": skew}[conv]
    pos = (np.arange(n) + off + (jitter if jitter is not None else 0.0)) * m
    idx = np.clip(np.round(pos).astype(int), 0, yf.size - 1)
    return yf[idx]


_IMPULSE: dict = {}


def impulse(fs_hz: float, span_s: float = 2.0) -> np.ndarray:
    """Impulse response of P(s) discretised exactly under a zero-order hold at ``fs_hz``: ``h[i] = C A^(i-1) B``
    (``h[0] = 0``, P(s) is strictly proper), ``span_s`` long (mm per kV-sample)."""
    if fs_hz not in _IMPULSE:
        a, b, c, _, _ = signal.cont2discrete(signal.tf2ss(NUM, DEN), 1.0 / fs_hz, method="zoh")
        n = int(round(span_s * fs_hz))
        h = np.zeros(n)
        x = b[:, 0].copy()
        cc = c[0]
        for i in range(1, n):
            h[i] = cc @ x
            x = a @ x
        _IMPULSE[fs_hz] = h
    return _IMPULSE[fs_hz]


def _chirp_paper(rng, rate, v, amp, t_tot, f_f):
    t = np.arange(int(round(t_tot * rate))) / rate
    k = f_f / t_tot  # the paper's formula: phase 2 pi k t^2, instantaneous frequency 2 k t
    return v + amp * np.sin(2 * np.pi * k * t * t)


def command(design: str, rng: np.random.Generator, rate: float, dur: float) -> np.ndarray:
    """An open-loop command (kV) of ``design`` at ``rate`` (Hz), about ``dur`` s long."""
    n = int(round(dur * rate))

    def hold(v, s):
        return np.full(max(1, int(round(s * rate))), float(v))

    if design.startswith("paper"):
        pre = design == "paper_pre"
        n_off = int(rng.integers(3, 7))
        offs = sorted(rng.choice(np.arange(2.0, 8.0), n_off, replace=False))
        if rng.random() < 0.3:
            rng.shuffle(offs)
        reps = int(rng.integers(1, 4))
        seg_s = dur / n_off
        parts = []
        for v in offs:
            settle = float(rng.uniform(0.3, 3.0))
            if pre:
                parts.append(hold(-1.0, float(rng.uniform(0.3, 1.0))))
                parts.append(hold(0.0, float(rng.uniform(0.1, 0.5))))
            parts.append(hold(v, settle))
            t_tot = max(1.0, (seg_s - settle) / reps)
            for _ in range(reps):
                parts.append(_chirp_paper(rng, rate, v, 1.0, t_tot, 20.0))
        return np.concatenate(parts)
    if design in ("linchirp", "logchirp"):
        n_off = int(rng.integers(2, 5))
        offs = rng.choice(np.arange(2.0, 7.0), n_off, replace=False)
        if rng.random() < 0.5:
            offs = np.sort(offs)
        amp = float(rng.uniform(0.6, 1.2))
        seg = dur / n_off
        parts = []
        for v in offs:
            parts.append(hold(v, 0.5))
            t = np.arange(int(round((seg - 0.5) * rate))) / rate
            f0, f1 = 0.2, 20.0
            if design == "linchirp":
                x = signal.chirp(t, f0, t[-1], f1, method="linear")
            else:
                x = signal.chirp(t, f0, t[-1], f1, method="logarithmic")
            parts.append(v + amp * x)
        return np.concatenate(parts)
    t = np.arange(n) / rate
    if design == "multisine":
        f = np.geomspace(0.1, 15.0, 40)
        x = sum(np.cos(2 * np.pi * fi * t + float(rng.uniform(0, 2 * np.pi))) for fi in f)
        return float(rng.uniform(3.0, 5.0)) + float(rng.uniform(0.5, 1.2)) * x / x.std()
    if design == "prbs":
        clock = max(1, int(round(float(rng.uniform(0.005, 0.05)) * rate)))
        bits = rng.integers(0, 2, n // clock + 1)
        lev = np.repeat(2.0 * bits - 1.0, clock)[:n]
        return float(rng.uniform(2.5, 5.5)) + float(rng.uniform(0.5, 1.5)) * lev
    if design in ("levels", "steps"):
        lo, hi = (0.05, 1.0) if design == "levels" else (0.5, 3.0)
        out = []
        while sum(x.size for x in out) < n:
            out.append(hold(float(rng.uniform(0.5, 8.0)) if design == "levels" else float(rng.integers(0, 9)),
                            float(rng.uniform(lo, hi))))
        return np.concatenate(out)[:n]
    raise ValueError(design)


def closed_loop(rng: np.random.Generator, rate: float, dur: float, measure) -> np.ndarray:
    """A dual-mode PI (the paper's C+ / C- without their tiny derivative terms, 40 Hz first-order low-pass on the
    feedback) at ``rate`` on P(s) tracking stroke steps in 2-6 mm held 1-3 s; ``measure(z, k)`` gives the
    measured stroke of sample ``k``. Returns the applied voltage (kV), clamped to 0-9 kV."""
    n = int(round(dur * rate))
    dt = 1.0 / rate
    a, b, c, _, _ = signal.cont2discrete(signal.tf2ss(NUM, DEN), dt, method="zoh")
    ref = np.empty(n)
    i = 0
    while i < n:
        m = int(rng.uniform(1.0, 3.0) * rate)
        ref[i:i + m] = float(rng.uniform(2.0, 6.0))
        i += m
    u0 = ref[0] / G0
    x = np.linalg.solve(np.eye(a.shape[0]) - a, b[:, 0] * u0)
    integ_p, integ_m = u0, u0
    alpha = 1.0 - math.exp(-2 * math.pi * 40.0 * dt)
    zf = ref[0]
    u = np.empty(n)
    cc, bb = c[0], b[:, 0]
    e_prev = 0.0
    integ = u0
    for k in range(n):
        z = float(cc @ x)
        zf += alpha * (measure(z, k) - zf)
        e = ref[k] - zf
        kp, ki = (1.15, 25.0) if e >= 0 else (1.25, 26.0)
        integ += ki * dt * 0.5 * (e + e_prev)
        e_prev = e
        uk = integ + kp * e
        if uk > 9.0 or uk < 0.0:  # conditional integration: undo the step that winds up
            integ -= ki * dt * 0.5 * (e + e_prev)
        u[k] = min(max(uk, 0.0), 9.0)
        x = a @ x + bb * u[k]
    del integ_p, integ_m
    return u


class Noise:
    """A noise form's realisation for ``n`` samples at ``rate``: additive parts independent of the stroke,
    a level-dependent white part and an output quantiser; ``measure(z)`` applies them."""

    def __init__(self, form: str, rng: np.random.Generator, n: int, rate: float, seg_s: float, dur: float):
        self.form, self.n, self.rate = form, n, rate
        self.sd = float(rng.uniform(0.002, 0.012))
        self.add = np.zeros(n)
        self.hetero = 0.0
        self.lsb = None
        self.v_noise, self.v_lsb = 0.0, None
        self.jitter_sample = None
        self.jitter_stamp = None
        self.desc = []
        parts = form.split("_")[1:] if form.startswith("mix") else [form]
        t = np.arange(n) / rate
        for p in parts:
            if p == "quant":
                rng_mm = float(rng.choice([9.9, 12.2, 20.0]))
                bits = int(rng.integers(10, 17))
                self.lsb = rng_mm / 2 ** bits
                self.sd = float(rng.uniform(0.15, 1.0)) * self.lsb
                self.desc.append(f"{bits} bit over {rng_mm:g} mm (step {self.lsb * 1e3:.2f} um)")
            elif p == "hetero":
                self.hetero = float(rng.uniform(1.0, 4.0)) / 12.2
                self.desc.append(f"sd x{1 + self.hetero * 12.2:.1f} at 12.2 mm")
            elif p == "ar1":
                tau = float(rng.uniform(0.1, 3.0))
                a = math.exp(-1.0 / (tau * rate))
                x = signal.lfilter([1.0], [1.0, -a], rng.standard_normal(n))
                k = float(rng.uniform(1.0, 3.0))
                self.add += k * self.sd * x / x.std()
                self.desc.append(f"AR(1) tau {tau:.2f} s, {k:.1f}x white")
            elif p == "walk":
                w = signal.detrend(np.cumsum(rng.standard_normal(n)), type="constant")
                k = float(rng.uniform(1.0, 5.0))
                self.add += w / np.abs(w).max() * k * self.sd
                self.desc.append(f"walk peak {k:.1f}x white")
            elif p == "wander":
                k = float(rng.uniform(1.0, 5.0))
                if rng.random() < 0.5:
                    per = 2.0 * seg_s
                    s = np.sin(2 * np.pi * t / per + float(rng.uniform(0, 2 * np.pi)))
                    self.desc.append(f"sine wander period {per:.1f} s, {k:.1f}x white")
                else:
                    tau = float(rng.uniform(0.2, 1.0)) * dur
                    s = 1.0 - np.exp(-t / tau)
                    s = s - s.mean()
                    self.desc.append(f"warm-up tau {tau:.0f} s, {k:.1f}x white")
                self.add += k * self.sd * s / np.abs(s).max()
            elif p == "pink":
                f = np.fft.rfftfreq(n, 1.0 / rate)
                g = 1.0 / np.sqrt(np.maximum(f, 0.01))
                x = np.fft.irfft(np.fft.rfft(rng.standard_normal(n)) * g, n)
                k = float(rng.uniform(1.0, 3.0))
                self.add += k * self.sd * x / x.std()
                self.desc.append(f"pink {k:.1f}x white")
            elif p == "spikes":
                share = float(rng.uniform(0.0005, 0.003))
                idx = rng.random(n) < share
                self.add[idx] += rng.choice([-1.0, 1.0], idx.sum()) * rng.uniform(5, 20, idx.sum()) * self.sd
                self.desc.append(f"spikes {100 * share:.2f} %")
            elif p == "hum":
                f = float(rng.choice([50.0, 60.0])) + float(rng.uniform(-0.2, 0.2))
                k = float(rng.uniform(1.0, 3.0))
                self.add += k * self.sd * (np.sin(2 * np.pi * f * t + rng.uniform(0, 6.3))
                                           + 0.3 * np.sin(2 * np.pi * 3 * f * t + rng.uniform(0, 6.3)))
                self.desc.append(f"hum {f:.2f} Hz {k:.1f}x white")
            elif p == "vnoise":
                self.v_noise = float(rng.uniform(0.01, 0.04))
                self.desc.append(f"voltage noise {self.v_noise * 1e3:.0f} V rms")
            elif p == "vquant":
                bits = int(rng.integers(10, 13))
                self.v_lsb = 10.0 / 2 ** bits
                self.desc.append(f"voltage {bits} bit over 10 kV")
            elif p == "jitter":
                j = float(rng.uniform(0.05, 0.3))
                if rng.random() < 0.5:
                    self.jitter_sample = j * rng.uniform(-1, 1, n)
                    self.desc.append(f"sampling jitter +-{j:.2f} sample")
                else:
                    self.jitter_stamp = j * rng.uniform(-1, 1, n) / rate
                    self.desc.append(f"stamp jitter +-{j:.2f} sample")
            else:
                raise ValueError(p)
        self.white = rng.standard_normal(n)
        self.vwhite = rng.standard_normal(n)

    def measure(self, z, k=None):
        """Measured stroke (mm) of the true stroke ``z`` (mm): whole array, or sample ``k``."""
        sl = slice(None) if k is None else k
        y = z + self.add[sl] + self.sd * (1.0 + self.hetero * np.abs(z)) * self.white[sl]
        if self.lsb is not None:
            y = np.round(y / self.lsb) * self.lsb
        return y

    def record_voltage(self, u: np.ndarray) -> np.ndarray:
        """The recorded voltage (kV) of the applied ``u``."""
        v = u + self.v_noise * self.vwhite[:u.size]
        if self.v_lsb is not None:
            v = np.round(v / self.v_lsb) * self.v_lsb
        return v


def _one_log(rng, design, rate, dur, conv, skew, form):
    seg_s = dur / 4.0 if design not in ("levels", "steps", "closed_loop", "prbs", "multisine") else 1.5
    if design == "closed_loop":
        nz = Noise(form, rng, int(round(dur * rate)), rate, seg_s, dur)
        u = closed_loop(rng, rate, dur, lambda z, k: float(nz.measure(np.array([z]), slice(k, k + 1))[0]))
        if conv == "foh":
            conv = "zoh"
    else:
        u = command(design, rng, rate, dur)
        nz = Noise(form, rng, u.size, rate, seg_s, u.size / rate)
    z = simulate(u, rate, conv, skew, nz.jitter_sample[:u.size] if nz.jitter_sample is not None else None)
    y = nz.measure(z, slice(0, u.size))
    t = np.arange(u.size) / rate
    if nz.jitter_stamp is not None:
        t = t + nz.jitter_stamp[:u.size]
        t = np.maximum.accumulate(t + 1e-9 * np.arange(u.size))
    return t, nz.record_voltage(u), y, conv, nz


def make_one(seed: int, i: int) -> tuple[dict, dict]:
    """Log ``i`` of seed ``seed``: (arrays for the ``.npz``, its description)."""
    rng = np.random.default_rng([seed, 900 + i])
    form = FORMS[i % len(FORMS)]
    design = DESIGNS[(i * 5 + seed) % len(DESIGNS)]
    rate = RATES[(i * 3 + seed) % len(RATES)]
    conv = CONVS[(i + seed // 2) % len(CONVS)]
    skew = float(rng.uniform(-0.45, 0.45))
    # short at high rates (the diagnosis time grows with the working samples), up to 60 s at 100-200 Hz
    dur = float(rng.uniform(30.0, 60.0)) if rate <= 200 else float(rng.uniform(15.0, 30.0)) if rate <= 1000 \
        else float(rng.uniform(15.0, 20.0))
    t, u, y, conv_used, nz = _one_log(rng, design, rate, dur, conv, skew, form)
    arrays = {"t_s": t, "voltage_kv": u, "stroke_mm": y, "num": NUM, "den": DEN}
    held = None
    if rng.random() < 0.25:
        held = DESIGNS[int(rng.integers(len(DESIGNS)))]
        if held == design:
            held = "multisine" if design != "multisine" else "steps"
        th, uh, yh, _, _ = _one_log(rng, held, rate, float(rng.uniform(10.0, 15.0)), conv_used, skew, form)
        arrays.update({"h_t_s": th, "h_voltage_kv": uh, "h_stroke_mm": yh})
    desc = {"form": form, "design": design, "rate": rate,
            "conv": conv_used + (f"{skew:+.2f}" if conv_used == "skew" else ""), "held": held,
            "dur": round(float(t[-1] - t[0]), 1), "labels": [], "truth": "; ".join(nz.desc),
            "white_um": round(nz.sd * 1e3, 2)}
    return arrays, desc


def make(directory: str, seed: int = 11, n_logs: int = N_LOGS, indices: list[int] | None = None) -> list[dict]:
    """Write ``n_logs`` effect-free logs (``.npz``: t_s, voltage_kv, stroke_mm, num, den, and optionally the
    held-out log's h_t_s, h_voltage_kv, h_stroke_mm) to ``directory`` (:func:`make_one`); returns their
    descriptions (only logs ``indices`` when given)."""
    out = []
    for i in (range(n_logs) if indices is None else indices):
        arrays, desc = make_one(seed, i)
        path = os.path.join(directory, f"indep_{i:02d}_{desc['form']}.npz")
        np.savez_compressed(path, **arrays)
        out.append({"path": path, **desc})
    return out


def run(cs: list[dict], say=print) -> list[dict]:
    """Diagnose each log with the exact P(s) (one process), recording the rounds and the progress lines."""
    from hasel.diagnose import core, pool

    pool.set_jobs(1)
    rows = []
    for c in cs:
        d = np.load(c["path"])
        trace: list[str] = []
        held = (d["h_t_s"], d["h_voltage_kv"], d["h_stroke_mm"]) if "h_t_s" in d else None
        t0 = time.perf_counter()
        try:
            v = core.diagnose(d["t_s"], d["voltage_kv"], d["stroke_mm"], heldout=held,
                              model={"num": d["num"].tolist(), "den": d["den"].tolist()}, units=("kV", "mm"),
                              options=core.DiagnoseOptions(progress=trace.append, jobs=1)
                              if "jobs" in core.DiagnoseOptions.__dataclass_fields__
                              else core.DiagnoseOptions(progress=trace.append))
            r = {"names": v.names, "nominal": v.heldout["nrmse_nominal"], "augmented": v.heldout["nrmse_augmented"],
                 "floor": v.noise_floor_nrmse, "dropped": [x["name"] for x in v.dropped],
                 "rounds": [{k: x.get(k) for k in ("best", "gain", "gap_share", "nominal_gap_share", "t_block",
                                                   "z_coloured", "over_floor", "accepted")} for x in v.rounds]}
        except Exception as err:  # noqa: BLE001 - a crash is a result
            r = {"names": [], "error": f"{type(err).__name__}: {err}"}
        r.update({k: c[k] for k in ("form", "design", "rate", "conv", "held", "truth", "dur")},
                 log=os.path.basename(c["path"]), seconds=time.perf_counter() - t0)
        with open(os.path.splitext(c["path"])[0] + "_trace.txt", "w") as fh:
            fh.write("\n".join(trace) + "\n")
        rows.append(r)
        say(f"{r['log']:28s} {c['design']:11s} {c['rate']:6g} Hz {r['conv']:10s} held {str(c['held']):11s} "
            f"named {','.join(r['names']) or 'none':30s} {r['seconds']:.1f} s {r.get('error', '')}  [{c['truth']}]")
        f3 = lambda v: "-" if v is None else f"{v:.3g}"  # noqa: E731
        for x in r.get("rounds", []):
            say(f"   round best {x['best']} gain {f3(x['gain'])} t_block {f3(x['t_block'])} z_col "
                f"{f3(x['z_coloured'])} over_floor {f3(x['over_floor'])} accepted {x['accepted']}")
    return rows


def table(rows: list[dict]) -> dict:
    """False alarms (logs naming any effect) overall and by name, design, rate, form and convention."""
    fa = [r for r in rows if r["names"]]
    out = {"false_alarms": f"{len(fa)}/{len(rows)}", "errors": sum("error" in r for r in rows),
           "seconds_mean": float(np.mean([r["seconds"] for r in rows])) if rows else 0.0,
           "by_name": dict(Counter(n for r in fa for n in r["names"]))}
    for key in ("design", "rate", "form"):
        out[f"by_{key}"] = {str(k): f"{sum(1 for r in fa if r[key] == k)}/{sum(1 for r in rows if r[key] == k)}"
                            for k in sorted({r[key] for r in rows}, key=str)}
    conv = lambda r: r["conv"][:4]  # noqa: E731
    out["by_conv"] = {k: f"{sum(1 for r in fa if conv(r) == k)}/{sum(1 for r in rows if conv(r) == k)}"
                      for k in sorted({conv(r) for r in rows})}
    return out


def main(argv: list[str] | None = None) -> int:
    """``python bench/tune_diag/free_indep.py --out DIR [--seed S] [--only SUBSTR,...] [--list]``."""
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--out", required=True)
    p.add_argument("--seed", type=int, default=11)
    p.add_argument("--n", type=int, default=N_LOGS)
    p.add_argument("--only", default="", help="comma-separated substrings of log names / designs to run")
    p.add_argument("--list", action="store_true", help="write and list the logs, do not diagnose")
    p.add_argument("--index", default="", help="comma-separated log indices to write and run (default: all)")
    a = p.parse_args(argv)
    os.makedirs(a.out, exist_ok=True)
    cs = make(a.out, a.seed, a.n, [int(x) for x in a.index.split(",")] if a.index else None)
    if a.only:
        keys = a.only.split(",")
        cs = [c for c in cs if any(k in os.path.basename(c["path"]) or k == c["design"] for k in keys)]
    if a.list:
        for c in cs:
            print(os.path.basename(c["path"]), c["design"], c["rate"], c["conv"], c["held"], c["dur"], c["truth"])
        return 0
    rows = run(cs, lambda m: (print(m), sys.stdout.flush()))
    s = table(rows)
    print(json.dumps(s, indent=1))
    with open(os.path.join(a.out, "results.json"), "w") as fh:
        json.dump({"summary": s, "rows": rows}, fh, indent=1, default=str)
    return 0


if __name__ == "__main__":
    sys.exit(main())
