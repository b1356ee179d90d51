#!/usr/bin/env python
"""Independent verification corpus for the HASEL sim-to-real diagnosis tool.

Plant: voltage u (kV) -> stroke y (mm).  Nominal
  P(s) = K (s+50.27)(s+62.83)(s^2+w^2)(s+628.3)
         / ((s+18.85)(s+56.55)(s^2+230 s+w^2)^2),  w = 122.2, P(0) = 1.35.
Load changes are applied section-wise; simulation is an exact ZOH of the
series state space at 20x the sample rate, output taken every 20th sample.
numpy/scipy only.
"""
import json
import os

import numpy as np
from scipy import signal

# the corpus directory: VLOAD_DIR (default: beside this file)
OUT = os.environ.get("VLOAD_DIR") or os.path.dirname(os.path.abspath(__file__))
os.makedirs(OUT, exist_ok=True)
SEED = 20261130
W = 122.2
G0 = 1.35
OVS = 20
K = G0 * 18.85 * 56.55 * W**4 / (50.27 * 62.83 * W**2 * 628.3)


def nominal_sections():
    """List of (num, den) sections whose product is P (descending powers)."""
    return [
        ([K, K * 50.27], [1.0, 18.85]),
        ([1.0, 62.83], [1.0, 56.55]),
        ([1.0, 0.0, W**2], [1.0, 230.0, W**2]),
        ([1.0, 628.3], [1.0, 230.0, W**2]),
    ]


def sections_for(form, p):
    s = nominal_sections()
    if form == "none":
        return s
    if form == "zeros":
        k, z = p["k"], p["z"]
        s[2] = ([1.0 / k**2, 2 * z * k * W / k**2, (k * W) ** 2 / k**2], s[2][1])
        return s
    if form == "pendulum":
        wp, wz, zp, zz = p["wp"], p["wz"], p["zp"], p["zz"]
        g = (wp / wz) ** 2
        s.append(([g, g * 2 * zz * wz, g * wz**2], [1.0, 2 * zp * wp, wp**2]))
        return s
    if form == "viscous":
        c = p["c"]
        s[0] = ([c * K, c * K * 50.27], [1.0, c * 18.85])
        s[1] = ([c, c * 62.83], [1.0, c * 56.55])
        return s
    if form == "heavier":
        m = p["m"]
        s[2] = (s[2][0], [m, 230.0, W**2])
        s[3] = (s[3][0], [m, 230.0, W**2])
        return s
    raise ValueError(form)


def series_ss(sections):
    """State space of the series connection, input -> sec0 -> sec1 -> ..."""
    A = np.zeros((0, 0)); B = np.zeros((0, 1)); C = np.zeros((1, 0)); D = np.ones((1, 1))
    for num, den in sections:
        a, b, c, d = signal.tf2ss(num, den)
        n0, n1 = A.shape[0], a.shape[0]
        An = np.zeros((n0 + n1, n0 + n1))
        An[:n0, :n0] = A
        An[n0:, :n0] = b @ C
        An[n0:, n0:] = a
        Bn = np.vstack([B, b @ D])
        Cn = np.hstack([d @ C, c])
        Dn = d @ D
        A, B, C, D = An, Bn, Cn, Dn
    return A, B, C, D


def tf_poly(sections):
    num = np.array([1.0]); den = np.array([1.0])
    for n, d in sections:
        num = np.polymul(num, n); den = np.polymul(den, d)
    return num, den


def simulate(sections, u_fast, dt_fast):
    """Exact ZOH at dt_fast; returns y at every OVS-th fast sample (n = 0, OVS, ...)."""
    A, B, C, D = series_ss(sections)
    Ad, Bd, Cd, Dd, _ = signal.cont2discrete((A, B, C, D), dt_fast, method="zoh")
    nx = A.shape[0]
    # block recursion over OVS fast steps: x[k+OVS] = A^OVS x[k] + sum_j A^(OVS-1-j) B u[k+j]
    G = np.zeros((nx, OVS))
    P = np.eye(nx)
    for j in range(OVS - 1, -1, -1):
        G[:, j] = (P @ Bd)[:, 0]
        P = P @ Ad
    A20 = P
    nslow = len(u_fast) // OVS
    U = u_fast[: nslow * OVS].reshape(nslow, OVS)
    x = -np.linalg.solve(A, B[:, 0]) * u_fast[0]  # rest at the first input value
    X = np.empty((nslow, nx))
    drive = U @ G.T
    for n in range(nslow):
        X[n] = x
        x = A20 @ x + drive[n]
    y = X @ Cd[0] + Dd[0, 0] * U[:, 0]
    return y


# ---------------------------------------------------------------- designs
def design_chirp(rng, fs):
    T = float(rng.uniform(30, 40)); off = float(rng.uniform(3.5, 5)); amp = float(rng.uniform(1, 1.5))
    def f(t):
        return off + amp * signal.chirp(t, f0=0.1, t1=T, f1=30.0, method="logarithmic", phi=-90)
    return T, f, dict(kind="chirp", T=T, offset=off, amp=amp, f0=0.1, f1=30.0)


def design_multisine(rng, fs):
    T = 30.0
    fr = np.logspace(np.log10(0.1), np.log10(30.0), 30)
    ph = rng.uniform(0, 2 * np.pi, 30)
    a = np.sqrt(2.0 / 30.0) * 1.0  # ~1 kV rms total
    def f(t):
        v = 4.5 + a * np.sin(2 * np.pi * np.outer(t, fr) + ph).sum(axis=1)
        return np.clip(v, 0.0, 9.0)
    return T, f, dict(kind="multisine", T=T, offset=4.5, rms=1.0, ntones=30)


def design_levels(rng, fs):
    T = 40.0
    edges = [0.0]; lv = []
    while edges[-1] < T:
        edges.append(edges[-1] + rng.uniform(0.3, 2.0)); lv.append(rng.uniform(0.5, 8.5))
    edges = np.array(edges); lv = np.array(lv)
    def f(t):
        return lv[np.clip(np.searchsorted(edges, t, side="right") - 1, 0, len(lv) - 1)]
    return T, f, dict(kind="levels", T=T, nlevels=len(lv), lo=0.5, hi=8.5, hold=[0.3, 2.0])


def design_prbs(rng, fs):
    T = 30.0
    clk = float(rng.uniform(0.02, 0.05))
    nbits = int(np.ceil(np.log2(T / clk + 1)))
    seq = signal.max_len_seq(nbits, state=rng.integers(0, 2, nbits).clip(0, 1) | np.eye(1, nbits, 0, dtype=int)[0])[0]
    def f(t):
        i = np.floor(t / clk + 1e-9).astype(int) % len(seq)
        return np.where(seq[i] > 0, 6.5, 2.5)
    return T, f, dict(kind="prbs", T=T, clock_s=clk, lo=2.5, hi=6.5, nbits=nbits)


DESIGNS = [design_chirp, design_multisine, design_levels, design_prbs]
RATES = [200, 500, 1000, 2000]


def draw_params(form, rng):
    if form == "none":
        return {}
    if form == "zeros":
        k = rng.uniform(0.6, 0.85) if rng.random() < 0.5 else rng.uniform(1.2, 1.6)
        return dict(k=float(k), z=float(rng.uniform(0.02, 0.3)))
    if form == "pendulum":
        fp = rng.uniform(2.5, 14.0); wp = 2 * np.pi * fp
        r = rng.uniform(0.65, 0.9) if rng.random() < 0.5 else rng.uniform(1.12, 1.45)
        return dict(fp_hz=float(fp), wp=float(wp), ratio=float(r), wz=float(r * wp),
                    zp=float(rng.uniform(0.02, 0.2)), zz=float(rng.uniform(0.02, 0.2)))
    if form == "viscous":
        return dict(c=float(rng.uniform(0.4, 0.75)))
    if form == "heavier":
        return dict(m=float(rng.uniform(1.3, 2.2)))
    raise ValueError(form)


def main():
    rng = np.random.default_rng(SEED)
    # model.json
    num, den = tf_poly(nominal_sections())
    num = np.trim_zeros(num, "f")
    with open(os.path.join(OUT, "model.json"), "w") as fh:
        json.dump({"num": [float(v) for v in num], "den": [float(v) for v in den]}, fh, indent=1)
    assert abs(np.polyval(num, 0) / np.polyval(den, 0) - G0) < 1e-9

    forms = ["zeros", "pendulum", "viscous", "heavier"] * 3 + ["none"] * 4
    forms = list(rng.permutation(forms))
    drift_cases = set(rng.choice(16, size=5, replace=False).tolist())
    cases = []
    for i, form in enumerate(forms):
        dfun = DESIGNS[i % 4]
        fs = RATES[(i + i // 4) % 4]
        T, ufun, dinfo = dfun(rng, fs)
        dtf = 1.0 / (fs * OVS)
        nslow = int(round(T * fs))
        tf_ = np.arange(nslow * OVS) * dtf
        u_fast = np.asarray(ufun(tf_), float)
        u = u_fast[::OVS][:nslow]
        y_nom = simulate(nominal_sections(), u_fast, dtf)
        noise_std = float(rng.uniform(0.003, 0.01))
        tries = 0
        while True:
            tries += 1
            params = draw_params(form, rng)
            y = simulate(sections_for(form, params), u_fast, dtf)
            vis = float(np.std(y - y_nom))
            if form == "none" or vis >= 5 * noise_std:
                break
            if tries > 200:
                raise RuntimeError(f"case {i}: cannot make {form} visible")
        assert np.all(np.isfinite(y))
        noise = rng.normal(0, noise_std, nslow)
        drift = None
        if i in drift_cases:
            wlk = np.cumsum(rng.normal(0, 1, nslow)); wlk -= wlk[0]
            tgt = float(rng.uniform(0.01, 0.02))
            wlk *= tgt / (wlk.max() - wlk.min())
            noise = noise + wlk
            drift = tgt
        ymeas = y + noise
        t = np.arange(nslow) / fs
        fn = f"case{i:02d}_{form}_{dinfo['kind']}_{fs}.csv"
        with open(os.path.join(OUT, fn), "w") as fh:
            fh.write("t_s,voltage_kv,stroke_mm\n")
            for a, b, c in zip(t, u, ymeas):
                fh.write(f"{a:.6f},{b:.6f},{c:.6f}\n")
        label = "none" if form == "none" else "load_mass"
        cases.append(dict(file=fn, form=form, params=params, redraws=tries - 1, design=dinfo, rate=fs,
                          noise=dict(std=noise_std, drift_range=drift), label=label,
                          visibility_std=vis, visibility_ratio=vis / noise_std,
                          y_rms=float(np.std(y)), u_range=[float(u.min()), float(u.max())]))
        print(f"{fn:42s} vis/noise={vis/noise_std:7.1f} redraws={tries-1} params={params}", flush=True)
    with open(os.path.join(OUT, "cases.json"), "w") as fh:
        json.dump(cases, fh, indent=1)


if __name__ == "__main__":
    main()
