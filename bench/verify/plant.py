"""An independent simulator of the HASEL paper's actuator for the verification corpus.

Written from the paper's P(s) (17) alone, without reading the project's simulator or
analysis code. Units: voltage in kV, stroke in mm, time in s.

The plant is a chain of stages. Each stage keeps its own state between calls, so the
same objects run a whole open-loop log in one call or a closed loop one controller
period at a time:

    input-side stages (sample rate)  ->  hold onto a fine grid  ->  linear dynamics
    (+ transport delay, fine grid)   ->  sampling (with a timing offset)  ->
    output-side stages (sample rate)  ->  noise (added by the caller)
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Callable

import numpy as np
from scipy import signal

# The paper's identified model (17), kV -> mm.
P_K = 10.836
P_W = 122.2  # rad/s, anti-resonance and double-pole frequency


def paper_tf(pole_scale: float = 1.0) -> tuple[np.ndarray, np.ndarray]:
    """The paper's P(s) as (num, den), descending powers of s, kV -> mm.

    `pole_scale` < 1 lowers the double-pole pair's frequency (same damping ratio) as an
    extra mass on the spring would, and rescales the gain so that G(0) is unchanged.
    """
    wp = P_W * pole_scale
    num = P_K * np.polymul(np.polymul(np.polymul([1, 50.27], [1, 62.83]), [1, 628.3]), [1, 0, P_W**2])
    quad = [1, 230.0 * pole_scale, wp**2]
    den = np.polymul(np.polymul([1, 18.85], [1, 56.55]), np.polymul(quad, quad))
    num = num * (pole_scale**4)  # keeps num(0)/den(0) since den(0) scales by pole_scale^4
    return np.asarray(num, float), np.asarray(den, float)


def dc_gain(num: np.ndarray, den: np.ndarray) -> float:
    """Static gain num(0)/den(0) of a transfer function (mm/kV)."""
    return float(num[-1] / den[-1])


def freq_response(num, den, f_hz: np.ndarray, delay_s: float = 0.0) -> np.ndarray:
    """Complex frequency response at f_hz (Hz), with an optional dead time (s)."""
    s = 2j * np.pi * np.asarray(f_hz, float)
    return np.polyval(num, s) / np.polyval(den, s) * np.exp(-s * delay_s)


class Stage:
    """One stateful block of the chain: `run(x) -> y` on consecutive chunks."""

    def run(self, x: np.ndarray) -> np.ndarray:  # pragma: no cover - interface
        raise NotImplementedError


class Linear(Stage):
    """A continuous transfer function integrated exactly for piecewise-constant input
    on a grid of step `dt` s (zero-order-hold discretisation).

    mode 'fir' (open loop, any dt): the discrete impulse response (Markov parameters
    C A^(k-1) B, over `memory_s` seconds) convolved with the whole input history;
    exact for any grid. mode 'sos' (closed loop, chunks of a few samples): second-order
    sections with carried state; accurate only for dt >= 0.5 ms (the sections lose
    precision when the poles crowd near z = 1), so it refuses finer grids.
    """

    def __init__(self, num, den, dt: float, mode: str = "fir", memory_s: float = 2.5):
        A, B, C, D = signal.tf2ss(num, den)
        Ad, Bd, Cd, Dd, _ = signal.cont2discrete((A, B, C, D), dt, method="zoh")
        self.mode = mode
        if mode == "fir":
            n = int(np.ceil(memory_s / dt))
            h = np.zeros(n)
            x = Bd[:, 0].copy()
            c = Cd[0]
            for k in range(1, n):
                h[k] = c @ x
                x = Ad @ x
            self.h = h
            self.hist = np.zeros(0)
            return
        if dt < 5e-4:
            raise ValueError("sos mode is inaccurate below 0.5 ms steps; use mode='fir'")
        z, p, k = signal.ss2zpk(Ad, Bd, Cd, Dd)
        z = z[np.isfinite(z)]
        self.sos = signal.zpk2sos(z, p, k)
        self.zi = np.zeros((self.sos.shape[0], 2))
        # zpk2sos pads missing zeros at z = 0, which advances the output by one grid
        # step per padded zero; a delay line puts the relative degree back.
        self.lag = Delay(len(p) - len(z))

    def run(self, x):
        x = np.asarray(x, float)
        if self.mode == "fir":
            self.hist = np.concatenate([self.hist, x])
            y = signal.fftconvolve(self.hist, self.h)[: self.hist.size]
            return y[self.hist.size - x.size:]
        y, self.zi = signal.sosfilt(self.sos, x, zi=self.zi)
        return self.lag.run(y)


class Delay(Stage):
    """Pure transport delay of n grid samples."""

    def __init__(self, n: int, init: float = 0.0):
        self.buf = np.full(int(n), float(init))

    def run(self, x):
        if self.buf.size == 0:
            return np.asarray(x, float)
        z = np.concatenate([self.buf, x])
        self.buf = z[len(x):]
        return z[: len(x)]


class Map(Stage):
    """A memoryless curve y = f(x)."""

    def __init__(self, f: Callable[[np.ndarray], np.ndarray]):
        self.f = f

    def run(self, x):
        return self.f(np.asarray(x, float))


class Play(Stage):
    """Prandtl-Ishlinskii hysteresis: a weighted sum of play (backlash) operators.

    Each operator of half-width r_i follows its input only when it is more than r_i
    away; `up_scale` != 1 widens the operators on rising input only (asymmetric loop).
    The output is normalised so that a large excursion has unit slope.
    """

    def __init__(self, radii, weights, init: float, up_scale: float = 1.0):
        self.r = np.asarray(radii, float)
        self.w = np.asarray(weights, float) / np.sum(weights)
        self.up = float(up_scale)
        self.state = np.full(self.r.size, float(init))

    def run(self, x):
        out = np.empty(len(x))
        st, r, w, up = self.state, self.r, self.w, self.up
        for i, v in enumerate(x):
            st = np.minimum(np.maximum(st, v - r * up), v + r)
            out[i] = w @ st
        self.state = st
        return out


class Duhem(Stage):
    """A Duhem-type rate-independent hysteresis on the input: v_eff = v - alpha h,
    where h (kV) relaxes towards +scale while v rises and towards -scale while it
    falls, exponentially in the input change (dh/dv = 1 -+ h/scale): loop width
    2 alpha scale."""

    def __init__(self, alpha: float, scale_kv: float, init: float):
        self.alpha, self.sc = float(alpha), float(scale_kv)
        self.h, self.prev = 0.0, float(init)

    def run(self, x):
        out = np.empty(len(x))
        h, prev, a, sc = self.h, self.prev, self.alpha, self.sc
        for i, v in enumerate(x):
            dv = v - prev
            if dv > 0:
                h = sc - (sc - h) * np.exp(-dv / sc)
            elif dv < 0:
                h = -sc + (h + sc) * np.exp(dv / sc)
            prev = v
            out[i] = v - a * h
        self.h, self.prev = h, prev
        return out


class DirLag(Stage):
    """First-order lag whose time constant depends on direction: tau_up while its
    output rises, tau_down while it falls (s), at sample period dt."""

    def __init__(self, tau_up: float, tau_down: float, dt: float, init: float):
        self.a_up = 1.0 - np.exp(-dt / tau_up)
        self.a_dn = 1.0 - np.exp(-dt / tau_down)
        self.y = float(init)

    def run(self, x):
        out = np.empty(len(x))
        y, au, ad = self.y, self.a_up, self.a_dn
        for i, v in enumerate(x):
            y += (au if v > y else ad) * (v - y)
            out[i] = y
        self.y = y
        return out


class Slew(Stage):
    """Rate limit: at most `up` units/s rising and `down` units/s falling (dt s steps)."""

    def __init__(self, up: float, down: float, dt: float, init: float):
        self.du, self.dd, self.y = up * dt, down * dt, float(init)

    def run(self, x):
        out = np.empty(len(x))
        y, du, dd = self.y, self.du, self.dd
        for i, v in enumerate(x):
            y += min(du, max(-dd, v - y))
            out[i] = y
        self.y = y
        return out


class Creep(Stage):
    """Charge creep: adds c * q to a signal, where q (kV s) is the leaky integral
    (time constant tau s) of the applied voltage accumulated before each sample.
    The voltage is given by `feed` before `run`."""

    def __init__(self, c: float, tau: float, dt: float):
        self.c, self.dt = float(c), float(dt)
        self.a = np.exp(-dt / tau)
        self.q = 0.0
        self.v = np.zeros(0)

    def feed(self, v: np.ndarray) -> None:
        """Set the applied voltage samples (kV) of the next chunk."""
        self.v = np.asarray(v, float)

    def run(self, x):
        if len(x) == 0:
            return np.asarray(x, float)
        q, _ = signal.lfilter([self.dt], [1.0, -self.a], self.v, zi=[self.a * self.q])
        before = np.concatenate([[self.q], q[:-1]])
        self.q = q[-1]
        return np.asarray(x, float) + self.c * before


class ChargeGain(Stage):
    """Charge build-up that scales the effective voltage: v_eff = v (1 + c q / v_ref),
    with q a first-order (time constant tau s) follower of |v|."""

    def __init__(self, c: float, tau: float, dt: float, v_ref: float = 5.0):
        self.c, self.vr = float(c), float(v_ref)
        self.a = np.exp(-dt / tau)
        self.q = 0.0

    def run(self, x):
        x = np.asarray(x, float)
        q, zf = signal.lfilter([1 - self.a], [1.0, -self.a], np.abs(x), zi=[self.a * self.q])
        self.q = q[-1] if len(q) else self.q
        return x * (1.0 + self.c * q / self.vr)


@dataclass
class Chain:
    """The whole plant: input stages, hold, dynamics, sampling, output stages.

    m: fine-grid steps per sample; convention: 'zoh', 'foh' or 'centred' (how the
    logged input samples map onto the continuous input); offset_fine: the output is
    sampled offset_fine fine steps after the input sample instant.
    """

    fs: float
    m: int
    lin: Linear
    delay: Delay
    pre: list = field(default_factory=list)
    post: list = field(default_factory=list)
    convention: str = "zoh"
    offset_fine: int = 0

    def hold(self, u: np.ndarray) -> np.ndarray:
        """Map sample-rate input onto the fine grid after its hold convention."""
        m = self.m
        if m == 1 or self.convention == "zoh":
            return np.repeat(u, m)
        if self.convention == "foh":
            nxt = np.concatenate([u[1:], u[-1:]])
            frac = np.arange(m) / m
            return (u[:, None] * (1 - frac) + nxt[:, None] * frac).ravel()
        if self.convention == "centred":
            # sample k holds over [t_k - T/2, t_k + T/2)
            h = m // 2
            uf = np.repeat(u, m)
            return np.concatenate([uf[h:], np.repeat(u[-1:], h)])
        raise ValueError(self.convention)

    def run(self, u: np.ndarray) -> np.ndarray:
        """Noise-free output samples (mm) for input samples u (kV), continuing state."""
        v = np.asarray(u, float)
        for st in self.pre:
            if isinstance(st, Creep):
                st.feed(u)
            v = st.run(v)
        vf = self.hold(v)
        yf = self.lin.run(self.delay.run(vf))
        # Output sample k is the grid value at t_k + offset. An offset needs the grid
        # beyond the last sample, so it is only for one-call (open-loop) runs.
        if self.offset_fine:
            tail = self.lin.run(self.delay.run(np.repeat(vf[-1:], self.m)))
            yf = np.concatenate([yf, tail])
        y = yf[self.offset_fine:: self.m][: len(u)]
        for st in self.post:
            if isinstance(st, Creep):
                st.feed(u)
            y = st.run(y)
        return y
