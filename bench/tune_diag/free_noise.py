"""Effect-free tuning logs with noise forms the diagnosis was not calibrated on (a tuning set, not verification).

The acceptance tests of :mod:`hasel.diagnose` (``t_min``, ``zc_min``, the coloured-noise z) and
its noise floor were calibrated on :func:`hasel_bench.othersim.make_free_case` (white, a
first-order low-pass at 2-20 Hz plus a white tenth, a slow offset wander of 2-6x the white
level; 12-bit laser quantisation; 200 Hz-5 kHz). Here the exact P(s)
(:func:`hasel.paper.plant_tf`) is simulated with :class:`hasel.diagnose.prep.LinearSim` and
measured with:

- ``ar1_<pole>``: AR(1) noise of pole 0.5-0.99 per *sample* (so its corner moves with the rate);
- ``pink``: 1/f-like noise (white shaped by ``1/sqrt(f)`` from 0.02 Hz to Nyquist);
- ``walk``: white plus a random-walk sensor offset (peak 0.5-3x the white rms);
- ``sines``: white plus a sum of three slow sinusoids 0.02-0.3 Hz (peak 0.5-3x the white rms);
- ``quant<bits>``: small white noise (0.5-3 um) and the output quantised with 10-14 bits over
  the stroke range (0 to P(0) x 9 kV = 12.2 mm: 11.9 um to 0.74 um steps);
- ``mix_*``: combinations of these.

No quantisation except where named. Designs: the paper protocol (othersim's short excitation),
a random-phase multisine, a binary PRBS, random levels, PI closed-loop steps. Rates 200 Hz to
10 kHz; sampling conventions: ``zoh`` (offset 0), ``foh`` (input linearly interpolated, simulated
at 4x and decimated), ``centred`` (offset 0.5) and ``skew`` (a fractional offset -0.45..0.45).

``--quiet`` writes instead a grid of quiet logs (white 0.5 or 1.5 um, no quantisation, 1-10 kHz,
every design), where the block means' deterministic error shows (see ``RESULT-e-free.md``).

Run ``python bench/tune_diag/free_noise.py --out DIR [--only SUBSTR,...] [--quiet]``: one line per log
(named effects, and for each round the best candidate, block score, coloured z, residual over
floor) and ``DIR/results.json`` (:func:`cases.finish`); ``DIR/trace_<i>.txt`` holds each log's
progress lines.
"""
from __future__ import annotations

import argparse
import math
import os
import sys

import numpy as np
from scipy import signal

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import cases  # noqa: E402  (bench/tune_diag/cases.py: run, finish)
from hasel import paper  # noqa: E402
from hasel.diagnose.prep import LinearSim  # noqa: E402
from hasel_bench import othersim as o  # noqa: E402

RATES = (200.0, 1000.0, 2000.0, 5000.0, 10000.0)
DESIGNS = ("paper", "multisine", "prbs", "levels", "closed_loop")
CONVS = ("zoh", "foh", "centred", "skew")
FORMS = ("ar1_0.5", "ar1_0.8", "ar1_0.9", "ar1_0.95", "ar1_0.99", "pink", "walk", "sines",
         "quant10", "quant12", "quant14", "mix_ar0.9_walk_q12", "mix_pink_sines_q11")
PER_FORM = 3
#: Stroke range, mm, over which the ``quant`` forms quantise: P(0) x the amplifier's top voltage (12.2 mm).
STROKE_MM = float(np.polyval(paper.plant_tf()[0], 0.0) / np.polyval(paper.plant_tf()[1], 0.0)) * paper.V_MAX_KV


def duration_s(rate_hz: float) -> float:
    """Log length, s, for a rate (Hz): 40 s at 200 Hz down to 10 s at 10 kHz."""
    return {200.0: 40.0, 1000.0: 30.0, 2000.0: 20.0, 5000.0: 15.0, 10000.0: 10.0}[rate_hz]


def command(design: str, rng: np.random.Generator, rate_hz: float, dur_s: float) -> np.ndarray:
    """An open-loop command (kV) of ``design`` (not ``closed_loop``) at ``rate_hz``, about ``dur_s`` long."""
    n = int(round(dur_s * rate_hz))
    if design == "paper":
        return o.excitation(rng, rate_hz, short=True)[0]
    if design == "multisine":
        return o._design_input("multisine", rng, rate_hz, dur_s)
    if design == "levels":  # random levels held 0.05-0.6 s
        return o._design_input("prbs", rng, rate_hz, dur_s)
    if design == "prbs":  # binary +-A around an offset, clock 10-40 ms, 9-bit LFSR
        clock = max(1, int(round(float(rng.uniform(0.01, 0.04)) * rate_hz)))
        reg = int(rng.integers(1, 511))
        bits = []
        for _ in range(n // clock + 1):
            b = ((reg >> 8) ^ (reg >> 4)) & 1
            reg = ((reg << 1) | b) & 0x1FF
            bits.append(b)
        lev = np.repeat(2.0 * np.array(bits, float) - 1.0, clock)[:n]
        return float(rng.uniform(3.0, 5.0)) + float(rng.uniform(0.8, 1.5)) * lev
    raise ValueError(design)


def noise(form: str, rng: np.random.Generator, n: int, rate_hz: float) -> tuple[np.ndarray, float, int | None]:
    """(additive noise mm, its white-part rms mm, quantisation bits or None) of ``form``."""
    sd = float(rng.uniform(0.003, 0.012))
    parts = form.split("_")
    out = np.zeros(n)
    bits = None
    if form.startswith("ar1"):
        a = float(parts[1])
        x = signal.lfilter([1.0], [1.0, -a], rng.standard_normal(n))
        return sd * x / x.std(), sd, None
    if form.startswith("quant"):
        sd = float(rng.uniform(0.0005, 0.003))
        return sd * rng.standard_normal(n), sd, int(form[5:])
    if form in ("pink", "walk", "sines"):
        parts = [form]
    else:
        parts = parts[1:]
    white = True
    for p in parts:
        if p.startswith("ar"):
            a = float(p[2:])
            x = signal.lfilter([1.0], [1.0, -a], rng.standard_normal(n))
            out += sd * x / x.std()
            white = False
        elif p == "pink":
            f = np.fft.rfftfreq(n, 1.0 / rate_hz)
            g = 1.0 / np.sqrt(np.maximum(f, 0.02))
            x = np.fft.irfft(np.fft.rfft(rng.standard_normal(n)) * g, n)
            out += sd * x / x.std()
            white = False
        elif p == "walk":
            w = signal.detrend(np.cumsum(rng.standard_normal(n)), type="constant")
            out += w / np.abs(w).max() * float(rng.uniform(0.5, 3.0)) * sd
        elif p == "sines":
            t = np.arange(n) / rate_hz
            s = sum(np.sin(2 * np.pi * float(rng.uniform(0.02, 0.3)) * t + float(rng.uniform(0, 6.3)))
                    for _ in range(3))
            out += s / np.abs(s).max() * float(rng.uniform(0.5, 3.0)) * sd
        elif p.startswith("q"):
            bits = int(p[1:])
    if white:
        out += sd * rng.standard_normal(n)
    return out, sd, bits


def simulate(u: np.ndarray, rate_hz: float, conv: str, skew: float) -> np.ndarray:
    """P(s)'s noise-free output (mm) of command ``u`` (kV) under sampling convention ``conv``."""
    num, den = paper.plant_tf()
    if conv == "foh":  # input linearly interpolated: simulate at 4x the rate, take every 4th
        m = 4
        fine = np.interp(np.arange(u.size * m) / m, np.arange(u.size), u)
        return LinearSim(num, den, rate_hz * m).run(fine)[::m]
    off = {"zoh": 0.0, "centred": 0.5, "skew": skew}[conv]
    return LinearSim(num, den, rate_hz, offset=off, exact=False).run(u)   # the logs of earlier sessions


def make(directory: str, seed: int = 3) -> list[dict]:
    """Write the effect-free logs to ``directory``; returns their descriptions (labels empty)."""
    out = []
    num, den = paper.plant_tf()
    for f, form in enumerate(FORMS):
        for j in range(PER_FORM):
            i = PER_FORM * f + j
            rng = np.random.default_rng([seed, i])
            rate = RATES[(f + 2 * j) % len(RATES)]
            design = DESIGNS[(2 * f + j) % len(DESIGNS)]
            conv = CONVS[i % len(CONVS)]
            skew = float(rng.uniform(-0.45, 0.45))
            dur = duration_s(rate)
            if design == "closed_loop":
                nz, sd, bits = noise(form, rng, int(round(dur * rate)), rate)
                u, _ = o._closed_loop(rng, rate, dur, nz)
                conv = "zoh" if conv == "foh" else conv  # a controller holds its command
            else:
                u = command(design, rng, rate, dur)
                nz, sd, bits = noise(form, rng, u.size, rate)
            z = simulate(u, rate, conv, skew)
            y = z + nz[:z.size]
            if bits is not None:
                lo = 0.0  # the stroke range: 0 to P(0) times the amplifier's top voltage
                lsb = STROKE_MM / 2 ** bits
                y = lo + np.round((y - lo) / lsb) * lsb
            path = os.path.join(directory, f"free_{i:02d}_{form}.npz")
            np.savez_compressed(path, t_s=np.arange(u.size) / rate, voltage_kv=u, stroke_mm=y, num=num, den=den)
            kind = f"{form}:{rate:g}:{design}:{conv}" + (f"{skew:+.2f}" if conv == "skew" else "")
            out.append({"path": path, "kind": kind, "labels": [],
                        "truth": [f"white sd {sd * 1e3:.1f} um" + (f", {bits} bit" if bits else "")]})
    return out


def make_quiet(directory: str, seed: int = 3) -> list[dict]:
    """A grid of quiet logs (white noise 0.5 or 1.5 um rms, no quantisation): rates 1-10 kHz x the five
    designs x the two levels, conventions in turn; descriptions like :func:`make`."""
    out = []
    num, den = paper.plant_tf()
    i = 0
    for rate in RATES[1:]:
        for design in DESIGNS:
            for sd in (0.0005, 0.0015):
                rng = np.random.default_rng([seed, 1000 + i])
                conv = CONVS[i % len(CONVS)]
                skew = float(rng.uniform(-0.45, 0.45))
                dur = duration_s(rate)
                nz = sd * rng.standard_normal(int(round(dur * rate)))
                if design == "closed_loop":
                    u, _ = o._closed_loop(rng, rate, dur, nz)
                    conv = "zoh" if conv == "foh" else conv
                else:
                    u = command(design, rng, rate, dur)
                    nz = sd * rng.standard_normal(u.size)
                y = simulate(u, rate, conv, skew) + nz[:u.size]
                path = os.path.join(directory, f"quiet_{i:02d}.npz")
                np.savez_compressed(path, t_s=np.arange(u.size) / rate, voltage_kv=u, stroke_mm=y, num=num, den=den)
                kind = f"quiet:{rate:g}:{design}:{conv}" + (f"{skew:+.2f}" if conv == "skew" else "")
                out.append({"path": path, "kind": kind, "labels": [], "truth": [f"white sd {sd * 1e3:.1f} um"]})
                i += 1
    return out


def main(argv: list[str] | None = None) -> int:
    """``python bench/tune_diag/free_noise.py --out DIR [--only SUBSTR,...] [--list]``."""
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--out", required=True)
    p.add_argument("--only", default="", help="comma-separated substrings of case kinds to run")
    p.add_argument("--seed", type=int, default=3)
    p.add_argument("--list", action="store_true", help="write and list the logs, do not diagnose")
    p.add_argument("--quiet", action="store_true", help="the quiet grid (make_quiet) instead of the noise forms")
    a = p.parse_args(argv)
    os.makedirs(a.out, exist_ok=True)
    cs = make_quiet(a.out, a.seed) if a.quiet else make(a.out, a.seed)
    if a.only:
        keys = a.only.split(",")
        cs = [c for c in cs if any(k in c["kind"] or k in os.path.basename(c["path"]) for k in keys)]
    if a.list:
        for c in cs:
            print(os.path.basename(c["path"]), c["kind"], c["truth"][0])
        return 0
    from hasel.diagnose import core, pool

    pool.set_jobs(1)
    orig = core.diagnose
    trace: list[str] = []

    def traced(*args, **kw):
        trace.clear()
        return orig(*args, options=core.DiagnoseOptions(progress=trace.append), **kw)

    core.diagnose = traced
    rows = []

    def say(msg: str) -> None:
        print(msg)
        sys.stdout.flush()

    for c in cs:
        r = cases.run([c], say)[0]
        with open(os.path.splitext(c["path"])[0] + "_trace.txt", "w") as fh:
            fh.write("\n".join(trace) + "\n")
        for x in r.get("rounds", []):
            say(f"   round best {x['best']} gain {x['gain']} t_block {x['t_block']} z_col {x['z_coloured']} "
                f"over_floor {x['over_floor']} accepted {x['accepted']}")
        rows.append(r)
    core.diagnose = orig
    cases.finish(cs, rows, a.out)
    return 0


if __name__ == "__main__":
    sys.exit(main())
