"""Effect-free logs of common identification designs, simulated from the paper's P(s).

The oracle of the identification tests and the tuning corpus of ``bench/tune_ident``.
It is written independently of :mod:`hasel.ident` and of the project's plant: the
plant is P(s) of :mod:`hasel.paper` discretised here by scipy's zero-order hold (a DAC
holds each input sample), the excitations are built here, and the output is the
stroke plus white noise. Units: kV in, mm out, s.

Designs (:data:`DESIGNS`), each on offsets 2..7 kV unless said otherwise:

- ``paper_chirp``: one 20 s chirp of the paper's formula ``sin(2 pi k t^2)`` per offset
  (instantaneous frequency 0 -> 40 Hz) after ``settle_s`` at the offset;
- ``paper_chirp3``: the same chirp three times back to back per offset;
- ``linear_chirp``: 0.05 -> 20 Hz linear sweep, 30 s, once per offset;
- ``log_chirp``: 0.05 -> 20 Hz logarithmic sweep, 30 s, twice per offset;
- ``multisine``: odd random-phase multisine 0.1-20 Hz, 10 s period, 3 periods per offset;
- ``prbs``: random binary levels +-0.7 kV about each offset, held for a random
  multiple of 20 ms, 20 s per offset;
- ``random_steps``: random levels uniform in +-1 kV about each offset held 0.05-1 s
  (``hold_s`` of :func:`make_log` sets other bounds);
- ``voltage_steps``: a staircase 0, 2, 4, 6, 4, 2, 0 ... kV, 1.5 s per level, twice;
- ``closed_loop``: the paper's dual-mode PID at 200 Hz on the noisy stroke, reference
  2 -> 4 -> 6 -> 4 -> 2 mm, 2 s each, three times; the log holds the applied voltage
  (``loop_gain`` of :func:`make_log` scales the three PID gains).

``precondition=True`` puts 1 s at -1 kV (then 0.2 s at 0 kV) before each offset.

Measurement knobs of :func:`make_log` (all off by default): the sampling ``convention``
(``"zoh"``: input held over each sample; ``"foh"``: input linearly interpolated between
samples; ``"centred"``: output read mid-sample), a fractional ``offset_samples`` between
input and output samples (output late > 0), the ``noise_kind`` (``"white"``,
``"coloured"``: white through a first-order low-pass at ``noise_fc_hz``, ``"wander"``:
white plus a slow offset drift of 4 x its rms), ``lsb_mm`` (quantisation of the stroke)
and ``amplitude`` (a factor on every excitation). Other conventions than a plain ZOH
are simulated on a grid 8 times finer.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from scipy import signal

from hasel import paper

DESIGNS = ("paper_chirp", "paper_chirp3", "linear_chirp", "log_chirp", "multisine", "prbs", "random_steps",
           "voltage_steps", "closed_loop")
OFFSETS_KV = (2.0, 3.0, 4.0, 5.0, 6.0, 7.0)


@dataclass
class Log:
    """A simulated log: times (s), applied voltage (kV), measured stroke (mm) and what made it."""

    t_s: np.ndarray
    u_kv: np.ndarray
    y_mm: np.ndarray
    design: str
    rate_hz: float
    meta: dict = field(default_factory=dict)


def plant_discrete(rate_hz: float) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """P(s) as a ZOH state-space model ``(A, B, C, D)`` at ``rate_hz`` (kV -> mm)."""
    num, den = paper.plant_tf()
    A, B, C, D = signal.tf2ss(num, den)
    Ad, Bd, Cd, Dd, _ = signal.cont2discrete((A, B, C, D), 1.0 / rate_hz, method="zoh")
    return Ad, Bd, Cd, Dd


def static_gain() -> float:
    """P(0), mm/kV."""
    num, den = paper.plant_tf()
    return float(num[-1] / den[-1])


def _simulate(u: np.ndarray, rate_hz: float) -> np.ndarray:
    """Stroke of P(s) for the held input samples ``u`` starting at rest at ``u[0]``."""
    Ad, Bd, Cd, Dd = plant_discrete(rate_hz)
    x0 = np.linalg.solve(np.eye(Ad.shape[0]) - Ad, Bd[:, 0] * u[0])
    _, y, _ = signal.dlsim((Ad, Bd, Cd, Dd, 1.0 / rate_hz), u, x0=x0)
    return np.asarray(y).ravel()


def random_levels(rng: np.random.Generator, n: int, lo_kv: float, hi_kv: float,
                  hold_samples: tuple[int, int] = (20, 200)) -> np.ndarray:
    """``n`` samples of random voltage levels, kV: each uniform in ``[lo_kv, hi_kv]``, held for a random
    number of samples in ``[hold_samples[0], hold_samples[1])``."""
    u = np.empty(n)
    i = 0
    while i < n:
        k = int(rng.integers(*hold_samples))
        u[i:i + k] = rng.uniform(lo_kv, hi_kv)
        i += k
    return u


def multisine_through(plant, seed: int, rate_hz: float = 500.0, delay_s: float = 0.0, noise_mm: float = 0.004,
                      dur_s: float = 16.0) -> tuple[np.ndarray, np.ndarray, np.ndarray, dict]:
    """A multisine (0.3-40 Hz, 12 tones of random phase, about 4 kV) through ``plant`` (``(num, den)``, kV -> mm,
    scipy's zero-order hold at ``rate_hz``) after a pure delay of ``delay_s`` (whole samples), white noise of
    ``noise_mm`` and a 12-bit laser's quantisation. Returns ``t_s, u_kv, y_mm`` and P(s) as the nominal model."""
    rng = np.random.default_rng(seed)
    t = np.arange(int(dur_s * rate_hz)) / rate_hz
    freqs = np.geomspace(0.3, 40.0, 12)
    u = 4.0 + sum(0.5 * np.sin(2 * np.pi * fk * t + rng.uniform(0, 2 * np.pi)) for fk in freqs) / np.sqrt(3.0)
    k = int(round(delay_s * rate_hz))
    x = np.concatenate([np.full(k, u[0]), u[: u.size - k]]) if k else u
    b, a, _ = signal.cont2discrete(plant, 1.0 / rate_hz, method="zoh")
    b = np.ravel(b)
    y = signal.lfilter(b, a, x, zi=signal.lfilter_zi(b, a) * x[0])[0]
    lsb = 10.0 * 3.0 / 4096
    y = np.round((y + noise_mm * rng.standard_normal(u.size)) / lsb) * lsb
    num, den = paper.plant_tf()
    return t, u, y, {"num": num.tolist(), "den": den.tolist()}


def chunked_gap(make_stage, u: np.ndarray, cut: int) -> float:
    """Largest difference between one stage run on ``u`` whole and a second run in two chunks split at ``cut``
    (both built by ``make_stage()``, reset at ``u[0]``): zero when the stage carries its state between chunks."""
    a, b = make_stage(), make_stage()
    a.reset(u[0])
    b.reset(u[0])
    return float(np.max(np.abs(a.run(u) - np.concatenate([b.run(u[:cut]), b.run(u[cut:])]))))


def swing_over_nominal(model, f_hz: float, rate_hz: float = 10_000.0) -> float:
    """Peak-to-peak stroke (mm over mm) of the simulator's actuator built from the plant model ``model``
    (:class:`hasel.plantfile.PlantModel`) over that of P(s)'s, both driven by ``4 + 0.3 sin(2 pi f_hz t)`` kV for 4 s at
    ``rate_hz`` (the amplifier's filter included), the last two seconds (settled)."""
    from hasel.plantchain import build_actuator
    from hasel.plantfile import PlantModel

    tt = np.arange(int(4.0 * rate_hz)) / rate_hz
    cmd = 4.0 + 0.3 * np.sin(2.0 * np.pi * f_hz * tt)

    def swing(m) -> float:
        act = build_actuator(m)
        act.reset(4.0)
        return float(np.ptp(act.run(cmd).stroke_mm[int(2.0 * rate_hz):]))

    num, den = paper.plant_tf()
    return swing(model) / swing(PlantModel(tuple(num), tuple(den)))


def cosine_chirp(rate_hz: float = 500.0, dur_s: float = 20.0) -> np.ndarray:
    """Raised-cosine log chirp 0.2-20 Hz between 0 and 7 kV (kV), ``dur_s`` at ``rate_hz`` (a HASEL driven from
    0 kV, as the static-map form tests use)."""
    t = np.arange(int(dur_s * rate_hz)) / rate_hz
    f0, f1 = 0.2, 20.0
    ph = 2 * np.pi * f0 * dur_s / np.log(f1 / f0) * (np.exp(t / dur_s * np.log(f1 / f0)) - 1.0)
    return 3.5 * (1.0 - np.cos(ph))


def zoh_stroke(v: np.ndarray, rate_hz: float = 500.0) -> np.ndarray:
    """``v`` (kV) through P(s), zero-order hold at ``rate_hz``, from rest at ``v[0]`` (mm): :func:`_simulate`."""
    return _simulate(np.asarray(v, float), rate_hz)


def diagnose_noisy(u: np.ndarray, z: np.ndarray, seed: int, rate_hz: float = 500.0, noise_mm: float = 0.005):
    """``hasel.diagnose`` of input ``u`` (kV) against the stroke ``z`` (mm) plus white noise of ``noise_mm`` drawn
    from ``seed``, sampled at ``rate_hz``, with the exact P(s) as the nominal model."""
    from hasel.diagnose import diagnose

    y = z + noise_mm * np.random.default_rng(seed).standard_normal(u.size)
    num, den = paper.plant_tf()
    return diagnose(np.arange(u.size) / rate_hz, u, y, model={"num": num.tolist(), "den": den.tolist()},
                    units=("kV", "mm"))


def _chirp_per_offset(kind: str, rate_hz: float, rng: np.random.Generator,
                      hold_s: tuple[float, float] = (0.05, 1.0)) -> np.ndarray:
    if kind in ("paper_chirp", "paper_chirp3"):
        t = np.arange(int(round(20.0 * rate_hz))) / rate_hz
        one = np.sin(2 * np.pi * (20.0 / 20.0) * t * t)
        return np.tile(one, 3 if kind == "paper_chirp3" else 1)
    if kind == "linear_chirp":
        t = np.arange(int(round(30.0 * rate_hz))) / rate_hz
        return signal.chirp(t, 0.05, 30.0, min(20.0, 0.4 * rate_hz), method="linear", phi=-90)
    if kind == "log_chirp":
        t = np.arange(int(round(30.0 * rate_hz))) / rate_hz
        return np.tile(signal.chirp(t, 0.05, 30.0, min(20.0, 0.4 * rate_hz), method="logarithmic", phi=-90), 2)
    if kind == "multisine":
        n = int(round(10.0 * rate_hz))
        k = np.arange(1, int(min(20.0, 0.4 * rate_hz) * 10.0) + 1, 2)
        spec = np.zeros(n // 2 + 1, complex)
        spec[k] = np.exp(2j * np.pi * rng.random(k.size))
        x = np.fft.irfft(spec, n)
        return np.tile(0.9 * x / np.max(np.abs(x)), 3)
    if kind == "prbs":
        n = int(round(20.0 * rate_hz))
        clock = max(1, int(round(0.02 * rate_hz)))
        bits = rng.integers(0, 2, n // clock + 1) * 2 - 1
        return 0.7 * np.repeat(bits, clock)[:n].astype(float)
    if kind == "random_steps":
        n = int(round(20.0 * rate_hz))
        out = np.empty(n)
        i = 0
        while i < n:
            hold = int(rng.uniform(hold_s[0], hold_s[1]) * rate_hz) + 1
            out[i:i + hold] = rng.uniform(-1.0, 1.0)
            i += hold
        return out
    raise ValueError(kind)


def _fine(u: np.ndarray, rate_hz: float, convention: str, offset_samples: float, m: int = 8) -> np.ndarray:
    """Stroke of P(s) for ``u`` under a sampling ``convention`` and timing offset (simulated at ``m x rate_hz``)."""
    m = max(2, min(m, int(40000.0 // rate_hz)))
    fine = np.repeat(u, m) if convention in ("zoh", "centred") else np.interp(np.arange(u.size * m) / m,
                                                                                np.arange(u.size), u)
    # hasel.lti's exact ZOH sections (the state-space path of scipy loses digits on the double pole pair)
    from hasel.lti import zoh_sos

    num, den = paper.plant_tf()
    sos = zoh_sos(num, den, 1.0 / (rate_hz * m), output="start")
    yf, _ = signal.sosfilt(sos, fine, zi=signal.sosfilt_zi(sos) * fine[0])
    shift = (m // 2 if convention == "centred" else 0) - int(round(offset_samples * m))
    return yf[np.clip(np.arange(u.size) * m + shift, 0, yf.size - 1)]


def _noise(rng: np.random.Generator, n: int, rate_hz: float, sd: float, kind: str, fc_hz: float) -> np.ndarray:
    """Measurement noise of rms ``sd`` (mm) of ``kind`` (see the module)."""
    w = rng.standard_normal(n)
    if kind == "white":
        return sd * w
    if kind == "coloured":
        a = np.exp(-2 * np.pi * fc_hz / rate_hz)
        x = signal.lfilter([1.0 - a], [1.0, -a], w)
        return sd * x / x.std()
    if kind == "wander":
        a = np.exp(-1.0 / (10.0 * rate_hz))
        d = signal.detrend(signal.lfilter([1.0], [1.0, -a], rng.standard_normal(n)), type="constant")
        return sd * w + 4.0 * sd * d / max(float(np.abs(d).max()), 1e-12)
    raise ValueError(kind)


def make_log(design: str, rate_hz: float = 1000.0, *, seed: int = 0, precondition: bool = False,
             settle_s: float = 0.5, noise_mm: float = 0.01, offsets_kv=OFFSETS_KV, convention: str = "zoh",
             offset_samples: float = 0.0, noise_kind: str = "white", noise_fc_hz: float = 5.0,
             lsb_mm: float = 0.0, amplitude: float = 1.0, hold_s: tuple[float, float] = (0.05, 1.0),
             loop_gain: float = 1.0) -> Log:
    """One effect-free log of ``design`` (see the module) at ``rate_hz``, noise ``noise_mm`` (mm RMS).

    The measurement knobs (``convention`` ... ``amplitude``) are described in the module;
    ``hold_s`` bounds the hold times of ``random_steps`` (s), ``loop_gain`` scales the
    PID gains of ``closed_loop``.
    """
    rng = np.random.default_rng(seed)
    if design == "closed_loop":
        return _closed_loop(rate_hz, rng, noise_mm, loop_gain)
    parts: list[np.ndarray] = [np.zeros(int(round(0.5 * rate_hz)))]
    marks = []
    if design == "voltage_steps":
        levels = [0.0, 2.0, 4.0, 6.0, 4.0, 2.0, 0.0, 3.0, 5.0, 7.0, 5.0, 3.0, 0.0]
        for v in levels:
            parts.append(np.full(int(round(1.5 * rate_hz)), v))
    else:
        for off in offsets_kv:
            if precondition:
                parts.append(np.full(int(round(1.0 * rate_hz)), -1.0))
                parts.append(np.zeros(int(round(0.2 * rate_hz))))
            parts.append(np.full(int(round(settle_s * rate_hz)), off))
            n0 = sum(p.size for p in parts)
            x = off + amplitude * _chirp_per_offset(design, rate_hz, rng, hold_s)
            parts.append(x)
            marks.append((n0 / rate_hz, (n0 + x.size) / rate_hz, off))
        parts.append(np.zeros(int(round(0.5 * rate_hz))))
    u = np.concatenate(parts)
    plain = convention == "zoh" and offset_samples == 0.0 and noise_kind == "white" and lsb_mm == 0.0
    if plain:   # the original generator, draw for draw
        y = _simulate(u, rate_hz) + noise_mm * rng.standard_normal(u.size)
    else:
        y = _fine(u, rate_hz, convention, offset_samples) + _noise(rng, u.size, rate_hz, noise_mm, noise_kind,
                                                                   noise_fc_hz)
        if lsb_mm > 0:
            y = np.round(y / lsb_mm) * lsb_mm
    t = np.arange(u.size) / rate_hz
    return Log(t, u, y, design, rate_hz, {"excitation_segments": marks, "precondition": precondition,
                                          "settle_s": settle_s, "noise_mm": noise_mm, "seed": seed,
                                          "convention": convention, "offset_samples": offset_samples,
                                          "noise_kind": noise_kind, "lsb_mm": lsb_mm, "amplitude": amplitude})


def _closed_loop(rate_hz: float, rng: np.random.Generator, noise_mm: float, loop_gain: float = 1.0) -> Log:
    """The dual-mode PID at 200 Hz (its own implementation, gains times ``loop_gain``) around P(s) at ``rate_hz``."""
    Ad, Bd, Cd, Dd = plant_discrete(rate_hz)
    dt_c = paper.LOOP_PERIOD_S
    every = max(1, int(round(dt_c * rate_hz)))
    dt_c = every / rate_hz
    refs = [0.0] + list(paper.STEP_SEQUENCE_MM) * 3 + [0.0]
    hold = int(round(2.0 * rate_hz))
    r = np.repeat(np.array(refs, float), hold)
    r[:hold] = 0.0
    n = r.size
    x = np.zeros(Ad.shape[0])
    u = np.zeros(n)
    y = np.zeros(n)
    integ, e_prev, v = 0.0, 0.0, 0.0
    for i in range(n):
        y_true = float(Cd[0] @ x + Dd[0, 0] * v)
        y[i] = y_true + noise_mm * rng.standard_normal()
        if i % every == 0 and i >= hold:
            e = r[i] - y[i]
            kp, ki, kd = (loop_gain * g for g in (paper.C_PLUS if e >= 0 else paper.C_MINUS))
            integ_new = integ + 0.5 * (e + e_prev) * dt_c
            out = kp * e + ki * integ_new + kd * (e - e_prev) / dt_c
            if 0.0 <= out <= paper.V_MAX_KV:
                integ = integ_new
            v = float(np.clip(out, 0.0, paper.V_MAX_KV))
            e_prev = e
        u[i] = v
        x = Ad @ x + Bd[:, 0] * v
    # the stroke sample i is taken before the voltage of sample i acts (as a sampled loop does)
    t = np.arange(n) / rate_hz
    return Log(t, u, y, "closed_loop", rate_hz, {"noise_mm": noise_mm, "reference_mm": refs, "loop_gain": loop_gain})
