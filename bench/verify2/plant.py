"""Independent simulator of the HASEL paper's plant P(s) (eq. 17) with unmodelled effects.

Written for the verify2 corpus without reference to the hasel package. Units: time s,
voltage kV, stroke mm, frequency Hz unless a name says rad/s.

The chain (each stage optional, state carried across chunks so that a closed loop can
step it one controller period at a time):

    logged voltage -> [input stages] -> LTI P(s) (or a load-modified P) -> [output stages]
    -> sampled at the log instants (+ a timing skew) -> + noise + sensor offset wander
"""
from __future__ import annotations

import math

import numpy as np
from scipy import linalg, signal

K_PAPER = 10.836       # gain of eq. (17), mm/kV * (rad/s)^...
W_PAPER = 122.2        # anti-resonance and resonance frequency, rad/s
DAMP_PAPER = 230.0     # s coefficient of the double resonant pair, rad/s


def paper_tf(load_mu: float = 0.0, load_form: str = "a"):
    """Return (num, den) of P(s), descending powers of s, kV -> mm.

    load_mu > 0 gives a load-modified plant (mass ratio mu added to the moving mass),
    static gain kept equal to P(0):
      form 'a': both resonant pairs s^2 + 230/(1+mu) s + W^2/(1+mu) (same damper c, mass up);
      form 'b': both pairs keep their damping ratio: s^2 + 230/sqrt(1+mu) s + W^2/(1+mu);
      form 'c': one pair moves as in 'a' and the anti-resonance zeros move with it
                (s^2 + W^2/(1+mu)): the mass shifts the notch as well.
    """
    num = K_PAPER * np.polymul(np.polymul([1, 50.27], [1, 62.83]),
                               np.polymul([1, 628.3], [1, 0, W_PAPER ** 2]))
    p1 = [1, 18.85]
    p2 = [1, 56.55]
    pair = [1, DAMP_PAPER, W_PAPER ** 2]
    if load_mu <= 0:
        den = np.polymul(np.polymul(p1, p2), np.polymul(pair, pair))
        return np.asarray(num, float), np.asarray(den, float)
    m = 1.0 + load_mu
    if load_form == "a":
        lp = [1, DAMP_PAPER / m, W_PAPER ** 2 / m]
        den = np.polymul(np.polymul(p1, p2), np.polymul(lp, lp))
    elif load_form == "b":
        lp = [1, DAMP_PAPER / math.sqrt(m), W_PAPER ** 2 / m]
        den = np.polymul(np.polymul(p1, p2), np.polymul(lp, lp))
    elif load_form == "c":
        lp = [1, DAMP_PAPER / m, W_PAPER ** 2 / m]
        den = np.polymul(np.polymul(p1, p2), np.polymul(pair, lp))
        num = K_PAPER * np.polymul(np.polymul([1, 50.27], [1, 62.83]),
                                   np.polymul([1, 628.3], [1, 0, W_PAPER ** 2 / m]))
    else:
        raise ValueError(load_form)
    num = np.asarray(num, float)
    den = np.asarray(den, float)
    n0, d0 = paper_tf()
    g_nom = n0[-1] / d0[-1]
    num = num * g_nom / (num[-1] / den[-1])
    return num, den


def dc_gain(num, den) -> float:
    """Static gain num(0)/den(0), mm/kV."""
    return float(num[-1] / den[-1])


def zoh_sections(num, den, dt: float):
    """Exact zero-order-hold discretisation of the strictly proper num/den at step dt (s),
    in parallel (partial-fraction) form: a list of (b, a, weight) complex first- or
    second-order sections (a repeated pole as one Jordan block, discretised in closed form),
    to be summed as weight * Re(lfilter(b, a, u)). y[n] is the output at n*dt for an input
    held constant over [k dt, (k+1) dt): y[n] depends on u[n-1] and earlier."""
    r, p, k = signal.residue(num, den, tol=1e-3)
    if np.any(np.abs(k) > 0):
        raise ValueError("P(s) must be strictly proper")
    secs = []
    i = 0
    while i < len(p):
        m = 1
        while i + m < len(p) and abs(p[i + m] - p[i]) < 1e-3 * max(1.0, abs(p[i])):
            m += 1
        pi = p[i]
        if pi.imag < -1e-9:
            i += m
            continue
        wgt = 2.0 if pi.imag > 1e-9 else 1.0
        lam = np.exp(pi * dt)
        if m == 1:
            b = np.array([0.0, r[i] * (lam - 1.0) / pi], complex)
            a = np.array([1.0, -lam], complex)
        elif m == 2:
            r1, r2 = r[i], r[i + 1]                 # r1/(s-p) + r2/(s-p)^2
            A = np.array([[pi, 1.0, 0.0], [0.0, pi, 1.0], [0.0, 0.0, 0.0]], complex)
            E = linalg.expm(A * dt)
            Bd = E[:2, 2]
            Cc = np.array([r2, r1])
            c1 = Cc @ Bd
            c2 = Cc[0] * lam * dt * Bd[1]
            b = np.array([0.0, c1, -c1 * lam + c2], complex)
            a = np.array([1.0, -2.0 * lam, lam * lam], complex)
        else:
            raise ValueError("pole multiplicity > 2 not supported")
        secs.append((b, a, wgt))
        i += m
    return secs


class LTI:
    """Chunked simulation of the parallel sections of zoh_sections, state carried over."""

    def __init__(self, secs, u0: float):
        """secs from zoh_sections; u0: input (kV) at which the plant starts at rest."""
        self.secs = secs
        self.set_rest(u0)

    def set_rest(self, u0: float):
        """Put every section in its steady state for the constant input u0 (kV)."""
        self.zi = [signal.lfilter_zi(b, a) * u0 for b, a, _ in self.secs]

    def run(self, u: np.ndarray) -> np.ndarray:
        """Advance over the fine-grid input chunk u (kV); returns stroke (mm)."""
        y = np.zeros(len(u))
        uc = np.asarray(u, complex)
        for j, (b, a, w) in enumerate(self.secs):
            yj, self.zi[j] = signal.lfilter(b, a, uc, zi=self.zi[j])
            y += w * yj.real
        return y


def freq_response(secs, f, dt):
    """Discrete frequency response of zoh_sections at frequencies f (Hz), step dt (s)."""
    z = np.exp(-2j * np.pi * np.asarray(f) * dt)
    H = np.zeros(len(z), complex)
    for b, a, w in secs:
        Hb = np.polyval(b[::-1], z) / np.polyval(a[::-1], z)
        Hn = np.polyval(np.conj(b)[::-1], z) / np.polyval(np.conj(a)[::-1], z)
        H += Hb if w == 1.0 else (Hb + Hn)
    return H


# ---------------------------------------------------------------- effect stages
# Every stage: __init__(params, h, x0) with h the fine step (s) and x0 the stage's input at
# the start; run(x_chunk) -> y_chunk. Stages are causal and carry state across chunks.

class Delay:
    """Pure transport delay of n fine steps (n*h seconds), initialised with x0."""

    def __init__(self, n: int, x0: float):
        self.buf = np.full(int(n), float(x0))

    def run(self, x):
        z = np.concatenate([self.buf, x])
        self.buf = z[len(x):]
        return z[:len(x)]


class Map:
    """Memoryless map y = f(x) (static_nonlinearity on the input, sensor curve, clip)."""

    def __init__(self, f):
        self.f = f

    def run(self, x):
        return self.f(np.asarray(x, float))


class Play:
    """Prandtl-Ishlinskii operator: w0*x + sum_i w_i * play_{r_i}(x); play half-widths r_i."""

    def __init__(self, radii, weights, w0, x0):
        self.r = np.asarray(radii, float)
        self.w = np.asarray(weights, float)
        self.w0 = float(w0)
        self.s = np.full(len(self.r), float(x0))

    def run(self, x):
        y = np.empty(len(x))
        s = self.s
        r = self.r
        for i, xi in enumerate(x):
            s = np.minimum(xi + r, np.maximum(xi - r, s))
            y[i] = self.w0 * xi + float(np.dot(self.w, s))
        self.s = s
        return y


class BoucWen:
    """Bouc-Wen hysteresis (n = 1) on the input: y = x - c*hz,
    dhz = A dx - beta |dx| hz - gamma dx |hz| (hz in kV, beta/gamma in 1/kV)."""

    def __init__(self, A, beta, gamma, c, x0):
        self.A, self.beta, self.gamma, self.c = A, beta, gamma, c
        self.xp = float(x0)
        self.hz = 0.0

    def run(self, x):
        y = np.empty(len(x))
        xp, hz = self.xp, self.hz
        A, b, g, c = self.A, self.beta, self.gamma, self.c
        for i, xi in enumerate(x):
            dx = xi - xp
            # sub-steps of at most 0.005 kV keep the explicit update stable on jumps
            m = int(abs(dx) / 0.005) + 1
            dd = dx / m
            for _ in range(m):
                hz += A * dd - b * abs(dd) * hz - g * dd * abs(hz)
            xp = xi
            y[i] = xi - c * hz
        self.xp, self.hz = xp, hz
        return y


class AsymLag:
    """First-order lag whose time constant depends on direction: tau_up when the input is
    above the state (rising), tau_down when below (falling). s."""

    def __init__(self, tau_up, tau_down, h, x0):
        self.au = 1.0 - math.exp(-h / tau_up)
        self.ad = 1.0 - math.exp(-h / tau_down)
        self.s = float(x0)

    def run(self, x):
        y = np.empty(len(x))
        s, au, ad = self.s, self.au, self.ad
        for i, xi in enumerate(x):
            s += (au if xi > s else ad) * (xi - s)
            y[i] = s
        self.s = s
        return y


class AsymRate:
    """Falling slew-rate limit (mm/s or kV/s) with free rise: y' >= -rate_down."""

    def __init__(self, rate_down, h, x0):
        self.d = rate_down * h
        self.s = float(x0)

    def run(self, x):
        y = np.empty(len(x))
        s, d = self.s, self.d
        for i, xi in enumerate(x):
            s = xi if xi >= s - d else s - d
            y[i] = s
        self.s = s
        return y


class Charge:
    """Charge retention. form 'a': stroke creep y = x + kappa*q, q' = x - q/tau (integral of
    the voltage with a slow leak); form 'b': screening y = x - q, q' = (rho*x - q)/tau;
    form 'c': field-driven injection y = x*(1 - q), q' = beta*x^2 - q/tau.
    Form 'a' (kappa in mm/(kV s)) is applied as the equivalent voltage kappa*q/P(0), so that
    its static creep is kappa*q mm; all three act on the voltage (kV), before P(s)."""

    def __init__(self, form, p, h, x0, g0):
        self.form, self.p, self.h = form, dict(p), h
        tau = p["tau_s"]
        self.a = math.exp(-h / tau)
        self.g0 = g0
        self.q = 0.0      # no retained charge at the start (after the reversal)

    def run(self, x):
        p, a = self.p, self.a
        tau = p["tau_s"]
        if self.form == "a":
            drive = x * tau            # q -> x*tau in steady state
        elif self.form == "b":
            drive = p["rho"] * x
        else:
            drive = p["beta"] * x * x * tau
        # exact discretisation of q' = (drive - q)/tau with drive held per step
        q, zf = signal.lfilter([1 - a], [1, -a], drive, zi=[a * self.q])
        # q[i] is the state after step i; use the state at the start of the step
        qs = np.concatenate([[self.q], q[:-1]])
        self.q = float(q[-1])
        if self.form == "a":
            return x + p["kappa"] * qs / self.g0
        if self.form == "b":
            return x - qs
        return x * (1.0 - qs)


# ---------------------------------------------------------------- plant assembly

def make_stages(effects, h, u0, y0, sos_fn):
    """Build the stage lists for a list of effect dicts (name, form, params).

    h: fine step (s); u0: first input (kV); sos_fn(num, den) -> sos.
    Returns (input_stages, lti, output_stages)."""
    ins, outs = [], []
    load = None
    order_in = ["saturation_in", "asymmetric_dynamics_in", "time_delay_in", "charge_drift",
                "hysteresis", "static_nonlinearity"]
    order_out = ["saturation_out", "asymmetric_dynamics_out", "sensor_nonlinearity",
                 "time_delay_out"]
    slot_of = {}
    for e in effects:
        slot_of[effect_slot(e)] = e
    num0, den0 = paper_tf()
    g0 = dc_gain(num0, den0)
    for slot in order_in:
        e = slot_of.get(slot)
        if e is not None:
            ins.append(_stage(e, h, u0, g0))
    e = slot_of.get("lti")
    if e is not None:
        num, den = paper_tf(e["params"]["mu"], e["form"])
    else:
        num, den = num0, den0
    lti = LTI(sos_fn(num, den), 0.0)
    outs_e = [slot_of.get(s) for s in order_out]
    for e in outs_e:
        if e is not None:
            outs.append(_stage(e, h, None, g0))
    return ins, lti, outs, (num, den)


def effect_slot(e) -> str:
    """The chain slot of an effect dict."""
    n, f = e["name"], e["form"]
    if n == "saturation":
        return "saturation_in" if f == "b" else "saturation_out"
    if n == "asymmetric_dynamics":
        return "asymmetric_dynamics_in" if f == "b" else "asymmetric_dynamics_out"
    if n == "time_delay":
        return "time_delay_out" if f == "b" else "time_delay_in"
    if n == "load_mass":
        return "lti"
    return n


def _stage(e, h, x0, g0):
    n, f, p = e["name"], e["form"], e["params"]
    x0 = 0.0 if x0 is None else x0
    if n == "static_nonlinearity":
        if f == "a":
            a, vr = p["a"], p["v_ref_kv"]
            return Map(lambda v: (1 - a) * v + a * v * np.abs(v) / vr)
        if f == "b":
            pw, vr = p["p"], p["v_ref_kv"]
            return Map(lambda v: vr * np.sign(v) * np.abs(v / vr) ** pw)
        vk, g, wd = p["v_knee_kv"], p["g_below"], p["width_kv"]
        # smooth knee: slope g below v_knee, 1 above; value continuous, equals v above
        return Map(lambda v: v - (1 - g) * wd * np.logaddexp(0.0, (vk - v) / wd))
    if n == "hysteresis":
        if f == "a":
            return Play([p["r_kv"]], [1.0], 0.0, x0)
        if f == "b":
            return Play(p["radii_kv"], p["weights"], p["w0"], x0)
        return BoucWen(p["A"], p["beta"], p["gamma"], p["c"], x0)
    if n == "saturation":
        if f == "a":
            hi = p["z_max_mm"]
            return Map(lambda z: np.minimum(z, hi))
        if f == "b":
            hi = p["v_max_kv"]
            return Map(lambda v: np.minimum(v, hi))
        lo, hi = p["z_min_mm"], p["z_max_mm"]
        return Map(lambda z: np.clip(z, lo, hi))
    if n == "asymmetric_dynamics":
        if f == "a":
            return AsymLag(p["tau_up_s"], p["tau_down_s"], h, x0)
        if f == "b":
            return AsymLag(p["tau_up_s"], p["tau_down_s"], h, x0)
        return AsymRate(p["rate_down_mm_s"], h, x0)
    if n == "time_delay":
        return Delay(int(round(p["delay_s"] / h)), x0)
    if n == "charge_drift":
        return Charge(f, p, h, x0, g0)
    if n == "sensor_nonlinearity":
        zc, zs = p["z_c_mm"], p["z_span_mm"]
        if f == "a":
            a = p["a"]
            return Map(lambda z: z + a * (z - zc) ** 2 / zs)
        if f == "b":
            b = p["b"]
            return Map(lambda z: z + b * ((z - zc) / zs) ** 3 * zs)
        e_, per = p["e_mm"], p["period_mm"]
        return Map(lambda z: z + e_ * np.sin(2 * np.pi * (z - zc) / per))
    raise ValueError(n)


class Plant:
    """The whole chain on a fine grid of step h (s), chunk by chunk."""

    def __init__(self, effects, h, u0):
        """effects: list of effect dicts; h: fine step, s; u0: the input (kV) the plant has
        rested at before t = 0 (every stage starts in its steady state for u0)."""
        self.h = h
        self.ins, self.lti, self.outs, self.tf = make_stages(
            effects, h, u0, None, lambda n, d: zoh_sections(n, d, h))
        # bring each stage to rest at u0: run a short constant prefix through them
        x = np.full(1, float(u0))
        for st in self.ins:
            if isinstance(st, Delay):
                st.buf[:] = x[0]
            x = st.run(x)
        self.lti.set_rest(x[0])
        z = np.full(1, dc_gain(*self.tf) * x[0])
        for st in self.outs:
            if isinstance(st, Delay):
                st.buf[:] = z[0]
            elif isinstance(st, (AsymLag, AsymRate)):
                st.s = float(z[0])
            z = st.run(z)

    def run(self, u_fine):
        """Fine-grid input chunk (kV) -> fine-grid true sensed stroke (mm), noise-free."""
        x = np.asarray(u_fine, float)
        for st in self.ins:
            x = st.run(x)
        z = self.lti.run(x)
        for st in self.outs:
            z = st.run(z)
        return z


def simulate_open(effects, t_log, u_of_t, u_log, conv, skew, M):
    """Open-loop simulation.

    t_log: log times (s), uniform; u_of_t: the continuous design function (for 'centred');
    u_log: logged input samples (kV); conv: 'zoh' | 'foh' | 'centred' | 'skew';
    skew: output sampling offset in log samples (output taken at t_k + skew*T, rounded to
    the fine grid); M: fine steps per log sample. Returns (y_log noise-free, actual skew).
    """
    T = t_log[1] - t_log[0]
    h = T / M
    n = len(t_log)
    nf = n * M
    tf = t_log[0] + np.arange(nf) * h
    if conv == "zoh" or conv == "skew":
        uf = np.repeat(u_log, M)
    elif conv == "foh":
        # linear interpolation between log samples, evaluated at fine midpoints
        uf = np.interp(tf + h / 2, t_log, u_log)
    elif conv == "centred":
        uf = u_of_t(tf + h / 2)
    else:
        raise ValueError(conv)
    u0 = uf[0]
    pl = Plant(effects, h, u0)
    yf = pl.run(uf)
    s = int(round(skew * M))
    idx = np.arange(n) * M + s
    y = np.where(idx < 0, yf[0], yf[np.clip(idx, 0, nf - 1)])
    return y, s / M
