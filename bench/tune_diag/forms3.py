"""Effects in forms no other tuning generator uses: 24 singles, 10 pairs, 6 effect-free logs (a tuning set, not
verification).

The diagnosis does almost perfectly on the single-effect cases of the existing generators (``cases.py``,
``loads.py``, ``combos.py``, ``other_pairs.py``, ``maps.py``, ``multi2.py``, ``deadzones.py``, ``drifts.py``,
``modes.py``, ``free_noise.py``, ``free_indep.py`` and ``hasel_bench/othersim.py``) but much worse on other
forms of the same effects. Every form here differs from every form those files draw (their docstrings and
form code were read for that, and only for that); this file was written WITHOUT reading the diagnosis code
(``src/hasel/diagnose``), the project's effect library (``src/hasel/effects``), any verification set or
result, and no form or size was changed after seeing the diagnosis's names. The simulation is this file's
own (numpy/scipy); :mod:`hasel.paper` gives only the nominal ``num``/``den`` written into each log.

Plant: the paper's P(s) (17), ``K (s+50.27)(s+62.83)(s+628.3)(s^2+w^2) / [(s+18.85)(s+56.55)(s^2+230 s+w^2)^2]``,
``K`` 10.836, ``w`` 122.2 rad/s, static gain ``g0`` = 1.351 mm/kV, realised as a series of first/second-order
sections and discretised EXACTLY for a held input (zero-order hold, ``expm``) on a fine grid ``m`` times the
log's rate (``m`` = 10 up to 1 kHz, 5 at 2 kHz, 2 at 5 kHz, 1 at 10 kHz: the fine grid is 2-10 kHz), run as
second-order sections whose zeros are the exact transmission zeros of the discrete state space. The logged
command is held between log samples (a DAC); the rate-dependent effects act on the fine grid; the stroke is
read at the log's instants ``t_k``. Every effect is placed where its physics puts it, in this order:
command -> input delays -> amplifier -> input drift -> input map -> input hysteresis -> P(s) (or the loaded /
switched P(s)) -> stroke limits -> asymmetric stroke follower -> output hysteresis -> stroke drift -> sensor
curve -> output delay -> sampling, noise, 12-bit laser quantisation (3.3 V x 3 mm/V / 4096 = 2.4 um).

Forms (``v`` the voltage in kV at that point of the chain, ``z`` the stroke in mm, ``lp(x, tau)`` a first-order
lag from rest at the first value, ``q_a`` the ``a`` quantile of the command / nominal stroke):

load_mass (P(s) changed, static gain kept)
- ``antires``: the anti-resonance moves: P's ``(s^2 + w^2)`` becomes ``(w/wn)^2 (s^2 + 2 zn wn s + wn^2)``,
  ``wn = kn w`` with ``kn`` 0.62-0.85 or 1.2-1.5, ``zn`` 0.03-0.25 (the load changes the counter-motion);
- ``lowmode``: a lightly damped pole-zero pair (a payload pendulum) BELOW the resonance, P(s) times
  ``(wp/wz)^2 (s^2 + 2 zz wz s + wz^2) / (s^2 + 2 zp wp s + wp^2)``, ``fp`` 3-12 Hz, ``wz/wp`` 0.7-0.88 or
  1.15-1.4, ``zp`` 0.03-0.12, ``zz`` 0.03-0.15;
- ``slowpoles``: a viscous load slows P's two real poles (18.85, 56.55 rad/s) by ``kr`` 0.45-0.75 (the
  sections ``(s+a)/(s+p)`` become ``kr (s+a)/(s+kr p)``);

time_delay
- ``outdelay``: an OUTPUT-side transport delay of the read-out, 5-25 ms, applied to the measured stroke after
  the sensor curve (fractional, linear interpolation on the fine grid);
- ``vardelay``: an input transport delay varying slowly with time, ``d(t) = d0 + d1 sin(2 pi t / T + phi)``,
  ``d0`` 6-20 ms, ``d1`` 0.3-0.7 ``d0``, ``T`` 3-15 s;
- ``vdelay``: an input delay that depends on the voltage (the zipping front starts later at a low field),
  ``d = d_hi + (d_lo - d_hi) (1 - clip(lp(v, 50 ms), 0, 9) / 9)``, ``d_hi`` 2-6 ms (9 kV), ``d_lo`` 15-35 ms (0 kV);

saturation
- ``zstop2``: two HARD end stops of the stroke, ``clip(z, z_lo, z_hi)``, ``z_lo`` 5-20 % of the nominal stroke's
  span above its minimum, ``z_hi`` 5-20 % below its maximum;
- ``zrate``: a SYMMETRIC rate limit of the stroke (the liquid's flow through the pouch neck),
  ``|dz/dt| <= R``, ``R`` 0.25-0.6 of the nominal stroke's 99.5 % quantile of ``|dz/dt|``;
- ``vfloor``: the amplifier cannot go below a floor (a bottom-only voltage clip), ``max(v, v_f)``, ``v_f`` at
  ``q_0.06-0.25`` of the command, within 0.3-3 kV;

hysteresis
- ``preisach``: a discrete Preisach model of 6-14 relays on the voltage, ``(1 - s) v + s (v_lo + (v_hi - v_lo)
  sum_i w_i R_i(v))``, relay ``i`` up at ``a_i`` (uniform in ``q_0.1-0.9``), down at ``a_i - 0.2-1.5 kV``, weights
  0.5-1.5 normalised, ``v_lo``/``v_hi`` the command's 2/98 % quantiles, ``s`` 0.2-0.5, relays from 0 kV;
- ``piout``: a Prandtl-Ishlinskii loop on the STROKE with 2-3 play operators and a direct path,
  ``(1 - s) z + s sum_i w_i play_{r_i}(z)``, radii 0.05-0.4 mm, ``s`` 0.3-0.7;
- ``stickslip``: stick-slip of the measured point: it sticks until ``|z - p| > r_s`` (0.04-0.2 mm), then slips
  to ``z -/+ r_k``, ``r_k`` 0.1-0.6 ``r_s`` (breakaway above sliding friction; a sawtooth on monotone motion);

static_nonlinearity (input side, before P(s); each map meets the line at ``v_r``, the command's median)
- ``expmap``: convex ``v_r expm1(v/v0) / expm1(v_r/v0)`` or concave ``v_r (1 - exp(-v/v0)) / (1 - exp(-v_r/v0))``,
  ``v0`` 3-8 kV (convex) or 4-9 kV (concave);
- ``sigmoid``: an S-shaped zipping map, ``(1 - a) v + a v_r (S(v) - S(0)) / (S(v_r) - S(0))``,
  ``S(v) = 1 / (1 + exp(-(v - v_c) / w))``, ``v_c`` at ``q_0.35-0.65``, ``w`` 0.6-1.8 kV, ``a`` 0.4-0.9;
- ``stairs``: the 12 pouches zip at staggered voltages, ``v - a (P / 2 pi) sin(2 pi (v - phi) / P)``, ``P``
  0.8-2 kV, ``a`` 0.5-0.95 (monotone), ``phi`` 0-P;

sensor_nonlinearity (output side, on the measured stroke)
- ``recip555``: the read-out inverts the timer's period (a reciprocal curve) calibrated by a line at 2 and
  7 mm (the paper's range): ``y = a + b / (1 + z / L)`` with ``y(2) = 2``, ``y(7) = 7``, ``L`` 12-60 mm;
- ``calpts``: calibration-point errors (the paper's offsets at 2 and 4 mm): ``y = z + interp(z, k, e_k)``,
  knots ``k`` = 0, 1, ..., 15 mm, ``e_k`` normal with sd 0.04-0.14 mm, less their least-squares line over 2-7 mm;
- ``quantiser``: a step-like read-out (a timer counting coarse clock ticks), ``y = q round(z / q - phi) + q phi``,
  ``q`` 0.06-0.3 mm, ``phi`` 0-1;

asymmetric_dynamics
- ``unidamper``: a one-way damper in the mechanics: one of P's two mechanical pole pairs,
  ``w^2 (1 + s/628.3) / (s^2 + c s + w^2)``, has ``c`` = 230 while its velocity rises and ``c`` = 230 ``k``
  (``k`` 2.5-6) while it falls (a check valve; simulated on the fine grid, first-order hold per step);
- ``asymslew``: the amplifier sources more current than it sinks: the voltage rises at most ``S_up`` and falls
  at most ``S_dn`` kV/s, ``S_dn`` 0.12-0.4 of the command's 99.5 % quantile of ``|du/dt|`` (at least 3 kV/s),
  ``S_up`` 4-10 ``S_dn``;
- ``asymgain``: a direction-dependent incremental gain that relaxes: ``y += g(dir) dz``, then ``y -> z`` with
  ``tau`` 0.1-0.8 s; ``g`` 1 one way and 0.4-0.8 the other (the fall reduced in 60 % of draws);

charge_drift (driven by the applied voltage)
- ``dielabs3``: dielectric absorption with three time constants, the field creeps after a change,
  ``(1 - sum a_i) v + sum_i a_i lp(v, tau_i)``, ``tau`` 1-3, 6-15, 30-80 s, ``a_i`` 0.04-0.12;
- ``ratchet``: an offset that ratchets with each new voltage peak, ``z + o (p - p_0) / 8 kV``, ``p_k =
  max(p_{k-1} exp(-dt / tau), lp(v, 20 ms)_k)`` (a leaky peak memory, ``tau`` 100-400 s), ``o`` 0.25-0.8 mm
  either sign;
- ``cycling``: charge injected per swing, a gain loss ``z (1 - c q)`` with ``q`` the leaky integral of
  ``|dv/dt|`` (kV of swing, leak ``tau`` 30-200 s) and ``c`` set for a peak loss of 4-15 %.

Cases (``KINDS``): 24 singles (the 24 forms), 10 pairs of two families (expmap+vardelay, stickslip+slowpoles,
recip555+outdelay, zrate+dielabs3, asymgain+lowmode, sigmoid+ratchet, preisach+calpts, zstop2+antires,
unidamper+stairs, cycling+piout) and 6 effect-free logs. Each member must be visible: its effect alone
(against the nominal) and its removal from the case's chain (for pairs) must change the noise-free stroke by
at least ``MIN_VISIBLE`` = 5 times the realised noise rms (``std`` of the difference: a constant offset does
not count), and the stroke must stay within -0.5-14.5 mm, else the parameters are drawn again (after every
10 failed draws the noise is lowered by 15 %, never below 3 um; after 40, the next design is tried).

Designs (``DESIGNS``, cycled over the cases, within 0-9 kV): ``paper`` (the paper's chirp (3)-(5): offsets
among 2-7 kV each held 1 s then swept ``v_s + 1 kV sin(2 pi k t^2)``, ``k = (20 - 0.001) / 20``, 20 s per
chirp, 1-4 chirps), ``linchirp`` (textbook 0.1 Hz -> 20-30 Hz around 3-6 kV, 0.8-2 kV), ``logchirp``
(0.05-0.2 Hz -> 20-40 Hz), ``multisine`` (40 log-spaced tones 0.05-30 Hz, flat or 1/sqrt(f), random phases,
0.8-1.5 kV rms about 3.5-5.5 kV), ``prbs`` (a random binary sequence between 1-3 and 5-8 kV, clock 10-60 ms),
``levels`` (random levels 0.3-8.5 kV held 0.1-1.5 s), ``steps`` (open-loop voltage steps among 0-8 kV held 2-5
s), ``closedloop`` (a dual-mode PI at the log's rate, bandwidth 1-3 Hz, on the nominal P(s) with the log's
noise through the paper's 40 Hz second-order filter, tracking stroke steps in 2-6 mm held 1.5-4 s; the
applied voltage, clipped to 0-9 kV, is the log's command, replayed through the effect chain). The amplifier's
edges are a 1 ms lag. Rates 200, 500, 1000, 2000, 5000, 10000 Hz; lengths 40-90 s at 200 Hz, 30-80 s at
500 Hz, 30-60 s at 1 kHz, 20-40 s at 2 kHz, 20-30 s at 5 kHz, 20-25 s at 10 kHz. Noise on the stroke
(``NOISES``): ``white`` (0.003-0.015 mm rms), ``ar1`` (AR(1) with a corner 1-30 Hz, same rms) or ``walk``
(white plus a random-walk sensor offset whose peak is 1-4x the white rms).

Run ``python bench/tune_diag/forms3.py --out DIR [--seed S] [--only SUBSTR,...] [--list]``. Seed 1 is for
tuning. Logs go to ``DIR/f3_NN_<forms>.npz`` (``t_s``, ``voltage_kv``, ``stroke_mm``, and the nominal ``num``,
``den``), their truth to ``DIR/cases_<seed>.json`` (``path``, ``labels``, ``kind`` = forms:design:rate:noise,
``truth``, ``visible``: per member the smaller of its alone and in-case visibility in noise rms). ``--list``
writes them and prints the truth only; otherwise every case is diagnosed in one process and the output is
``cases.py``'s (one line per case, the summary, ``DIR/results.json``).
"""
from __future__ import annotations

import math
import os
import sys

import numpy as np
from scipy import linalg, signal

from hasel import paper

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from combos import generator_main  # noqa: E402

#: P(s) (17) of the paper (kV -> mm): gain, notch (rad/s), the mechanical pairs' 2 zeta w (rad/s)
K_P, W_P, C_P = 10.836, 122.2, 230.0
G0 = K_P * 50.27 * 62.83 * 628.3 / (18.85 * 56.55 * W_P ** 2)  # static gain, mm/kV
RATES = (200.0, 500.0, 1000.0, 2000.0, 5000.0, 10000.0)
DURATIONS = {200.0: (40.0, 90.0), 500.0: (30.0, 80.0), 1000.0: (30.0, 60.0), 2000.0: (20.0, 40.0),
             5000.0: (20.0, 30.0), 10000.0: (20.0, 25.0)}
DESIGNS = ("paper", "linchirp", "logchirp", "multisine", "prbs", "levels", "steps", "closedloop")
NOISES = ("white", "ar1", "walk")
LSB_MM = 3.3 * 3.0 / 4096  # the laser's 12-bit ADC: 0-3.3 V at 3 mm/V
MIN_VISIBLE = 5.0  # noise rms a member must reach, alone and in its case
Z_RANGE = (-0.5, 14.5)  # a plausible noise-free stroke, mm

LABEL = {"antires": "load_mass", "lowmode": "load_mass", "slowpoles": "load_mass",
         "outdelay": "time_delay", "vardelay": "time_delay", "vdelay": "time_delay",
         "zstop2": "saturation", "zrate": "saturation", "vfloor": "saturation",
         "preisach": "hysteresis", "piout": "hysteresis", "stickslip": "hysteresis",
         "expmap": "static_nonlinearity", "sigmoid": "static_nonlinearity", "stairs": "static_nonlinearity",
         "recip555": "sensor_nonlinearity", "calpts": "sensor_nonlinearity", "quantiser": "sensor_nonlinearity",
         "unidamper": "asymmetric_dynamics", "asymslew": "asymmetric_dynamics", "asymgain": "asymmetric_dynamics",
         "dielabs3": "charge_drift", "ratchet": "charge_drift", "cycling": "charge_drift"}
#: forms per case: the 24 singles (3 per family), 10 pairs, 6 effect-free logs (())
KINDS: tuple[tuple[str, ...], ...] = tuple((f,) for f in LABEL) + (
    ("expmap", "vardelay"), ("stickslip", "slowpoles"), ("recip555", "outdelay"), ("zrate", "dielabs3"),
    ("asymgain", "lowmode"), ("sigmoid", "ratchet"), ("preisach", "calpts"), ("zstop2", "antires"),
    ("unidamper", "stairs"), ("cycling", "piout"),
    (), (), (), (), (), ())


# ---------------------------------------------------------------------------------------------- linear parts
def _sections(load: tuple[str, dict] | None = None) -> list[tuple[list, list]]:
    """P(s) (or P(s) with the load form ``load``) as a series of proper (num, den) sections, static gain kept."""
    w2 = W_P * W_P
    s1, s2 = ([1.0, 50.27], [1.0, 18.85]), ([1.0, 62.83], [1.0, 56.55])
    notch = ([1.0, 0.0, w2], [1.0, C_P, w2])
    last = ([K_P, K_P * 628.3], [1.0, C_P, w2])
    if load is None:
        return [s1, s2, notch, last]
    form, k = load
    if form == "antires":
        wn = k["kn"] * W_P
        notch = ([w2 / wn ** 2, w2 / wn ** 2 * 2 * k["zn"] * wn, w2], [1.0, C_P, w2])
        return [s1, s2, notch, last]
    if form == "lowmode":
        wp, wz = 2 * math.pi * k["fp_hz"], 2 * math.pi * k["fp_hz"] * k["ratio"]
        r = (wp / wz) ** 2
        dip = ([r, r * 2 * k["zz"] * wz, r * wz * wz], [1.0, 2 * k["zp"] * wp, wp * wp])
        return [s1, s2, notch, last, dip]
    if form == "slowpoles":
        kr = k["kr"]
        return [([kr, kr * 50.27], [1.0, kr * 18.85]), ([kr, kr * 62.83], [1.0, kr * 56.55]), notch, last]
    raise ValueError(form)


def _series(secs: list[tuple[list, list]]) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """A continuous state space (A, B, C, D) of the sections in series (well conditioned, unlike one tf)."""
    a_, b_, c_, d_ = np.zeros((0, 0)), np.zeros((0, 1)), np.zeros((1, 0)), np.ones((1, 1))
    for num, den in secs:
        a, b, c, d = signal.tf2ss(num, den)
        n0, n1 = a_.shape[0], a.shape[0]
        a2 = np.zeros((n0 + n1, n0 + n1))
        a2[:n0, :n0], a2[n0:, n0:], a2[n0:, :n0] = a_, a, b @ c_
        a_, b_, c_, d_ = a2, np.vstack([b_, b @ d_]), np.hstack([d @ c_, c]), d @ d_
    return a_, b_, c_, d_


def _zoh_ss(secs, dt: float) -> tuple[np.ndarray, np.ndarray, np.ndarray, float]:
    """The sections' exact zero-order-hold discretisation at step ``dt``: (Ad, Bd, C, D)."""
    a, b, c, d = _series(secs)
    n = a.shape[0]
    m = np.zeros((n + 1, n + 1))
    m[:n, :n], m[:n, n] = a * dt, b[:, 0] * dt
    e = linalg.expm(m)
    return e[:n, :n], e[:n, n], c[0], float(d[0, 0])


_SOS: dict = {}


def _zoh_sos(secs, dt: float) -> tuple[np.ndarray, int]:
    """Second-order sections of the exact ZOH discretisation (poles of ``Ad``, zeros the finite generalised
    eigenvalues of the discrete Rosenbrock pencil, DC gain matched) and the output shift (relative degree)."""
    key = (repr(secs), dt)
    if key not in _SOS:
        ad, bd, c, d = _zoh_ss(secs, dt)
        n = ad.shape[0]
        mm, nn = np.zeros((n + 1, n + 1)), np.zeros((n + 1, n + 1))
        mm[:n, :n], mm[:n, n], mm[n, :n], mm[n, n] = ad, bd, c, d
        nn[:n, :n] = np.eye(n)
        ev = linalg.eigvals(mm, nn)
        zeros = ev[np.isfinite(ev) & (np.abs(ev) < 1e6)]
        poles = linalg.eigvals(ad)
        sos = signal.zpk2sos(zeros, poles, 1.0)
        g = np.prod([np.polyval(s[:3], 1.0) / np.polyval(s[3:], 1.0) for s in sos])
        sos[0, :3] *= (c @ np.linalg.solve(np.eye(n) - ad, bd) + d) / g
        _SOS[key] = (sos, len(poles) - len(zeros))
    return _SOS[key]


def linear(x: np.ndarray, secs, dt: float) -> np.ndarray:
    """``x`` (held over each step ``dt``) through the sections, exact, from rest at ``x[0]``; output at the steps'
    starts."""
    sos, shift = _zoh_sos(secs, dt)
    y = signal.sosfilt(sos, x, zi=signal.sosfilt_zi(sos) * x[0])[0]
    return np.concatenate([np.full(shift, y[0]), y[:x.size - shift]]) if shift else y


def lowpass(x: np.ndarray, dt: float, tau: float) -> np.ndarray:
    """First-order lag (time constant ``tau``) of ``x`` held over each step, from rest at ``x[0]``."""
    a = math.exp(-dt / tau)
    return signal.lfilter([1.0 - a], [1.0, -a], x, zi=np.array([a * x[0]]))[0]


def _foh_pair(c: float, dt: float) -> tuple:
    """``x'' = w^2 (u - x) - c x'`` per step ``dt`` for ``u`` linear over the step: (Ad, B0, B1) as floats."""
    a = np.array([[0.0, 1.0], [-W_P ** 2, -c]])
    m = np.zeros((4, 4))
    m[:2, :2], m[:2, 2], m[2, 3] = a * dt, np.array([0.0, W_P ** 2]) * dt, 1.0
    e = linalg.expm(m)
    b1 = e[:2, 3]
    b0 = e[:2, 2] - b1
    return tuple(e[:2, :2].ravel()) + tuple(b0) + tuple(b1)


def unidamper(v: np.ndarray, dt: float, k: float) -> np.ndarray:
    """P(s) = G1 G2 with G2 = w^2 (1 + s/628.3) / (s^2 + c s + w^2) switched: ``c`` = 230 while the pair's
    velocity is >= 0, 230 ``k`` while it is < 0. G1 (biproper) exact ZOH; into G2 its feedthrough ``D v`` is held
    and its strictly proper part (continuous) linear over each fine step."""
    d = K_P * 628.3 / W_P ** 2
    secs = [([1.0, 50.27], [1.0, 18.85]), ([1.0, 62.83], [1.0, 56.55]), ([d, 0.0, d * W_P ** 2], [1.0, C_P, W_P ** 2])]
    vl = v.tolist()
    g = (linear(v, secs, dt) - d * v).tolist()
    up, dn = _foh_pair(C_P, dt), _foh_pair(C_P * k, dt)
    x, xd = g[0] + d * vl[0], 0.0
    out = np.empty(len(g))
    for i in range(len(g)):
        out[i] = x + xd / 628.3
        if i + 1 < len(g):
            a11, a12, a21, a22, b00, b01, b10, b11 = up if xd >= 0.0 else dn
            h = d * vl[i]
            x, xd = (a11 * x + a12 * xd + b00 * (g[i] + h) + b10 * (g[i + 1] + h),
                     a21 * x + a22 * xd + b01 * (g[i] + h) + b11 * (g[i + 1] + h))
    return out


# ---------------------------------------------------------------------------------------------- nonlinear parts
def _play(x: np.ndarray, r: float) -> np.ndarray:
    """A play (backlash) operator of half-width ``r`` from ``x[0]``."""
    out = np.empty(x.size)
    p = float(x[0])
    for i, v in enumerate(x.tolist()):
        if v - r > p:
            p = v - r
        elif v + r < p:
            p = v + r
        out[i] = p
    return out


def _stickslip(x: np.ndarray, rs: float, rk: float) -> np.ndarray:
    """Stick until ``|x - p| > rs``, then slip to ``x -/+ rk``."""
    out = np.empty(x.size)
    p = float(x[0])
    for i, v in enumerate(x.tolist()):
        if v - p > rs:
            p = v - rk
        elif p - v > rs:
            p = v + rk
        out[i] = p
    return out


def _rate_limit(x: np.ndarray, up: float, down: float) -> np.ndarray:
    """``x`` rising at most ``up`` and falling at most ``down`` per step."""
    out = np.empty(x.size)
    y = float(x[0])
    for i, v in enumerate(x.tolist()):
        d = v - y
        y += up if d > up else -down if d < -down else d
        out[i] = y
    return out


def _asymgain(z: np.ndarray, dt: float, g_up: float, g_dn: float, tau: float) -> np.ndarray:
    """``y += g(dir) dz`` then ``y`` relaxes to ``z`` with ``tau``."""
    a = math.exp(-dt / tau)
    out = np.empty(z.size)
    zl = z.tolist()
    y = prev = zl[0]
    for i, v in enumerate(zl):
        d = v - prev
        y += (g_up if d >= 0.0 else g_dn) * d
        y = v + (y - v) * a
        prev = v
        out[i] = y
    return out


def _relays(v: np.ndarray, alpha: float, beta: float) -> np.ndarray:
    """A relay up at ``alpha``, down at ``beta`` (< alpha), from 0 kV (off unless the first value is >= alpha)."""
    ev = np.where(v >= alpha, 1, np.where(v <= beta, -1, 0))
    ev[0] = 1 if v[0] >= alpha else -1
    idx = np.maximum.accumulate(np.where(ev != 0, np.arange(v.size), 0))
    return (ev[idx] > 0).astype(float)


def _peak_memory(x: np.ndarray, dt: float, tau: float) -> np.ndarray:
    """``p_k = max(p_{k-1} exp(-dt / tau), x_k)`` from ``x[0]``."""
    a = math.exp(-dt / tau)
    out = np.empty(x.size)
    p = float(x[0])
    for i, v in enumerate(x.tolist()):
        p = max(p * a, v)
        out[i] = p
    return out


def _delay(x: np.ndarray, dt: float, d: np.ndarray | float) -> np.ndarray:
    """``x`` delayed by ``d`` s (an array per sample or a number), linear interpolation, the first value held."""
    t = np.arange(x.size) * dt
    return np.interp(t - d, t, x, left=x[0])


# ---------------------------------------------------------------------------------------------- the chain
class Ctx:
    """A log's command, rate and fine grid, and the nominal stroke on it (for the draws)."""

    def __init__(self, u: np.ndarray, rate: float):
        self.u, self.rate = np.asarray(u, float), rate
        self.m = 10 if rate <= 1000.0 else 5 if rate <= 2000.0 else 2 if rate <= 5000.0 else 1
        self.dt = 1.0 / (rate * self.m)
        self.uf = np.repeat(self.u, self.m)
        self.z0f = linear(self.uf, _sections(), self.dt)


def chain(ctx: Ctx, parts: list[tuple[str, dict]]) -> np.ndarray:
    """The noise-free stroke (mm) at the log's instants for the command of ``ctx`` through ``parts`` ((form,
    parameters)) in the physical order of the module."""
    p = dict(parts)
    dt = ctx.dt
    v = v_start = ctx.uf
    t = np.arange(v.size) * dt
    if "vardelay" in p:
        k = p["vardelay"]
        v = _delay(v, dt, k["d0"] + k["d1"] * np.sin(2 * np.pi * t / k["T"] + k["phi"]))
    if "vdelay" in p:
        k = p["vdelay"]
        vs = np.clip(lowpass(v, dt, 0.05), 0.0, 9.0)
        v = _delay(v, dt, k["d_hi"] + (k["d_lo"] - k["d_hi"]) * (1.0 - vs / 9.0))
    if "vfloor" in p:
        v = np.maximum(v, p["vfloor"]["v_f"])
    if "asymslew" in p:
        k = p["asymslew"]
        v = _rate_limit(v, k["s_up"] * dt, k["s_dn"] * dt)
    applied = v
    if "dielabs3" in p:
        k = p["dielabs3"]
        a = [k["a1"], k["a2"], k["a3"]]
        v = (1.0 - sum(a)) * v + sum(ai * lowpass(applied, dt, k[f"tau{i + 1}"]) for i, ai in enumerate(a))
    if "expmap" in p:
        k = p["expmap"]
        vr, v0 = k["v_r"], k["v0"]
        v = (vr * np.expm1(v / v0) / math.expm1(vr / v0) if k["convex"]
             else vr * -np.expm1(-v / v0) / -math.expm1(-vr / v0))
    if "sigmoid" in p:
        k = p["sigmoid"]

        def s_(x):
            return 1.0 / (1.0 + np.exp(-(x - k["v_c"]) / k["w"]))
        v = (1.0 - k["a"]) * v + k["a"] * k["v_r"] * (s_(v) - s_(0.0)) / (s_(k["v_r"]) - s_(0.0))
    if "stairs" in p:
        k = p["stairs"]
        v = v - k["a"] * k["P"] / (2 * np.pi) * np.sin(2 * np.pi * (v - k["phi"]) / k["P"])
    if "preisach" in p:
        k = p["preisach"]
        r = sum(w * _relays(v, a, b) for a, b, w in zip(k["alpha"], k["beta"], k["w"]))
        v = (1.0 - k["s"]) * v + k["s"] * (k["v_lo"] + (k["v_hi"] - k["v_lo"]) * r)
    load = next(((f, p[f]) for f in ("antires", "lowmode", "slowpoles") if f in p), None)
    if "unidamper" in p:
        z = unidamper(v, dt, p["unidamper"]["k"])
    elif load is None and v is v_start:
        z = ctx.z0f.copy()
    else:
        z = linear(v, _sections(load), dt)
    if "zrate" in p:
        r = p["zrate"]["R"] * dt
        z = _rate_limit(z, r, r)
    if "zstop2" in p:
        z = np.clip(z, p["zstop2"]["z_lo"], p["zstop2"]["z_hi"])
    if "asymgain" in p:
        k = p["asymgain"]
        z = _asymgain(z, dt, k["g_up"], k["g_dn"], k["tau"])
    if "piout" in p:
        k = p["piout"]
        z = (1.0 - k["s"]) * z + k["s"] * sum(w * _play(z, r) for r, w in zip(k["r"], k["w"]))
    if "stickslip" in p:
        z = _stickslip(z, p["stickslip"]["r_s"], p["stickslip"]["r_k"])
    if "ratchet" in p:
        k = p["ratchet"]
        pk = _peak_memory(lowpass(applied, dt, 0.02), dt, k["tau"])
        z = z + k["o"] * (pk - pk[0]) / 8.0
    if "cycling" in p:
        k = p["cycling"]
        a = math.exp(-dt / k["tau"])
        q = signal.lfilter([1.0], [1.0, -a], np.abs(np.diff(applied, prepend=applied[0])))
        z = z * (1.0 - k["c"] * q)
    if "recip555" in p:
        k = p["recip555"]
        z = k["a"] + k["b"] / (1.0 + z / k["L"])
    if "calpts" in p:
        k = p["calpts"]
        z = z + np.interp(z, np.arange(len(k["e"]), dtype=float), k["e"])
    if "quantiser" in p:
        k = p["quantiser"]
        z = k["q"] * np.round(z / k["q"] - k["phi"]) + k["q"] * k["phi"]
    if "outdelay" in p:
        z = _delay(z, dt, p["outdelay"]["d"])
    return np.asarray(z)[::ctx.m].copy()


def draw(form: str, rng: np.random.Generator, ctx: Ctx) -> dict:
    """Parameters of ``form`` (ranges of the module) for the log of ``ctx``."""
    u = rng.uniform
    qu = lambda a, b: float(np.quantile(ctx.u, u(a, b)))  # noqa: E731
    sign = 1.0 if rng.random() < 0.5 else -1.0
    vr = float(np.median(ctx.u))
    if form == "antires":
        return {"kn": u(0.62, 0.85) if rng.random() < 0.5 else u(1.2, 1.5), "zn": u(0.03, 0.25)}
    if form == "lowmode":
        return {"fp_hz": u(3.0, 12.0), "ratio": u(0.7, 0.88) if rng.random() < 0.5 else u(1.15, 1.4),
                "zp": u(0.03, 0.12), "zz": u(0.03, 0.15)}
    if form == "slowpoles":
        return {"kr": u(0.45, 0.75)}
    if form == "outdelay":
        return {"d": u(5e-3, 25e-3)}
    if form == "vardelay":
        d0 = u(6e-3, 20e-3)
        return {"d0": d0, "d1": d0 * u(0.3, 0.7), "T": u(3.0, 15.0), "phi": u(0, 2 * np.pi)}
    if form == "vdelay":
        return {"d_hi": u(2e-3, 6e-3), "d_lo": u(15e-3, 35e-3)}
    if form == "zstop2":
        lo, hi = float(ctx.z0f.min()), float(ctx.z0f.max())
        return {"z_lo": lo + (hi - lo) * u(0.05, 0.2), "z_hi": hi - (hi - lo) * u(0.05, 0.2)}
    if form == "zrate":
        dz = np.abs(np.diff(ctx.z0f)) / ctx.dt
        return {"R": float(np.quantile(dz, 0.995)) * u(0.25, 0.6)}
    if form == "vfloor":
        return {"v_f": min(max(qu(0.06, 0.25), 0.3), 3.0)}
    if form == "preisach":
        n = int(rng.integers(6, 15))
        lo, hi = float(np.quantile(ctx.u, 0.1)), float(np.quantile(ctx.u, 0.9))
        alpha = np.sort(rng.uniform(lo, hi, n))
        w = rng.uniform(0.5, 1.5, n)
        return {"alpha": alpha.tolist(), "beta": (alpha - rng.uniform(0.2, 1.5, n)).tolist(),
                "w": (w / w.sum()).tolist(), "s": u(0.2, 0.5), "v_lo": float(np.quantile(ctx.u, 0.02)),
                "v_hi": float(np.quantile(ctx.u, 0.98))}
    if form == "piout":
        n = int(rng.integers(2, 4))
        w = rng.uniform(0.5, 1.5, n)
        return {"r": np.sort(rng.uniform(0.05, 0.4, n)).tolist(), "w": (w / w.sum()).tolist(), "s": u(0.3, 0.7)}
    if form == "stickslip":
        rs = u(0.04, 0.2)
        return {"r_s": rs, "r_k": rs * u(0.1, 0.6)}
    if form == "expmap":
        convex = bool(rng.random() < 0.5)
        return {"v_r": vr, "v0": u(3.0, 8.0) if convex else u(4.0, 9.0), "convex": convex}
    if form == "sigmoid":
        return {"v_r": vr, "v_c": qu(0.35, 0.65), "w": u(0.6, 1.8), "a": u(0.4, 0.9)}
    if form == "stairs":
        per = u(0.8, 2.0)
        return {"P": per, "a": u(0.5, 0.95), "phi": u(0.0, per)}
    if form == "recip555":
        L = u(12.0, 60.0)
        h2, h7 = 1.0 / (1.0 + 2.0 / L), 1.0 / (1.0 + 7.0 / L)
        b = 5.0 / (h7 - h2)
        return {"L": L, "a": 2.0 - b * h2, "b": b}
    if form == "calpts":
        knots = np.arange(16.0)
        e = rng.standard_normal(16) * u(0.04, 0.14)
        sel = (knots >= 2) & (knots <= 7)
        e = e - np.polyval(np.polyfit(knots[sel], e[sel], 1), knots)
        return {"e": e.tolist()}
    if form == "quantiser":
        return {"q": u(0.06, 0.3), "phi": u(0.0, 1.0)}
    if form == "unidamper":
        return {"k": u(2.5, 6.0)}
    if form == "asymslew":
        du = np.abs(np.diff(ctx.u)) * ctx.rate
        s_dn = max(float(np.quantile(du, 0.995)) * u(0.12, 0.4), 3.0)
        return {"s_dn": s_dn, "s_up": s_dn * u(4.0, 10.0)}
    if form == "asymgain":
        g = u(0.4, 0.8)
        fall = rng.random() < 0.6
        return {"g_up": 1.0 if fall else g, "g_dn": g if fall else 1.0, "tau": u(0.1, 0.8)}
    if form == "dielabs3":
        return {"a1": u(0.04, 0.12), "tau1": u(1.0, 3.0), "a2": u(0.04, 0.12), "tau2": u(6.0, 15.0),
                "a3": u(0.04, 0.12), "tau3": u(30.0, 80.0)}
    if form == "ratchet":
        return {"o": sign * u(0.25, 0.8), "tau": u(100.0, 400.0)}
    if form == "cycling":
        tau = u(30.0, 200.0)
        a = math.exp(-ctx.dt / tau)
        q = signal.lfilter([1.0], [1.0, -a], np.abs(np.diff(ctx.uf, prepend=ctx.uf[0])))
        return {"tau": tau, "c": u(0.04, 0.15) / max(float(q.max()), 1e-9)}
    raise ValueError(form)


# ---------------------------------------------------------------------------------------------- designs
def _edge(u: np.ndarray, rate: float) -> np.ndarray:
    """The amplifier's 1 ms edge."""
    return lowpass(np.asarray(u, float), 1.0 / rate, 1e-3)


def _held(rng: np.random.Generator, n: int, rate: float, lo_s: float, hi_s: float, level) -> np.ndarray:
    out = np.empty(n)
    i = 0
    while i < n:
        m = max(1, int(rng.uniform(lo_s, hi_s) * rate))
        out[i:i + m] = level()
        i += m
    return out


def closed_loop(rng: np.random.Generator, rate: float, n: int, noise: np.ndarray) -> np.ndarray:
    """The applied voltage (kV) of a dual-mode PI at ``rate`` on the nominal P(s) (exact ZOH) tracking stroke steps
    in 2-6 mm held 1.5-4 s, measuring ``z + noise`` through a 40 Hz second-order Butterworth low-pass."""
    ad, bd, c, _ = _zoh_ss(_sections(), 1.0 / rate)
    ref = _held(rng, n, rate, 1.5, 4.0, lambda: rng.uniform(2.0, 6.0))
    wc = 2 * math.pi * rng.uniform(1.0, 3.0)
    ki_up, kp_up = wc / G0, rng.uniform(0.2, 0.6) / G0
    ki_dn, kp_dn = ki_up * rng.uniform(0.7, 1.3), kp_up * rng.uniform(0.7, 1.3)
    b, a = signal.butter(2, min(40.0, 0.4 * rate), fs=rate)
    b0, b1, b2, a1, a2 = float(b[0]), float(b[1]), float(b[2]), float(a[1]), float(a[2])
    u0 = ref[0] / G0
    x = np.linalg.solve(np.eye(ad.shape[0]) - ad, bd * u0)
    s1 = (b1 + b2 - (a1 + a2)) * ref[0]  # DF-II transposed state at rest at ref[0]
    s2 = (b2 - a2) * ref[0]
    integ = u0
    out = np.empty(n)
    for i in range(n):
        meas = float(c @ x) + float(noise[i])
        yf = b0 * meas + s1
        s1, s2 = b1 * meas - a1 * yf + s2, b2 * meas - a2 * yf
        e = ref[i] - yf
        kp, ki = (kp_up, ki_up) if e >= 0.0 else (kp_dn, ki_dn)
        integ = min(max(integ + ki * e / rate, 0.0), 9.0)
        out[i] = min(max(integ + kp * e, 0.0), 9.0)
        x = ad @ x + bd * out[i]
    return out


def command(design: str, rng: np.random.Generator, rate: float, dur: float, noise: np.ndarray) -> np.ndarray:
    """The command (kV, 0-9) of ``design`` at ``rate`` Hz, about ``dur`` s long (the paper's: whole chirps)."""
    n = int(round(dur * rate))
    t = np.arange(n) / rate
    if design == "paper":
        k = (20.0 - 0.001) / 20.0  # the paper's formula: phase 2 pi k t^2
        tc = np.arange(int(round(20.0 * rate))) / rate
        offs = [float(x) for x in rng.permutation([2.0, 3.0, 4.0, 5.0, 6.0, 7.0])]
        parts = []
        for j in range(max(1, int(dur // 21.0))):
            vs = offs[j % len(offs)]
            parts += [np.full(int(rate), vs), vs + np.sin(2 * np.pi * k * tc * tc)]
        return _edge(np.concatenate(parts), rate)
    if design in ("linchirp", "logchirp"):
        off, amp = rng.uniform(3.0, 6.0), rng.uniform(0.8, 2.0)
        amp = min(amp, off - 0.3, 8.8 - off)
        if design == "linchirp":
            f0, f1 = 0.1, rng.uniform(20.0, 30.0)
            ph = 2 * np.pi * (f0 * t + 0.5 * (f1 - f0) / dur * t * t)
        else:
            f0, f1 = rng.uniform(0.05, 0.2), rng.uniform(20.0, 40.0)
            ph = 2 * np.pi * f0 * dur / math.log(f1 / f0) * np.expm1(t / dur * math.log(f1 / f0))
        return off + amp * np.sin(ph)
    if design == "multisine":
        f = np.geomspace(0.05, 30.0, 40)
        amp = 1.0 / np.sqrt(f) if rng.random() < 0.5 else np.ones(f.size)
        x = np.sin(2 * np.pi * np.outer(t, f) + rng.uniform(0, 2 * np.pi, f.size)) @ amp
        return np.clip(rng.uniform(3.5, 5.5) + rng.uniform(0.8, 1.5) * x / x.std(), 0.2, 8.8)
    if design == "prbs":
        lo, hi = rng.uniform(1.0, 3.0), rng.uniform(5.0, 8.0)
        clock = max(1, int(round(rng.uniform(0.01, 0.06) * rate)))
        bits = rng.random(n // clock + 1) < 0.5
        return _edge(np.where(np.repeat(bits, clock)[:n], hi, lo), rate)
    if design == "levels":
        return _edge(_held(rng, n, rate, 0.1, 1.5, lambda: rng.uniform(0.3, 8.5)), rate)
    if design == "steps":
        return _edge(_held(rng, n, rate, 2.0, 5.0, lambda: float(rng.integers(0, 9))), rate)
    if design == "closedloop":
        return closed_loop(rng, rate, n, noise)
    raise ValueError(design)


def make_noise(rng: np.random.Generator, kind: str, n: int, rate: float) -> tuple[np.ndarray, dict]:
    """Unit-scale noise of ``kind`` (scaled by the white rms later): the shape and its description."""
    w = rng.standard_normal(n)
    if kind == "ar1":
        fc = float(rng.uniform(1.0, 30.0))
        a = math.exp(-2 * math.pi * fc / rate)
        x = signal.lfilter([1.0], [1.0, -a], w)
        return x / x.std(), {"corner_hz": round(fc, 2)}
    if kind == "walk":
        x = np.cumsum(rng.standard_normal(n))
        x = x - x.mean()
        k = float(rng.uniform(1.0, 4.0))
        return w + k * x / max(np.abs(x).max(), 1e-12), {"walk_peak_x_white": round(k, 2)}
    return w, {}


# ---------------------------------------------------------------------------------------------- cases
def _plan(seed: int) -> tuple[list[str], list[float], list[str]]:
    """Design, rate and noise of each case: designs cycled (offset by the seed), rates and noises shuffled."""
    rng = np.random.default_rng([seed, 33])
    n = len(KINDS)
    off = int(rng.integers(len(DESIGNS)))
    designs = [DESIGNS[(i + off) % len(DESIGNS)] for i in range(n)]
    rates = [RATES[int(j) % len(RATES)] for j in rng.permutation(n)]
    noises = [NOISES[int(j) % len(NOISES)] for j in rng.permutation(n)]
    return designs, rates, noises


def _fmt(k: dict) -> dict:
    return {a: (round(float(b), 5) if isinstance(b, float) else [round(float(x), 4) for x in b]
                if isinstance(b, list) else b) for a, b in k.items()}


def make_case(directory: str, seed: int, i: int) -> dict:
    """Case ``i`` of :data:`KINDS` (draws from ``(seed, i)``), written to ``directory``."""
    forms = KINDS[i]
    designs, rates, noises = _plan(seed)
    rate, noise_kind = rates[i], noises[i]
    rng = np.random.default_rng([seed, 3, i])
    start = DESIGNS.index(designs[i])
    for j in range(len(DESIGNS)):
        design = DESIGNS[(start + j) % len(DESIGNS)]
        dur = float(rng.uniform(*DURATIONS[rate]))
        sd = float(rng.uniform(0.003, 0.015))
        shape, ninfo = make_noise(rng, noise_kind, int(round(dur * rate)), rate)
        u = command(design, rng, rate, dur, sd * shape)
        if u.size != shape.size:
            shape, ninfo = make_noise(rng, noise_kind, u.size, rate)
        ctx = Ctx(u, rate)
        z_nom = ctx.z0f[::ctx.m].copy()
        parts: list[tuple[str, dict]] = []
        vis: list[float] = []
        ok = not forms
        for attempt in range(0 if ok else 40):
            s = max(0.003, sd * 0.85 ** (attempt // 10))
            rms = float(np.std(s * shape))
            parts = [(f, draw(f, rng, ctx)) for f in forms]
            z = chain(ctx, parts)
            if not (np.all(np.isfinite(z)) and Z_RANGE[0] <= z.min() and z.max() <= Z_RANGE[1]):
                continue
            alone = [float(np.std(chain(ctx, [q]) - z_nom)) / rms for q in parts] if len(parts) > 1 else []
            removed = [float(np.std(z - chain(ctx, [q for q in parts if q is not p]))) / rms for p in parts]
            vis = [min(a, r) for a, r in zip(alone, removed)] if alone else removed
            if min(vis) >= MIN_VISIBLE:
                sd, ok = s, True
                break
        if ok:
            break
    else:
        raise RuntimeError(f"case {i} {forms}: no visible draw")
    z = chain(ctx, parts) if forms else z_nom
    nz = sd * shape
    y = np.round((z + nz) / LSB_MM) * LSB_MM
    num, den = paper.plant_tf()
    tag = "+".join(forms) or "free"
    path = os.path.join(directory, f"f3_{i:02d}_{tag}.npz")
    np.savez_compressed(path, t_s=np.arange(u.size) / rate, voltage_kv=u, stroke_mm=y, num=num, den=den)
    return {"path": path, "kind": f"{tag}:{design}:{rate:g}:{noise_kind}", "labels": sorted({LABEL[f] for f in forms}),
            "visible": [round(v, 1) for v in vis] if forms else [],
            "noise": {"kind": noise_kind, "white_sd_mm": round(sd, 5), "rms_mm": round(float(np.std(nz)), 5),
                      **ninfo},
            "duration_s": round(u.size / rate, 2), "v_range_kv": [round(float(u.min()), 3), round(float(u.max()), 3)],
            "z_range_mm": [round(float(z.min()), 3), round(float(z.max()), 3)],
            "truth": [f"{LABEL[f]}:{f}:{_fmt(k)}" for f, k in parts] if forms else []}


def make(directory: str, seed: int = 1) -> list[dict]:
    """Every case of :data:`KINDS` written to ``directory``; their labels and truth."""
    out = []
    for i in range(len(KINDS)):
        out.append(make_case(directory, seed, i))
        print(f"made {os.path.basename(out[-1]['path'])} {out[-1]['kind']} visible {out[-1]['visible']}",
              file=sys.stderr)
    return out


def main(argv: list[str] | None = None) -> int:
    """``python bench/tune_diag/forms3.py --out DIR [--seed S] [--only SUBSTR,...] [--list]``."""
    return generator_main(argv, __doc__, make, 1, serial=True)


if __name__ == "__main__":
    sys.exit(main())
