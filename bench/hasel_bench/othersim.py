"""An independent "other simulator" of a HASEL-like actuator, and a blind check of the diagnosis on it.

The project's own blind check (:mod:`hasel_bench.blind`) draws its cases from the
project's own effect library (:mod:`hasel.effects`), whose functional forms are the
same ones the diagnosis fits; that can flatter the diagnosis. This module is written
from scratch (numpy/scipy only, plus :mod:`hasel.paper` for the nominal ``P(s)``) and
parametrises each of the eight effects of ``shared/interfaces.md`` *differently*:

===================== ================================================================
verdict name          foreign forms (``kind``)
===================== ================================================================
static_nonlinearity   ``"power"``: ``f(v) = v_ref sign(v) |v / v_ref|^p`` (electrostatic-like);
                      ``"knee"``: piecewise-linear, slope ratio ``ratio`` above ``v_knee_kv``
asymmetric_dynamics   ``"rate_limit"``: the stroke may fall at most ``rate_mm_s``;
                      ``"switched_2nd"``: a 2nd-order follower whose natural frequency and
                      damping switch on the direction (fast up, slow over-damped down)
charge_drift          ``"screening"``: ``q`` = leaky integral of ``v^2`` (kV^2, time constant
                      ``tau_s``) screens the field, ``v_eff = v (1 - share q / 25 kV^2)``;
                      ``"offset"``: ``q`` = leaky integral of ``|v|`` adds a stroke offset
saturation            ``"slew"``: amplifier current limit, ``|dv/dt| <= slew_kv_s``;
                      ``"soft_stroke"``: ``tanh`` knee of the stroke above ``knee_mm``
time_delay            ``"pade"``: a 3rd-order Pade all-pass; ``"shift"``: an exact transport
                      delay of the piecewise-linear input
sensor_nonlinearity   ``"quadratic"``: ``y = z + c (z - z_c)^2``; ``"exponential"``:
                      ``y = z_c + b (exp((z - z_c) / b) - 1)``
load_mass             ``"coupled"``: the stroke is read on a load mass on a compliant coupling
                      (a new resonance, ``(c s + k) / (m s^2 + c s + k)``, ``k = m (2 pi f_n)^2``)
                      with a sag;
                      ``"heavier_mode"``: one of P(s)'s two mechanical pole pairs gets the
                      added inertia (the other stays)
hysteresis            ``"prandtl_ishlinskii"``: weighted sum of play operators (a Preisach
                      subclass) in parallel with a direct path; ``"duhem"``: a
                      rate-independent Duhem lag ``dw = alpha |dv| (v - w)``
===================== ================================================================

Signal chain (every stage optional, in this order), simulated at ``oversample`` times
the log's rate with the command linearly interpolated between log samples:
command (kV) -> delay -> amplifier slew limit -> hysteresis -> static map -> field
screening -> P(s) (or the loaded P(s)) -> load coupling -> asymmetric follower ->
stroke limit -> drift offset -> sensor map -> decimated to the log rate -> white noise
and a 12-bit laser quantisation. Linear blocks are discretised exactly for a
piecewise-linear input (first-order hold, as :func:`scipy.signal.lsim`), so with no
effect the output is P(s)'s response to the log's command to rounding.

:func:`run_othersim` draws cases (none / one effect / a pair, random kinds and
parameters, 500 Hz or 1 kHz logs, researcher-style excitations), writes each log to a
file holding only ``t_s``, ``voltage_kv``, ``stroke_mm`` (and the nominal model), has a
separate spawned process diagnose the file (:mod:`hasel_bench.harness`), then reveals
the labels and scores.
Run ``python -m hasel_bench.othersim --cases 28 --json FILE``.
"""
from __future__ import annotations

import argparse
import math
import os
import sys
import time
from collections import Counter
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np
from scipy import linalg, signal

from hasel import paper
from hasel_bench.harness import case_directory, diagnose_files, result_line, say_stderr, write_json

__all__ = [
    "EFFECT_KINDS", "ForeignEffect", "sample_foreign", "play_operator", "prandtl_ishlinskii", "duhem",
    "FohSystem", "pade_tf", "simulate", "excitation", "ForeignCase", "make_case", "score", "run_othersim",
    "format_report", "main", "FREE_DESIGNS", "CONVENTIONS", "FreeCase", "make_free_case",
]

#: Foreign kinds of each verdict name (the names of ``shared/interfaces.md``).
EFFECT_KINDS: dict[str, tuple[str, str]] = {
    "static_nonlinearity": ("power", "knee"),
    "asymmetric_dynamics": ("rate_limit", "switched_2nd"),
    "charge_drift": ("screening", "offset"),
    "saturation": ("slew", "soft_stroke"),
    "time_delay": ("pade", "shift"),
    "sensor_nonlinearity": ("quadratic", "exponential"),
    "load_mass": ("coupled", "heavier_mode"),
    "hysteresis": ("prandtl_ishlinskii", "duhem"),
}
_NAMES = tuple(EFFECT_KINDS)
_NONE = "none"
_Q_REF_KV2 = 25.0   # screening reference, kV^2 (5 kV held)
_V_REF_ABS_KV = 5.0  # offset-drift reference, kV


@dataclass(frozen=True)
class ForeignEffect:
    """One foreign effect: the verdict name it should be called, its kind and parameters.

    Attributes
    ----------
    name : str
        The verdict name (``shared/interfaces.md``) a correct diagnosis gives it.
    kind : str
        One of ``EFFECT_KINDS[name]`` (see the module docstring).
    params : dict
        Physical parameters, units in the keys (``_kv``, ``_mm``, ``_s``, ``_hz``, ``_g``).
    """

    name: str
    kind: str
    params: dict[str, float] = field(default_factory=dict)

    def __post_init__(self) -> None:
        if self.name not in EFFECT_KINDS:
            raise ValueError(f"unknown effect {self.name!r}; expected one of {', '.join(_NAMES)}")
        if self.kind not in EFFECT_KINDS[self.name]:
            raise ValueError(f"{self.name} kind must be one of {EFFECT_KINDS[self.name]}, got {self.kind!r}")


def sample_foreign(name: str, rng: np.random.Generator, kind: str | None = None) -> ForeignEffect:
    """A random foreign effect ``name`` (kind drawn if not given).

    Ranges are chosen so that each effect is visible above 0.003-0.015 mm of laser
    noise on the excitation of :func:`excitation` (as on a real rig), but they are not
    the project's ranges.

    Parameters
    ----------
    name : str
        Verdict name.
    rng : numpy.random.Generator
        Source of the draws.
    kind : str, optional
        One of ``EFFECT_KINDS[name]``.

    Returns
    -------
    ForeignEffect
    """
    kinds = EFFECT_KINDS[name]
    kind = kind or kinds[int(rng.integers(2))]
    u = rng.uniform
    sgn = 1.0 if rng.random() < 0.5 else -1.0
    p: dict[str, float]
    if name == "static_nonlinearity":
        if kind == "power":
            p = {"exponent": u(1.3, 1.8), "v_ref_kv": u(3.5, 5.0)}
        else:
            ratio = u(0.45, 0.7) if rng.random() < 0.5 else u(1.5, 2.0)
            p = {"v_knee_kv": u(3.0, 4.5), "ratio": ratio, "v_ref_kv": u(3.5, 5.0)}
    elif name == "asymmetric_dynamics":
        if kind == "rate_limit":
            p = {"rate_mm_s": u(8.0, 20.0)}
        else:
            p = {"f_up_hz": u(40.0, 80.0), "f_down_hz": u(3.0, 7.0), "zeta_down": u(1.0, 2.0)}
    elif name == "charge_drift":
        if kind == "screening":
            p = {"tau_s": u(40.0, 200.0), "share": u(0.12, 0.3)}
        else:
            p = {"tau_s": u(40.0, 200.0), "offset_mm": sgn * u(0.4, 1.0)}
    elif name == "saturation":
        if kind == "slew":
            p = {"slew_kv_s": u(20.0, 45.0)}
        else:
            p = {"knee_mm": u(5.5, 7.0), "room_mm": u(0.3, 0.8)}
    elif name == "time_delay":
        p = {"delay_s": u(0.006, 0.03)}
    elif name == "sensor_nonlinearity":
        if kind == "quadratic":
            p = {"curvature_per_mm": sgn * u(0.02, 0.05), "center_mm": u(3.0, 6.0)}
        else:
            p = {"scale_mm": sgn * u(8.0, 18.0), "center_mm": u(3.0, 6.0)}
    elif name == "load_mass":
        if kind == "coupled":
            p = {"mass_g": u(20.0, 80.0), "f_n_hz": u(6.0, 14.0), "zeta": u(0.1, 0.35), "sag_mm": u(0.0, 0.3)}
        else:
            p = {"mass_ratio": u(1.0, 3.0)}
    else:  # hysteresis
        if kind == "prandtl_ishlinskii":
            p = {"r_max_kv": u(0.3, 0.8), "share": u(0.3, 0.7)}
        else:
            p = {"lag_kv": u(0.2, 0.8), "share": u(0.4, 0.8)}
    return ForeignEffect(name, kind, {k: float(v) for k, v in p.items()})


# --------------------------------------------------------------------------- elements

def play_operator(v: np.ndarray, radius: float, p0: float | None = None) -> np.ndarray:
    """The play (backlash) operator of half-width ``radius`` (same unit as ``v``).

    ``p`` stays put while ``|v - p| <= radius`` and is dragged along otherwise:
    ``p_k = min(max(p_{k-1}, v_k - radius), v_k + radius)``.

    Parameters
    ----------
    v : ndarray, shape (n,)
        Input samples.
    radius : float
        Half-width of the play, >= 0.
    p0 : float, optional
        Initial output (default ``v[0]``).

    Returns
    -------
    ndarray, shape (n,)
    """
    out = np.empty(v.size)
    p = float(v[0]) if p0 is None else float(p0)
    r = float(radius)
    for k, x in enumerate(v.tolist()):
        if x - r > p:
            p = x - r
        elif x + r < p:
            p = x + r
        out[k] = p
    return out


def _pi_weights(r_max_kv: float, share: float, n: int = 5) -> tuple[np.ndarray, np.ndarray]:
    radii = np.linspace(r_max_kv / n, r_max_kv, n)
    w = np.linspace(1.0, 2.0, n)
    return radii, share * w / w.sum()


def prandtl_ishlinskii(v_kv: np.ndarray, r_max_kv: float, share: float) -> np.ndarray:
    """Prandtl-Ishlinskii hysteresis: ``(1 - share) v + sum_i w_i play_{r_i}(v)`` (kV).

    Five play operators with radii ``r_max_kv * (1..5) / 5`` and weights growing
    linearly (1 to 2), summing to ``share``. For a sine of amplitude ``A`` the loop
    in the (v, v_eff) plane has area ``sum_i w_i 4 r_i (A - r_i)`` over ``r_i < A``.

    Parameters
    ----------
    v_kv : ndarray, shape (n,)
        Applied voltage, kV.
    r_max_kv : float
        Largest play radius, kV.
    share : float
        Share of the input through the hysteretic path, in [0, 1].

    Returns
    -------
    ndarray, shape (n,)
        Effective voltage, kV.
    """
    radii, w = _pi_weights(r_max_kv, share)
    out = (1.0 - share) * v_kv
    for r, wi in zip(radii, w):
        out = out + wi * play_operator(v_kv, r)
    return out


def duhem(v_kv: np.ndarray, lag_kv: float, share: float) -> np.ndarray:
    """Rate-independent Duhem hysteresis: ``(1 - share) v + share w``, ``dw = |dv| (v - w) / lag_kv``.

    On a monotone branch from ``w = v = v0`` the state is ``w = v - lag (1 - exp(-(v -
    v0) / lag))`` (rising): it lags the input by up to ``lag_kv`` (kV). Each sample is
    updated exactly for a step with ``v`` held at its new value.

    Parameters
    ----------
    v_kv : ndarray, shape (n,)
        Applied voltage, kV.
    lag_kv : float
        Voltage scale of the memory, kV (> 0).
    share : float
        Share of the input through the hysteretic path.

    Returns
    -------
    ndarray, shape (n,)
        Effective voltage, kV.
    """
    w = float(v_kv[0])
    out = np.empty(v_kv.size)
    prev = w
    inv = 1.0 / lag_kv
    for k, x in enumerate(v_kv.tolist()):
        w = x - (x - w) * math.exp(-abs(x - prev) * inv)
        prev = x
        out[k] = w
    return (1.0 - share) * v_kv + share * out


def pade_tf(delay_s: float) -> tuple[np.ndarray, np.ndarray]:
    """The [3/3] Pade approximant of ``exp(-s delay_s)``: (num, den), descending powers of s."""
    d = float(delay_s)
    c = [1.0, d / 2.0, d * d / 10.0, d ** 3 / 120.0]
    den = np.array([c[3], c[2], c[1], c[0]])
    num = np.array([-c[3], c[2], -c[1], c[0]])
    return num, den


class FohSystem:
    """A proper continuous transfer function discretised exactly for piecewise-linear input.

    Same recursion as :func:`scipy.signal.lsim` (``x_{k+1} = Ad x_k + Bd0 u_k + Bd1
    u_{k+1}``), started at the steady state of the first input sample.

    Parameters
    ----------
    num, den : array_like
        Transfer function, descending powers of s (no pole at 0).
    dt_s : float
        Sample period, s.
    """

    def __init__(self, num: np.ndarray, den: np.ndarray, dt_s: float) -> None:
        a, b, c, d = signal.tf2ss(num, den)
        n = a.shape[0]
        m = np.zeros((n + 2, n + 2))
        m[:n, :n] = a * dt_s
        m[:n, n] = b[:, 0] * dt_s
        m[n, n + 1] = 1.0
        e = linalg.expm(m)
        self.ad = e[:n, :n]
        self.bd1 = e[:n, n + 1]
        self.bd0 = e[:n, n] - self.bd1
        self.a, self.b, self.c, self.d = a, b[:, 0], c[0], float(d[0, 0])

    def steady_state(self, u0: float) -> np.ndarray:
        """State (of :func:`scipy.signal.tf2ss`'s realisation) at rest under a constant ``u0``."""
        return np.linalg.solve(-self.a, self.b * u0)

    def run(self, u: np.ndarray) -> np.ndarray:
        """Output for input samples ``u`` (shape (n,)), from the steady state of ``u[0]``."""
        x = self.steady_state(float(u[0]))
        xs = np.empty((u.size, x.size))
        ad, b0, b1 = self.ad, self.bd0, self.bd1
        ul = u.tolist()
        for k in range(u.size):
            xs[k] = x
            if k + 1 < u.size:
                x = ad @ x + b0 * ul[k] + b1 * ul[k + 1]
        return xs @ self.c + self.d * u


def _leaky(x: np.ndarray, tau_s: float, dt_s: float) -> np.ndarray:
    """First-order low-pass ``tau dq/dt = x - q`` from ``q(0) = 0``, exact for each sample held over its step."""
    a = math.exp(-dt_s / tau_s)
    return signal.lfilter([0.0, 1.0 - a], [1.0, -a], x)


def _loaded_den(den: np.ndarray, mass_ratio: float) -> np.ndarray:
    """P(s)'s denominator with one complex pole pair's inertia times ``1 + mass_ratio`` (same DC)."""
    poles = np.roots(den)
    cpx = [p for p in poles if p.imag > 1e-9]
    first = cpx[0]
    wn2 = abs(first) ** 2
    two_zw = -2.0 * first.real
    rest = [p for p in poles if abs(p - first) > 1e-12 and abs(p - np.conj(first)) > 1e-12]
    new_pair = np.array([1.0 + mass_ratio, two_zw, wn2])
    return np.real(np.polymul(np.poly(rest), new_pair)) * den[0]


# --------------------------------------------------------------------------- simulator

def simulate(u_kv: np.ndarray, rate_hz: float, effects: list[ForeignEffect] | tuple[ForeignEffect, ...] = (),
             *, oversample: int = 4, return_true: bool = False) -> np.ndarray | tuple[np.ndarray, np.ndarray]:
    """The measured stroke (mm, noise-free) of the foreign actuator for a command (kV).

    Parameters
    ----------
    u_kv : ndarray, shape (n,)
        Command at ``rate_hz``, kV; linearly interpolated between samples.
    rate_hz : float
        Log sample rate, Hz.
    effects : sequence of ForeignEffect
        At most one per verdict name.
    oversample : int
        Internal steps per log sample.
    return_true : bool
        Also return the true stroke (before the sensor map), mm.

    Returns
    -------
    ndarray, shape (n,)  (or a pair of them with ``return_true``)
    """
    u_kv = np.asarray(u_kv, float)
    by = {e.name: e for e in effects}
    if len(by) != len(effects):
        raise ValueError("at most one effect per name")
    m = int(oversample)
    dt = 1.0 / (rate_hz * m)
    n = u_kv.size
    tf = np.arange((n - 1) * m + 1) * dt
    v = np.interp(tf, np.arange(n) / rate_hz, u_kv)

    e = by.get("time_delay")
    if e is not None:
        if e.kind == "shift":
            v = np.interp(tf - e.params["delay_s"], tf, v, left=v[0])
        else:
            v = FohSystem(*pade_tf(e.params["delay_s"]), dt).run(v)
    e = by.get("saturation")
    if e is not None and e.kind == "slew":
        step = e.params["slew_kv_s"] * dt
        out = np.empty(v.size)
        y = float(v[0])
        for k, x in enumerate(v.tolist()):
            y += min(max(x - y, -step), step)
            out[k] = y
        v = out
    applied = v
    e = by.get("hysteresis")
    if e is not None:
        v = (prandtl_ishlinskii(v, e.params["r_max_kv"], e.params["share"]) if e.kind == "prandtl_ishlinskii"
             else duhem(v, e.params["lag_kv"], e.params["share"]))
    e = by.get("static_nonlinearity")
    if e is not None:
        vr = e.params["v_ref_kv"]
        if e.kind == "power":
            v = vr * np.sign(v) * np.abs(v / vr) ** e.params["exponent"]
        else:
            vk, ratio = e.params["v_knee_kv"], e.params["ratio"]
            g = lambda x: np.where(x <= vk, x, vk + ratio * (x - vk))  # noqa: E731
            v = g(v) * vr / float(g(np.array(vr)))  # f(v_ref) = v_ref
    drift = by.get("charge_drift")
    if drift is not None and drift.kind == "screening":
        q = _leaky(applied ** 2, drift.params["tau_s"], dt)
        v = v * (1.0 - drift.params["share"] * q / _Q_REF_KV2)

    num, den = paper.plant_tf()
    e = by.get("load_mass")
    if e is not None and e.kind == "heavier_mode":
        den = _loaded_den(den, e.params["mass_ratio"])
    z = FohSystem(num, den, dt).run(v)
    if e is not None and e.kind == "coupled":
        wn = 2 * math.pi * e.params["f_n_hz"]
        z = FohSystem([2 * e.params["zeta"] * wn, wn * wn], [1.0, 2 * e.params["zeta"] * wn, wn * wn], dt).run(z)
        z = z - e.params["sag_mm"]

    e = by.get("asymmetric_dynamics")
    if e is not None:
        out = np.empty(z.size)
        y = float(z[0])
        if e.kind == "rate_limit":
            step = e.params["rate_mm_s"] * dt
            for k, x in enumerate(z.tolist()):
                y = x if x >= y else max(x, y - step)
                out[k] = y
        else:
            wu, wd = 2 * math.pi * e.params["f_up_hz"], 2 * math.pi * e.params["f_down_hz"]
            zu, zd = 0.9, e.params["zeta_down"]
            vel = 0.0
            for k, x in enumerate(z.tolist()):
                w, zt = (wu, zu) if x >= y else (wd, zd)
                # semi-implicit step: damping and stiffness implicit in the velocity
                vel = (vel + dt * w * w * (x - y)) / (1.0 + dt * (2 * zt * w + dt * w * w))
                y += dt * vel
                out[k] = y
        z = out
    e = by.get("saturation")
    if e is not None and e.kind == "soft_stroke":
        zk, room = e.params["knee_mm"], e.params["room_mm"]
        z = np.where(z <= zk, z, zk + room * np.tanh((z - zk) / room))
    if drift is not None and drift.kind == "offset":
        q = _leaky(np.abs(applied), drift.params["tau_s"], dt)
        z = z + drift.params["offset_mm"] * q / _V_REF_ABS_KV
    true_z = z
    e = by.get("sensor_nonlinearity")
    if e is not None:
        zc = e.params["center_mm"]
        if e.kind == "quadratic":
            z = z + e.params["curvature_per_mm"] * (z - zc) ** 2
        else:
            b = e.params["scale_mm"]
            z = zc + b * np.expm1((z - zc) / b)
    if return_true:
        return z[::m].copy(), true_z[::m].copy()
    return z[::m].copy()


# --------------------------------------------------------------------------- cases

def excitation(rng: np.random.Generator, rate_hz: float, *, short: bool = False) -> tuple[np.ndarray, dict]:
    """A researcher's command (kV) at ``rate_hz``, and what it holds.

    -1 kV for 1 s and 0 kV for 1 s (charge reversal), a slow triangle 0.5-6 kV (12 s,
    the static map), three DC offsets from {2, 3, 4, 5, 6} kV (one of them >= 5 kV) in
    random order each held 1 s then swept by a textbook linear chirp 0.1-15 Hz
    (amplitude 0.7-1.0 kV, 12-16 s, once or twice), a flat random-phase multisine
    0.1-10 Hz around 4 kV (0.5 kV rms, 8 s), and steps 1-3-5-3-1-0 kV (1.5 s each).
    ``short`` keeps one offset, a 4 s chirp and no multisine (tests).

    Parameters
    ----------
    rng : numpy.random.Generator
        Draws offsets, amplitude, durations, phases.
    rate_hz : float
        Sample rate, Hz.
    short : bool
        A short version (about 15 s).

    Returns
    -------
    u_kv : ndarray
        The command, kV.
    info : dict
        ``offsets_kv``, ``chirp_amplitude_kv``, ``chirp_s``, ``repeats``, ``duration_s``.
    """
    def seg(s: float) -> np.ndarray:
        return np.arange(int(round(s * rate_hz))) / rate_hz

    def hold(v: float, s: float) -> np.ndarray:
        return np.full(int(round(s * rate_hz)), float(v))

    hi = [5.0, 6.0][int(rng.integers(2))]
    others = [2.0, 3.0, 4.0]
    rng.shuffle(others)
    offsets = [hi] + others[:2]
    rng.shuffle(offsets)
    amp = float(rng.uniform(0.7, 1.0))
    dur = float(rng.uniform(12.0, 16.0))
    reps = int(rng.integers(1, 3))
    if short:
        offsets, dur, reps = offsets[:1], 4.0, 1
    parts = [hold(-1.0, 1.0), hold(0.0, 1.0)]
    tri_s = 6.0 if short else 12.0
    tt = seg(tri_s)
    parts.append(0.5 + 5.5 * (1.0 - np.abs(2.0 * tt / tri_s - 1.0)))
    tc = seg(dur)
    ch = amp * np.sin(2 * np.pi * (0.1 * tc + 0.5 * (15.0 - 0.1) / dur * tc * tc))
    for v in offsets:
        parts.append(hold(v, 1.0))
        parts.append(v + np.tile(ch, reps))
    if not short:
        tm = seg(8.0)
        f = np.arange(1, 81) / 8.0  # 0.125-10 Hz
        ph = rng.uniform(0, 2 * np.pi, f.size)
        ms = np.sin(2 * np.pi * np.outer(tm, f) + ph).sum(axis=1)
        parts.append(4.0 + 0.5 * ms / ms.std())
    for v in (1.0, 3.0, 5.0, 3.0, 1.0, 0.0):
        parts.append(hold(v, 1.5))
    u = np.concatenate(parts)
    return u, {"offsets_kv": offsets, "chirp_amplitude_kv": amp, "chirp_s": dur, "repeats": reps,
               "duration_s": u.size / rate_hz}


@dataclass(frozen=True)
class ForeignCase:
    """A generated case; the labels live only here, never in its file."""

    index: int
    seed: int
    effects: tuple[ForeignEffect, ...]
    rate_hz: float
    noise_mm: float
    excitation: dict
    path: str

    @property
    def labels(self) -> list[str]:
        """The verdict names of the case's effects."""
        return [e.name for e in self.effects]


#: Laser quantisation step, mm (3 mm/V on a 12-bit 0-3.3 V ADC).
LASER_LSB_MM = paper.ADC_FULL_SCALE_V * paper.LASER_MM_PER_V / 2 ** paper.ADC_BITS


def make_case(index: int, seed: int, effects: tuple[ForeignEffect, ...], directory: str, *,
              short: bool = False) -> ForeignCase:
    """Simulate one case with ``effects`` and write its unlabelled log (``.npz``) to ``directory``.

    The file holds ``t_s`` (s), ``voltage_kv``, ``stroke_mm`` and the nominal ``num``/``den``
    of P(s) only. Rate: 500 Hz or 1 kHz; white noise 0.003-0.015 mm rms; 12-bit laser
    quantisation (:data:`LASER_LSB_MM`).
    """
    rng = np.random.default_rng(seed)
    rate = [500.0, 1000.0][int(rng.integers(2))]
    u, info = excitation(rng, rate, short=short)
    z = simulate(u, rate, list(effects))
    noise = float(rng.uniform(0.003, 0.015))
    y = np.round((z + noise * rng.standard_normal(u.size)) / LASER_LSB_MM) * LASER_LSB_MM
    t = np.arange(u.size) / rate
    num, den = paper.plant_tf()
    path = os.path.join(directory, f"other_{index:03d}.npz")
    np.savez_compressed(path, t_s=t, voltage_kv=u, stroke_mm=y, num=num, den=den)
    return ForeignCase(index, seed, tuple(effects), rate, noise, info, path)


# --------------------------------------------------------------------------- effect-free logs of many designs

#: Designs of the effect-free calibration logs.
FREE_DESIGNS = ("paper", "chirp", "multisine", "prbs", "closed_loop")
#: Sampling conventions: input held (zoh) or linearly interpolated (foh) over each sample; output at
#: the sample's start, or mid-sample (centred).
CONVENTIONS = ("zoh", "foh", "centred")


def _design_input(design: str, rng: np.random.Generator, rate_hz: float, duration_s: float) -> np.ndarray:
    """An open-loop command (kV) of ``design`` at ``rate_hz`` (``paper`` uses :func:`excitation`)."""
    n = int(round(duration_s * rate_hz))
    t = np.arange(n) / rate_hz
    off = float(rng.uniform(2.5, 5.5))
    if design == "paper":
        return excitation(rng, rate_hz)[0]
    if design == "chirp":  # one logarithmic chirp 0.1-20 Hz after a settle at the offset
        f0, f1 = 0.1, float(rng.uniform(12.0, 20.0))
        ts = np.maximum(t - 1.0, 0.0)
        T = max(duration_s - 1.0, 1.0)
        k = (f1 / f0) ** (1.0 / T)
        ph = 2 * np.pi * f0 * (k ** ts - 1.0) / math.log(k)
        return off + float(rng.uniform(0.6, 1.2)) * np.where(t >= 1.0, np.sin(ph), 0.0)
    if design == "multisine":  # random-phase multisine 0.05-15 Hz, period 20 s
        per = 20.0
        f = np.arange(1, int(15.0 * per) + 1) / per
        phs = rng.uniform(0, 2 * np.pi, f.size)
        tm = np.arange(int(round(per * rate_hz))) / rate_hz
        ms = np.zeros(tm.size)
        for fi, pi in zip(f, phs):
            ms += np.sin(2 * np.pi * fi * tm + pi)
        ms = np.resize(ms / ms.std(), n)
        return off + float(rng.uniform(0.4, 0.8)) * ms
    if design == "prbs":  # random level steps held 0.05-0.6 s
        out = np.empty(n)
        i = 0
        while i < n:
            m = int(rng.uniform(0.05, 0.6) * rate_hz) + 1
            out[i:i + m] = off + float(rng.uniform(-1.5, 1.5))
            i += m
        return out
    raise ValueError(f"unknown design {design!r}")


def _closed_loop(rng: np.random.Generator, rate_hz: float, duration_s: float, noise: np.ndarray
                 ) -> tuple[np.ndarray, np.ndarray]:
    """A PI loop at ``rate_hz`` on P(s) (zero-order hold) tracking random stroke steps, measured with
    ``noise`` in the loop: (applied voltage kV, noise-free stroke mm)."""
    num, den = paper.plant_tf()
    a, b, c, d = signal.cont2discrete(signal.tf2ss(num, den), 1.0 / rate_hz, method="zoh")[:4]
    n = noise.size
    g0 = float(np.polyval(num, 0) / np.polyval(den, 0))
    ki = 2 * math.pi * 1.0 / g0  # about a 1 Hz loop on the static gain
    kp = 0.2 / g0
    ref = np.empty(n)
    i = 0
    while i < n:
        m = int(rng.uniform(0.5, 2.0) * rate_hz) + 1
        ref[i:i + m] = g0 * float(rng.uniform(2.0, 6.0))
        i += m
    x = np.linalg.solve(np.eye(a.shape[0]) - a, b[:, 0] * ref[0] / g0)
    integ = ref[0] / g0
    u = np.empty(n)
    z = np.empty(n)
    cc, bb = c[0], b[:, 0]
    for k in range(n):
        z[k] = float(cc @ x)
        e = ref[k] - (z[k] + noise[k])
        integ += ki * e / rate_hz
        u[k] = min(max(integ + kp * e, 0.0), 9.0)
        x = a @ x + bb * u[k]
    return u, z


def _sampled(u: np.ndarray, rate_hz: float, convention: str, offset_samples: float, m: int = 8) -> np.ndarray:
    """P(s)'s noise-free output (mm) sampled by ``convention`` and ``offset_samples`` (output late > 0)."""
    num, den = paper.plant_tf()
    from hasel.lti import zoh_sos

    fine = (np.repeat(u, m) if convention in ("zoh", "centred")
            else np.interp(np.arange(u.size * m) / m, np.arange(u.size), u))
    sos = zoh_sos(num, den, 1.0 / (rate_hz * m), output="start")
    z, _ = signal.sosfilt(sos, fine, zi=signal.sosfilt_zi(sos) * fine[0])
    shift = (m // 2 if convention == "centred" else 0) - int(round(offset_samples * m))
    idx = np.clip(np.arange(u.size) * m + shift, 0, z.size - 1)
    return z[idx]


def _coloured(rng: np.random.Generator, n: int, rate_hz: float, sd: float, kind: str) -> np.ndarray:
    """Measurement noise of rms ``sd``: ``white``, ``coloured`` (white through a first-order low-pass at
    2-20 Hz plus a white tenth), or ``wander`` (white plus a slow random offset drift of 2-6 x sd)."""
    w = rng.standard_normal(n)
    if kind == "white":
        return sd * w
    if kind == "coloured":
        fc = float(rng.uniform(2.0, 20.0))
        a = math.exp(-2 * math.pi * fc / rate_hz)
        x = signal.lfilter([1.0 - a], [1.0, -a], w)
        x = x / x.std()
        return sd * (0.95 * x + 0.3 * rng.standard_normal(n))
    if kind == "wander":
        a = math.exp(-1.0 / (rate_hz * float(rng.uniform(5.0, 20.0))))
        drift = signal.lfilter([1.0], [1.0, -a], rng.standard_normal(n))
        drift = signal.detrend(drift, type="constant")
        drift = drift / max(np.abs(drift).max(), 1e-12) * float(rng.uniform(2.0, 6.0)) * sd
        return sd * w + drift
    raise ValueError(f"unknown noise kind {kind!r}")


@dataclass(frozen=True)
class FreeCase:
    """An effect-free log of the tuning corpus: how it was made (its file holds only the data)."""

    index: int
    design: str
    rate_hz: float
    convention: str
    offset_samples: float
    noise: str
    noise_mm: float
    path: str


def make_free_case(index: int, seed: int, directory: str, *, design: str | None = None,
                   rate_hz: float | None = None, convention: str | None = None,
                   offset_samples: float | None = None, noise: str | None = None,
                   duration_s: float | None = None) -> FreeCase:
    """Write one effect-free log of P(s) (``.npz`` like :func:`make_case`) and return how it was made.

    Drawn unless given: the design (:data:`FREE_DESIGNS`), the rate (200 Hz to 5 kHz), the
    sampling convention (:data:`CONVENTIONS`), a fractional timing offset between the
    input and output samples (-0.5 to 0.5 samples, a third of the logs none), the noise
    (white, coloured or with a slow offset wander; 0.003-0.015 mm rms) and the length
    (shorter at high rates). Quantised like the laser (:data:`LASER_LSB_MM`).
    """
    rng = np.random.default_rng(seed)
    design = design or FREE_DESIGNS[int(rng.integers(len(FREE_DESIGNS)))]
    rate = float(rate_hz or [200.0, 500.0, 1000.0, 2000.0, 5000.0][int(rng.integers(5))])
    conv = convention or CONVENTIONS[int(rng.integers(len(CONVENTIONS)))]
    off = float(offset_samples if offset_samples is not None
                else (0.0 if rng.random() < 1 / 3 else rng.uniform(-0.5, 0.5)))
    kind = noise or ("white", "coloured", "wander")[int(rng.integers(3))]
    sd = float(rng.uniform(0.003, 0.015))
    dur = float(duration_s or (40.0 if rate <= 1000.0 else 20.0))
    n = int(round(dur * rate))
    nz = _coloured(rng, n, rate, sd, kind)
    if design == "closed_loop":
        u, _ = _closed_loop(rng, rate, dur, nz)
        conv = "zoh" if convention is None else conv  # a controller holds its command
    else:
        u = _design_input(design, rng, rate, dur)
        n = u.size
        nz = _coloured(rng, n, rate, sd, kind)
    z = _sampled(u, rate, conv, off)
    y = np.round((z + nz[:z.size]) / LASER_LSB_MM) * LASER_LSB_MM
    t = np.arange(u.size) / rate
    num, den = paper.plant_tf()
    path = os.path.join(directory, f"free_{index:03d}.npz")
    np.savez_compressed(path, t_s=t, voltage_kv=u, stroke_mm=y, num=num, den=den)
    return FreeCase(index, design, rate, conv, off, kind, sd, path)


def _draw_labels(n_cases: int, rng: np.random.Generator) -> list[tuple[tuple[str, str], ...]]:
    """(name, kind) tuples per case: a fifth none, a fifth pairs, the rest singles cycling names and kinds."""
    n_none = max(1, round(n_cases / 5))
    n_pair = max(1, round(n_cases / 5)) if n_cases >= 3 else 0
    n_single = n_cases - n_none - n_pair
    out: list[tuple[tuple[str, str], ...]] = [()] * n_none
    order = list(_NAMES)
    rng.shuffle(order)
    for i in range(n_single):
        nm = order[i % len(order)]
        out.append(((nm, EFFECT_KINDS[nm][(i // len(order)) % 2]),))
    for _ in range(n_pair):
        a, b = rng.choice(len(_NAMES), 2, replace=False)
        out.append(tuple((_NAMES[int(j)], EFFECT_KINDS[_NAMES[int(j)]][int(rng.integers(2))]) for j in (a, b)))
    perm = rng.permutation(len(out))
    return [out[i] for i in perm]


def score(cases: list[ForeignCase], results: list[dict]) -> dict:
    """Reveal the labels and score the verdicts.

    - **top-1** (single-effect and no-effect cases): the first named effect is the true
      one; for no effect, nothing named.
    - **pair_both_named**: both true names are among the named effects (any rank);
      **pair_first_two**: they are exactly the first two.
    - **false alarm**: something named on a no-effect case.
    - **shrink**: ``(nrmse_nominal - nrmse_augmented) / (nrmse_nominal - floor)``.

    Parameters
    ----------
    cases : list of ForeignCase
    results : list of dict
        Worker results (``path``, ``names``, ``nrmse_*``, ``floor``, ``seconds``).

    Returns
    -------
    dict
        Figures, ``confusion`` (truth name -> first named -> count), ``confusion_by_kind``
        and ``cases`` (one row per case).
    """
    by_path = {r["path"]: r for r in results}
    rows = []
    for c in cases:
        r = by_path[c.path]
        named, truth = r["names"], c.labels
        first = named[0] if named else _NONE
        if not truth:
            ok = not named
        elif len(truth) == 1:
            ok = first == truth[0]
        else:
            ok = sorted(named[:2]) == sorted(truth)
        gap = (r.get("nrmse_nominal", 0.0) - r.get("floor", 0.0))
        shrink = ((r["nrmse_nominal"] - r["nrmse_augmented"]) / gap) if truth and "floor" in r and gap > 0 else None
        rows.append({"case": c.index, "seed": c.seed, "rate_hz": c.rate_hz, "noise_mm": c.noise_mm,
                     "truth": [f"{e.name}:{e.kind}" for e in c.effects], "truth_names": truth,
                     "params": {e.name: e.params for e in c.effects}, "named": named, "correct": bool(ok),
                     "any_true_named": bool(set(truth) & set(named)), "shrink": shrink,
                     **{k: r.get(k) for k in ("nrmse_nominal", "nrmse_augmented", "floor", "seconds", "error",
                                              "effects", "rounds", "working_rate_hz", "model_source")},
                     "excitation": c.excitation})
    single = [x for x in rows if len(x["truth"]) <= 1]
    singles_eff = [x for x in rows if len(x["truth"]) == 1]
    pairs = [x for x in rows if len(x["truth"]) == 2]
    none = [x for x in rows if not x["truth"]]
    eff = [x for x in rows if x["truth"]]
    conf: dict[str, Counter] = {}
    conf_k: dict[str, Counter] = {}
    for x in single:
        t = x["truth_names"][0] if x["truth"] else _NONE
        f = x["named"][0] if x["named"] else _NONE
        conf.setdefault(t, Counter())[f] += 1
        conf_k.setdefault(x["truth"][0] if x["truth"] else _NONE, Counter())[f] += 1
    shrinks = [x["shrink"] for x in eff if x["shrink"] is not None]
    frac = lambda xs, key: (sum(bool(key(x)) for x in xs) / len(xs)) if xs else None  # noqa: E731
    return {
        "n_cases": len(rows),
        "top1_accuracy": frac(single, lambda x: x["correct"]), "n_single_or_none": len(single),
        "top1_effect_only": frac(singles_eff, lambda x: x["correct"]), "n_single": len(singles_eff),
        "pair_both_named": frac(pairs, lambda x: set(x["truth_names"]) <= set(x["named"])),
        "pair_first_two": frac(pairs, lambda x: x["correct"]),
        "pair_one_named": frac(pairs, lambda x: x["any_true_named"]), "n_pairs": len(pairs),
        "false_alarms": sum(bool(x["named"]) for x in none), "n_none": len(none),
        "misses": sum(not x["named"] for x in eff), "n_effect_cases": len(eff),
        "errors": sum(bool(x.get("error")) for x in rows),
        "median_shrink": float(np.median(shrinks)) if shrinks else None,
        "seconds_per_case": float(np.mean([x["seconds"] for x in rows])) if rows else None,
        "confusion": {k: dict(v) for k, v in conf.items()},
        "confusion_by_kind": {k: dict(v) for k, v in conf_k.items()},
        "cases": rows,
    }


def format_report(s: dict, title: str = "other-simulator check") -> str:
    """Plain-text summary of :func:`score`'s dict (confusion rows: truth, columns: first named)."""
    def pct(x: float | None) -> str:
        return "n/a" if x is None else f"{100 * x:.0f} %"

    lines = [f"{title}: {s['n_cases']} cases",
             f"  top-1 (single or none): {pct(s['top1_accuracy'])} of {s['n_single_or_none']}; "
             f"single effects only: {pct(s['top1_effect_only'])} of {s['n_single']}",
             f"  pairs: both named {pct(s['pair_both_named'])}, exactly the first two {pct(s['pair_first_two'])}, "
             f"at least one {pct(s['pair_one_named'])} of {s['n_pairs']}",
             f"  false alarms: {s['false_alarms']} of {s['n_none']}; misses: {s['misses']} of "
             f"{s['n_effect_cases']}; errors: {s['errors']}",
             f"  median held-out shrink: {pct(s['median_shrink'])}",
             f"  time per case: {s['seconds_per_case']:.1f} s" if s["seconds_per_case"] is not None else "",
             "  confusion by kind (truth -> first named):"]
    for k, row in sorted(s["confusion_by_kind"].items()):
        lines.append(f"    {k:40s} " + ", ".join(f"{n} x{c}" for n, c in sorted(row.items(), key=lambda a: -a[1])))
    wrong = [x for x in s["cases"] if not x["correct"]]
    if wrong:
        lines.append("  wrong cases:")
        for x in wrong:
            lines.append(f"    #{x['case']} truth {x['truth'] or ['none']} named {x['named'] or ['none']}"
                         + (f" ERROR {x['error']}" if x.get("error") else ""))
    return "\n".join(lines)


def run_othersim(n_cases: int, seed: int, progress: Callable[[str], None] | None = None, *,
                 no_model_cases: int = 0, directory: str | None = None, short: bool = False) -> dict:
    """Generate ``n_cases`` foreign cases, diagnose each blind, reveal the labels, score.

    Each log is written to a file with no label and diagnosed in one spawned process
    that receives only the file's path (with the nominal P(s) model). The first
    ``no_model_cases`` cases are diagnosed a second time without a model (the
    diagnosis identifies a linear model from the log) and scored separately.

    Parameters
    ----------
    n_cases : int
        Number of cases (a fifth no-effect, a fifth pairs, the rest single effects
        cycling over the eight names and their two foreign kinds).
    seed : int
        Master seed (case ``i`` uses ``seed * 100003 + i``).
    progress : callable, optional
        Called with one-line messages.
    no_model_cases : int
        Cases also diagnosed without a model.
    directory : str, optional
        Where the case files go (a temporary directory by default).
    short : bool
        Short excitations (tests).

    Returns
    -------
    dict
        :func:`score` of the model runs, plus ``"no_model"`` (:func:`score` of the
        model-free runs, or None) and ``"wall_s"``.
    """
    say = progress or (lambda m: None)
    t0 = time.perf_counter()
    rng = np.random.default_rng(seed)
    labels = _draw_labels(int(n_cases), rng)
    with case_directory(directory, "hasel-othersim-") as directory:
        cases = []
        for i, lab in enumerate(labels):
            cs = seed * 100003 + i
            erng = np.random.default_rng([cs, 1])
            effs = tuple(sample_foreign(nm, erng, kind) for nm, kind in lab)
            cases.append(make_case(i, cs, effs, directory, short=short))
        say(f"generated {len(cases)} cases in {time.perf_counter() - t0:.1f} s")
        jobs = [(c.path, True) for c in cases] + [(c.path, False) for c in cases[:max(0, no_model_cases)]]
        results = diagnose_files(jobs, 1, lambda r: say(result_line(r)))
        s = score(cases, [r for r in results if r["with_model"]])
        nm = [r for r in results if not r["with_model"]]
        s["no_model"] = score(cases[:len(nm)], nm) if nm else None
        s["wall_s"] = time.perf_counter() - t0
        return s


def main(argv: list[str] | None = None) -> int:
    """``python -m hasel_bench.othersim [--cases N] [--seed S] [--no-model K] [--json FILE]``."""
    p = argparse.ArgumentParser(prog="python -m hasel_bench.othersim", description=__doc__.split("\n")[0])
    p.add_argument("--cases", type=int, default=28, help="number of cases (default 28)")
    p.add_argument("--seed", type=int, default=0, help="master seed (default 0)")
    p.add_argument("--no-model", type=int, default=0, help="cases also diagnosed without a model")
    p.add_argument("--json", help="write the full scores here")
    a = p.parse_args(argv)
    s = run_othersim(a.cases, a.seed, say_stderr, no_model_cases=a.no_model)
    print(format_report(s))
    if s["no_model"]:
        print(format_report(s["no_model"], "without a model"))
    write_json(s, a.json)
    return 0


if __name__ == "__main__":
    sys.exit(main())
