"""Independent simulator of the HASEL paper's plant P(s) with unmodelled effects.

Written for the third blind verification corpus (bench/verify3) without reading
the project's analysis code.  Units: voltage in kV, stroke in mm, time in s.

The chain simulated per sample is

    v (logged) -> input-side blocks -> [delay + linear dynamics P(s), possibly
    load-modified] -> + charge drift -> output-side blocks -> noise -> logged y

Every block has ``step(u) -> y`` (one sample, state carried) and ``reset()``.
The linear block discretises P(s) itself with one of the sample-time
conventions: ``zoh`` (input held until the next sample), ``foh`` (input
interpolated linearly between samples, triangle hold), ``centred`` (input held
over the half-sample either side of its stamp == zoh with the output read half a
sample later), plus an arbitrary real input/output skew in samples.
"""
from __future__ import annotations

import math

import numpy as np
from scipy import linalg, signal

# ---------------------------------------------------------------- the paper's P(s)
K_PAPER = 10.836
W_NOTCH = 122.2  # rad/s


def paper_tf():
    """Return (num, den) of the paper's identified P(s), eq. (17), kV -> mm.

    Coefficients are in descending powers of s; the static gain is about
    1.351 mm/kV."""
    w2 = W_NOTCH ** 2
    num = K_PAPER * np.polymul(np.polymul(np.polymul([1, 50.27], [1, 62.83]), [1, 628.3]),
                               [1, 0, w2])
    den = np.polymul(np.polymul([1, 18.85], [1, 56.55]),
                     np.polymul([1, 230.0, w2], [1, 230.0, w2]))
    return np.asarray(num, float), np.asarray(den, float)


def dc_gain(num, den):
    """Static gain of a continuous transfer function (mm/kV)."""
    return float(np.polyval(num, 0.0) / np.polyval(den, 0.0))


def freq_resp(num, den, f_hz):
    """Complex frequency response of num/den at frequencies f_hz (Hz)."""
    s = 2j * np.pi * np.asarray(f_hz, float)
    return np.polyval(num, s) / np.polyval(den, s)


def loaded_tf(mu=0.647, pairs=2):
    """P(s) with an added moving mass: the resonant pole pair(s) s^2+230s+w^2
    become s^2 + 230/(1+mu) s + w^2/(1+mu) (mass (1+mu) m, same damper and
    spring), ``pairs`` = 1 or 2 of them; the numerator is rescaled so the static
    gain is unchanged (mm/kV)."""
    num, den0 = paper_tf()
    w2 = W_NOTCH ** 2
    loaded = [1, 230.0 / (1 + mu), w2 / (1 + mu)]
    plain = [1, 230.0, w2]
    pp = np.polymul(loaded, loaded) if pairs == 2 else np.polymul(loaded, plain)
    den = np.polymul(np.polymul([1, 18.85], [1, 56.55]), pp)
    num = num * dc_gain(num, den0) / dc_gain(num, den)
    return num, np.asarray(den, float)


def third_pair_tf(f_hz=31.0, zeta=0.22):
    """P(s) times a unit-gain pole pair wn^2/(s^2+2 zeta wn s+wn^2): a load on a
    compliant link (f_hz in Hz)."""
    num, den = paper_tf()
    wn = 2 * np.pi * f_hz
    return num * wn ** 2, np.polymul(den, [1, 2 * zeta * wn, wn ** 2])


def lagged_tf(tau_s):
    """P(s) times a first-order lag 1/(tau s + 1), tau in s."""
    num, den = paper_tf()
    return num, np.polymul(den, [tau_s, 1.0])


# ---------------------------------------------------------------- linear block
class Linear:
    """Discrete simulation of a continuous num/den (kV -> mm) at period ts (s).

    convention: 'zoh', 'foh' or 'centred'.  skew: extra output lead in samples
    (real; negative = the output lags = pure input delay).  The total lead is
    split into an integer input delay line and a fractional read-out inside the
    held interval, which is exact for a zero-order-held input."""

    def __init__(self, num, den, ts, convention="zoh", skew=0.0):
        self.ts = float(ts)
        a, b, c, d = signal.tf2ss(num, den)
        self.convention = convention
        s = float(skew) + (0.5 if convention == "centred" else 0.0)
        if convention == "foh":
            ad, bd, cd, dd, _ = signal.cont2discrete((a, b, c, d), ts, method="foh")
            if abs(s - round(s)) > 1e-12:
                raise ValueError("foh supports integer skews only")
            self.frac = 0.0
            k = int(round(s))
            self.cphi, self.cgam = cd, dd
        else:
            k = math.floor(s + 1e-12)
            f = s - k
            n = a.shape[0]
            m = np.zeros((n + 1, n + 1))
            m[:n, :n] = a * ts
            m[:n, n:] = b * ts
            e = linalg.expm(m)
            ad, bd = e[:n, :n], e[:n, n:]
            mf = linalg.expm(m * f)
            self.cphi = c @ mf[:n, :n]
            self.cgam = c @ mf[:n, n:] + d
            self.frac = f
        if k > 0:
            raise ValueError("an output lead of one sample or more is not causal")
        self.ndelay = -k
        self.ad, self.bd = np.asarray(ad), np.asarray(bd).ravel()
        self.cphi = np.asarray(self.cphi).ravel()
        self.cgam = float(np.asarray(self.cgam).ravel()[0])
        self.reset()

    def reset(self, u0=0.0):
        """Start at the steady state for a constant input u0 (kV)."""
        n = self.ad.shape[0]
        self.x = np.linalg.solve(np.eye(n) - self.ad, self.bd * u0)
        self.line = [float(u0)] * self.ndelay

    def step(self, u):
        """One sample: input u (kV) -> output (mm)."""
        if self.ndelay:
            self.line.append(float(u))
            u = self.line.pop(0)
        y = float(self.cphi @ self.x) + self.cgam * u
        self.x = self.ad @ self.x + self.bd * u
        return y

    def run(self, u):
        """Simulate a whole input array u (kV) from the steady state of u[0]."""
        u = np.asarray(u, float)
        self.reset(u[0])
        ad, bd, cphi, cg = self.ad, self.bd, self.cphi, self.cgam
        if self.ndelay:
            u = np.concatenate([np.full(self.ndelay, u[0]), u[:len(u) - self.ndelay]])
        x = self.x
        y = np.empty(len(u))
        for i, ui in enumerate(u):
            y[i] = cphi @ x + cg * ui
            x = ad @ x + bd * ui
        self.x = x
        return y


# ---------------------------------------------------------------- effect blocks
class Block:
    """A memory or static element of the chain; ``step`` maps one sample."""

    side = "in"  # 'in' (voltage, kV) or 'out' (stroke, mm)

    def reset(self, u0=0.0):
        """Reset the state to rest at input u0."""

    def step(self, u):  # pragma: no cover - overridden
        """One sample."""
        raise NotImplementedError


class TwoSlopeMap(Block):
    """Input-side static map: gain g_lo below the corner v_c (kV), g_hi above,
    blended smoothly over width s (kV) with a softplus; continuous, no memory."""

    def __init__(self, v_c=4.5, g_lo=0.75, g_hi=1.3, s=0.35):
        self.v_c, self.g_lo, self.g_hi, self.s = v_c, g_lo, g_hi, s

    def step(self, u):
        x = (u - self.v_c) / self.s
        sp = self.s * (x + math.log1p(math.exp(-x)) if x > 0 else math.log1p(math.exp(x)))
        return self.v_c + self.g_lo * (u - self.v_c) + (self.g_hi - self.g_lo) * sp


class ThresholdMap(Block):
    """Input-side dead zone: v_eff = sign(v) max(|v| - v0, 0) smoothed by a
    quadratic blend of half-width b (kV): the actuator does nothing below v0."""

    def __init__(self, v0=0.9, b=0.4):
        self.v0, self.b = v0, b

    def step(self, u):
        a = abs(u)
        lo, hi = self.v0 - self.b, self.v0 + self.b
        if a <= lo:
            r = 0.0
        elif a >= hi:
            r = a - self.v0
        else:
            r = (a - lo) ** 2 / (4 * self.b)
        return math.copysign(r, u)


class RippleMap(Block):
    """Input-side map with a periodic ripple: v + a sin(2 pi v / p) (kV)."""

    def __init__(self, a=0.22, p=2.6):
        self.a, self.p = a, p

    def step(self, u):
        return u + self.a * math.sin(2 * math.pi * u / self.p)


class BoucWen(Block):
    """Input-side Bouc-Wen hysteresis (n = 1), integrated on input increments:
    dh = A dv - beta |dv| h - gamma dv |h|;  v_eff = v - h.  |h| is bounded by
    A / (beta + gamma) kV."""

    def __init__(self, A=0.6, beta=1.5, gamma=0.4):
        self.A, self.beta, self.gamma = A, beta, gamma
        self.reset()

    def reset(self, u0=0.0):
        self.h, self.prev = 0.0, u0

    def step(self, u):
        dv = u - self.prev
        self.prev = u
        nsub = max(1, int(abs(dv) / 0.02) + 1)
        d = dv / nsub
        for _ in range(nsub):
            self.h += self.A * d - self.beta * abs(d) * self.h - self.gamma * d * abs(self.h)
        return u - self.h


class AsymPI(Block):
    """Input-side asymmetric Prandtl-Ishlinskii: a weighted sum of play operators
    whose band is r_up above and r_dn below the operator's output (kV);
    weights sum to 1 with the linear weight w0, so the slope is kept."""

    def __init__(self, r_up=(0.15, 0.4, 0.8), r_dn=(0.05, 0.2, 0.5), w=(0.25, 0.2, 0.15)):
        self.r_up, self.r_dn, self.w = list(r_up), list(r_dn), list(w)
        self.w0 = 1.0 - sum(w)
        self.reset()

    def reset(self, u0=0.0):
        self.p = [u0] * len(self.w)

    def step(self, u):
        out = self.w0 * u
        for i, (ru, rd, w) in enumerate(zip(self.r_up, self.r_dn, self.w)):
            self.p[i] = min(u + rd, max(u - ru, self.p[i]))
            out += w * self.p[i]
        return out


class OutputPlay(Block):
    """Output-side backlash (dead band with memory) between actuator and sensor:
    the measured stroke follows only when the actuator moves more than r (mm)
    against it."""

    side = "out"

    def __init__(self, r=0.12):
        self.r = r
        self.reset()

    def reset(self, u0=0.0):
        self.p = u0

    def step(self, u):
        self.p = min(u + self.r, max(u - self.r, self.p))
        return self.p


class AmpClip(Block):
    """Input-side amplifier clip: the applied voltage never exceeds v_max (kV)."""

    def __init__(self, v_max=6.9, v_min=-1e9):
        self.v_max, self.v_min = v_max, v_min

    def step(self, u):
        return min(self.v_max, max(self.v_min, u))


class TanhEndStop(Block):
    """Output-side one-sided end stop: identity below z0 (mm), above it the
    stroke approaches z0 + w along w tanh((z - z0)/w)."""

    side = "out"

    def __init__(self, z0=7.6, w=0.7):
        self.z0, self.w = z0, w

    def step(self, u):
        if u <= self.z0:
            return u
        return self.z0 + self.w * math.tanh((u - self.z0) / self.w)


class HardStop(Block):
    """Output-side hard clip of the stroke at z_max (mm) (mechanical stop)."""

    side = "out"

    def __init__(self, z_max=8.2, z_min=-1e9):
        self.z_max, self.z_min = z_max, z_min

    def step(self, u):
        return min(self.z_max, max(self.z_min, u))


class QuadSensor(Block):
    """Output-side sensor curve: y = z + b z^2 / 10 (mm): a bow over the range."""

    side = "out"

    def __init__(self, b=0.07):
        self.b = b

    def step(self, u):
        return u + self.b * u * u / 10.0


class SqrtSensor(Block):
    """Output-side compressive sensor curve: y = s (sqrt(1 + 2 z / s) - 1) (mm),
    slope 1 at z = 0, bending over the whole range."""

    side = "out"

    def __init__(self, s=28.0):
        self.s = s

    def step(self, u):
        return self.s * (math.sqrt(max(1.0 + 2.0 * u / self.s, 0.0)) - 1.0)


class AsymChargeLag(Block):
    """Input-side asymmetric charge lag: v_eff follows v with time constant
    tau_up (s) while charging (v > v_eff) and tau_dn while discharging."""

    def __init__(self, ts, tau_up=0.002, tau_dn=0.030):
        self.a_up = math.exp(-ts / tau_up)
        self.a_dn = math.exp(-ts / tau_dn)
        self.reset()

    def reset(self, u0=0.0):
        self.v = u0

    def step(self, u):
        a = self.a_up if u > self.v else self.a_dn
        self.v = a * self.v + (1 - a) * u
        return self.v


class AsymRelax(Block):
    """Output-side one-sided relaxation: the stroke follows the actuator at once
    when rising and with time constant tau (s) when falling (the restoring
    wrap is slower than the electrostatic zipping)."""

    side = "out"

    def __init__(self, ts, tau=0.045):
        self.a = math.exp(-ts / tau)
        self.reset()

    def reset(self, u0=0.0):
        self.z = u0

    def step(self, u):
        if u >= self.z:
            self.z = u
        else:
            self.z = self.a * self.z + (1 - self.a) * u
        return self.z


class AsymSlew(Block):
    """Input-side asymmetric slew limit: the applied voltage rises at most
    up kV/s and falls at most dn kV/s (amplifier sources more than it sinks)."""

    def __init__(self, ts, up=70.0, dn=22.0):
        self.du, self.dd = up * ts, dn * ts
        self.reset()

    def reset(self, u0=0.0):
        self.v = u0

    def step(self, u):
        self.v += min(self.du, max(-self.dd, u - self.v))
        return self.v


class Drift:
    """Charge drift added to the stroke (mm), driven by the logged voltage.

    form 'leaky': dq/dt = a v^2 - q (b0 + b1 |v|)  (a leaky integrator whose leak
    rate grows with voltage); stroke += g q.
    form 'trap': dq/dt = k max(v - v_th, 0) - q / tau - c max(-v, 0) q  (charge
    trapped above a threshold, bled slowly, removed fast by reversed voltage)."""

    def __init__(self, ts, form="leaky", **p):
        self.ts, self.form = ts, form
        d = dict(a=0.004, b0=0.02, b1=0.004, g=1.0, k=0.02, v_th=2.5, tau=60.0, c=1.5)
        d.update(p)
        self.p = d
        self.reset()

    def reset(self, u0=0.0):
        self.q = 0.0

    def step(self, v):
        p, q = self.p, self.q
        if self.form == "leaky":
            dq = p["a"] * v * v - q * (p["b0"] + p["b1"] * abs(v))
        else:
            dq = p["k"] * max(v - p["v_th"], 0.0) - q / p["tau"] - p["c"] * max(-v, 0.0) * q
        self.q = q + self.ts * dq
        return p["g"] * self.q


# ---------------------------------------------------------------- the chain
class Plant:
    """The whole chain: input-side blocks, linear part, drift, output-side blocks.

    num/den: the (possibly load-modified) linear part; ts: sample period (s);
    convention/skew as for :class:`Linear`; delay_s: pure input delay (s)."""

    def __init__(self, ts, num=None, den=None, convention="zoh", skew=0.0, delay_s=0.0,
                 pre=(), post=(), drift=None):
        if num is None:
            num, den = paper_tf()
        self.ts = ts
        self.lin = Linear(num, den, ts, convention, skew - delay_s / ts)
        self.pre, self.post, self.drift = list(pre), list(post), drift

    def reset(self, v0=0.0):
        """Rest at the constant voltage v0 (kV)."""
        u = v0
        for b in self.pre:
            b.reset(u)
            u = b.step(u)
        self.lin.reset(u)
        z = self.lin.cgam * u + float(self.lin.cphi @ self.lin.x)
        if self.drift is not None:
            self.drift.reset()
        for b in self.post:
            b.reset(z)
            z = b.step(z)

    def step(self, v):
        """One sample: logged voltage v (kV) -> noise-free measured stroke (mm)."""
        u = v
        for b in self.pre:
            u = b.step(u)
        z = self.lin.step(u)
        if self.drift is not None:
            z += self.drift.step(v)
        for b in self.post:
            z = b.step(z)
        return z

    def run(self, v):
        """Simulate a voltage array v (kV) from rest at v[0]; noise-free stroke (mm)."""
        v = np.asarray(v, float)
        self.reset(v[0])
        if not self.pre and not self.post and self.drift is None:
            return self.lin.run(v)
        u = np.array([self._pre(x) for x in v]) if self.pre else v
        z = self.lin.run(u)
        if self.drift is not None:
            z = z + np.array([self.drift.step(x) for x in v])
        for b in self.post:
            b.reset(z[0])
            z = np.array([b.step(x) for x in z])
        return z

    def _pre(self, x):
        for b in self.pre:
            x = b.step(x)
        return x


# ---------------------------------------------------------------- noise
def noise(n, fs, rng, white=0.01, colour=0.0, colour_hz=2.0, wander=0.0, wander_hz=0.02,
          quant=0.0):
    """Additive sensor noise (mm) for n samples at fs (Hz).

    white: std of white noise; colour: std of AR(1) noise with corner colour_hz;
    wander: amplitude of a slow offset wander (sum of three random-phase sines
    below wander_hz plus a random walk scaled to that amplitude); quant: the
    ADC step applied afterwards by :func:`quantise` (returned for reference)."""
    e = white * rng.standard_normal(n)
    if colour > 0:
        a = math.exp(-2 * math.pi * colour_hz / fs)
        w = rng.standard_normal(n) * math.sqrt(1 - a * a) * colour
        e += signal.lfilter([1.0], [1.0, -a], w, zi=[rng.standard_normal() * colour * a])[0]
    if wander > 0:
        t = np.arange(n) / fs
        wv = np.zeros(n)
        for _ in range(3):
            f = rng.uniform(0.2, 1.0) * wander_hz
            wv += np.sin(2 * np.pi * f * t + rng.uniform(0, 2 * np.pi))
        rw = np.cumsum(rng.standard_normal(n))
        rw = signal.sosfiltfilt(signal.butter(2, min(wander_hz, 0.4 * fs) / (fs / 2),
                                              output="sos"), rw) if n > 50 else rw
        rw = rw / (np.std(rw) + 1e-12)
        wv = wv / (np.std(wv) + 1e-12) + 0.5 * rw
        e += wander * wv / np.max(np.abs(wv))
    return e


def quantise(y, step):
    """Round y (mm) to the ADC step (mm); step 0 leaves y unchanged."""
    if step <= 0:
        return y
    return np.round(y / step) * step
