"""Where the gap lives: the nominal residual localised in frequency, time, level, direction, amplitude.

All measures are of ``r = y - y_nominal`` on the log(s), compared with the noise
variance ``sigma2`` estimated from the data. Shares are fractions of the residual's
variance that a simple description explains:

- frequency: the residual's spectrum in bands against the noise level; a
  *model-error model* after Ljung (a FIR from the input to the residual, fitted by
  least squares, with its covariance), whose response is reported with 99 % bounds
  and the bands where it differs significantly from zero; ``linear_share`` is the
  residual variance that this linear error model explains (a linear gap has a
  large one, a nonlinear or time-varying gap a small one).
- time: linear trend with its t statistic; the share of slow variation (moving
  average over many time constants); RMS per tenth of the log; the change between
  repeats of the excitation (when the input repeats itself).
- level: residual means in bins of the operating level (the input and the nominal
  output, each averaged over two time constants).
- direction: extra share explained when each level bin is split by the direction
  of the nominal output (rising = activation, falling = relaxation); and the same
  at equal *input* levels split by the sign of the input's rate (a memory loop of
  the input, such as hysteresis, shows there even when a lagging model hides it).
- amplitude: residual RMS in bins of the local excitation amplitude.
- delay signature: correlation of the residual with the nominal output's rate.
"""
from __future__ import annotations

import math

import numpy as np
from scipy import linalg, signal, stats

from hasel.diagnose.augment import Pipeline

__all__ = ["analyse", "model_error_model"]


def _movavg(x: np.ndarray, n: int) -> np.ndarray:
    n = max(1, int(n))
    if n == 1:
        return x.copy()
    k = np.ones(n) / n
    pad = np.concatenate([np.full(n // 2, x[0]), x, np.full(n - n // 2 - 1, x[-1])])
    return np.convolve(pad, k, mode="valid")


def _share_binned(r: np.ndarray, labels: np.ndarray) -> float:
    """Fraction of var(r) explained by the mean of r within each label."""
    v = float(np.var(r))
    if v <= 0:
        return 0.0
    uniq, inv, cnt = np.unique(labels, return_inverse=True, return_counts=True)
    means = np.bincount(inv, weights=r) / cnt
    return float(np.sum(cnt * (means - r.mean()) ** 2) / (r.size * v))


def _quantile_bins(x: np.ndarray, n: int) -> np.ndarray:
    edges = np.unique(np.quantile(x, np.linspace(0, 1, n + 1)))
    if edges.size < 3:
        return np.zeros(x.size, int)
    return np.clip(np.searchsorted(edges, x, side="right") - 1, 0, edges.size - 2)


def model_error_model(u: np.ndarray, r: np.ndarray, rate_hz: float, n_taps: int,
                      f_hz: np.ndarray) -> dict:
    """FIR model-error model from ``u`` to ``r`` with 99 % significance per frequency.

    Parameters
    ----------
    u, r : ndarray
        Input and residual at ``rate_hz``.
    rate_hz : float
        Sample rate, Hz.
    n_taps : int
        FIR length, samples.
    f_hz : ndarray
        Frequencies to evaluate, Hz.

    Returns
    -------
    dict
        ``f_hz``, ``mag`` (|G_err|), ``bound`` (99 % half-width of |G_err| from the
        covariance), ``significant`` (bool per frequency), ``linear_share``.
    """
    uc = u - u.mean()
    rc = r - r.mean()
    n = uc.size
    nfft = int(2 ** np.ceil(np.log2(2 * n)))
    U = np.fft.rfft(uc, nfft)
    Rc = np.fft.rfft(rc, nfft)
    ruu = np.fft.irfft(U * np.conj(U), nfft)[:n_taps] / n
    rur = np.fft.irfft(Rc * np.conj(U), nfft)[:n_taps] / n
    ruu[0] *= 1.0 + 1e-6  # a little ridge: frequencies the input does not excite stay near zero
    try:
        h = linalg.solve_toeplitz(ruu, rur)
    except (linalg.LinAlgError, ValueError):
        h = np.zeros(n_taps)
    fit = signal.lfilter(h, [1.0], uc)
    e = rc - fit
    s2 = float(np.var(e))
    share = 1.0 - s2 / float(np.var(rc)) if np.var(rc) > 0 else 0.0
    # effective samples: the error of a nonlinear gap is coloured, so discount by its correlation
    rho = float(np.corrcoef(e[:-1], e[1:])[0, 1]) if e.size > 3 and np.std(e) > 0 else 0.0
    rho = min(max(rho, 0.0), 0.99)
    n_eff = n * (1 - rho) / (1 + rho)
    try:
        Rinv = linalg.inv(linalg.toeplitz(ruu))
    except linalg.LinAlgError:
        Rinv = np.eye(n_taps) / max(ruu[0], 1e-300)
    C = s2 / n_eff * Rinv
    k = np.arange(n_taps)
    w = 2 * np.pi * np.asarray(f_hz)[:, None] * k[None, :] / rate_hz
    Jc, Js = np.cos(w), -np.sin(w)
    G = Jc @ h + 1j * (Js @ h)
    mag = np.abs(G)
    sig = np.zeros(mag.size, bool)
    bound = np.zeros(mag.size)
    chi = stats.chi2.ppf(0.99, 2)
    for i in range(mag.size):
        J = np.vstack([Jc[i], Js[i]])
        S = J @ C @ J.T
        v = np.array([G[i].real, G[i].imag])
        try:
            d2 = float(v @ np.linalg.solve(S, v))
        except np.linalg.LinAlgError:
            d2 = 0.0
        sig[i] = d2 > chi
        bound[i] = math.sqrt(chi * max(np.linalg.eigvalsh(S).max(), 0.0))
    return {"f_hz": np.asarray(f_hz).tolist(), "mag": mag.tolist(), "bound": bound.tolist(),
            "significant": sig.tolist(), "linear_share": float(max(share, 0.0)), "n_taps": int(n_taps)}


def _bands(f: np.ndarray, sig: np.ndarray) -> list[list[float]]:
    out, start = [], None
    for i, s in enumerate(sig):
        if s and start is None:
            start = i
        if (not s or i == sig.size - 1) and start is not None:
            end = i if s else i - 1
            out.append([float(f[start]), float(f[end])])
            start = None
    return out


def _repeats(u: np.ndarray, y: np.ndarray, fs: float, tdom: float, sigma2: float) -> dict:
    """Change of the residual ``y`` between repeats of the excitation (if the input repeats).

    The input's repetition period comes from :func:`hasel.ident.detect_period` on its
    fast part (the operating level removed); where the input one period later is the
    same, the residual's difference one period later is noise (times sqrt 2) plus
    whatever changed in between: drift, memory, time variation (the nominal model's own
    transients cancel in the residual).
    """
    try:
        from hasel.ident import detect_period
    except ImportError:
        return {"period_s": None}
    fast = u - _movavg(u, int(max(4 * tdom * fs, 3)))
    try:
        period = detect_period(fast, fs, min_period_s=10 * max(tdom, 1 / fs), threshold=0.5)
    except Exception:  # noqa: BLE001 - no period is an answer too
        period = None
    if not period:
        return {"period_s": None}
    t = np.arange(u.size) / fs
    inside = t + period <= t[-1]
    if inside.sum() < 20:
        return {"period_s": None}
    u2 = np.interp(t[inside] + period, t, u)  # one period later (a period need not be whole samples)
    y2 = np.interp(t[inside] + period, t, y)
    same = np.abs(u2 - u[inside]) <= 1e-3 * max(np.ptp(u), 1e-300)
    if same.sum() < 20:
        return {"period_s": float(period), "matched_samples": int(same.sum())}
    d = (y2 - y[inside])[same]
    rms = float(np.sqrt(np.mean(d * d) / 2.0))
    return {"period_s": float(period), "matched_samples": int(same.sum()),
            "repeat_difference_rms": rms, "over_noise": rms / max(math.sqrt(sigma2), 1e-300),
            "mean_change_per_period": float(np.mean(d))}


def analyse(pipe: Pipeline, sigma2: float, noise_method: str) -> dict:
    """The WHERE part of the verdict (JSON-ready) plus private arrays under ``"_arrays"``.

    Parameters
    ----------
    pipe : Pipeline
        Data and nominal model.
    sigma2 : float
        Noise variance at the working rate, output unit squared.
    noise_method : str
        How ``sigma2`` was estimated.
    """
    prep = pipe.prep
    fs = prep.rate_hz
    rec = prep.records[0]
    y_nom = pipe.simulate({}, 0)
    r = rec.y - y_nom
    u = rec.u
    t = rec.t_s
    n = r.size
    var_r = float(np.var(r))
    tdom = max(pipe.t_dom, 2.0 / fs)
    out: dict = {"units_note": "residual r = measured - nominal, in the output's unit",
                 "residual_rms": float(np.sqrt(np.mean(r * r))), "residual_mean": float(r.mean()),
                 "noise_rms": float(math.sqrt(sigma2)), "noise_method": noise_method,
                 "gap_to_noise_ratio": float(np.sqrt(np.mean(r * r)) / max(math.sqrt(sigma2), 1e-300))}

    # ---- frequency -----------------------------------------------------------------------
    f_exc = min(prep.f_excited_hz, fs / 2)
    nper = int(min(n, max(64, 2 ** int(np.log2(max(n // 8, 64))))))
    f, p = signal.welch(r - r.mean(), fs=fs, nperseg=nper)
    noise_psd = sigma2 / (fs / 2)
    f_lo = max(f[1] if f.size > 1 else fs / n, 1.0 / (t[-1] - t[0] + 1 / fs))
    edges = list(np.geomspace(f_lo, max(f_exc, 2 * f_lo), 7))
    if 3 * f_exc < fs / 2:
        edges += [3 * f_exc]
    edges += [fs / 2]
    bands = []
    for a, b in zip(edges[:-1], edges[1:]):
        m = (f >= a) & (f < b)
        if not m.any():
            continue
        df = f[1] - f[0]
        pw = float(p[m].sum() * df)
        nw = float(noise_psd * m.sum() * df)
        bands.append({"f_lo_hz": float(a), "f_hi_hz": float(b), "residual_power": pw, "noise_power": nw,
                      "ratio_db": float(10 * np.log10(max(pw, 1e-300) / max(nw, 1e-300)))})
    # the error model lives at a rate a few times the excited band (block means), where the
    # input excites every frequency the FIR can represent: a well-conditioned estimate
    q = max(1, int(fs // max(6.0 * f_exc, 1e-9)))
    fs_m = fs / q
    nq = (n // q) * q
    u_m = u[:nq].reshape(-1, q).mean(axis=1)
    r_m = r[:nq].reshape(-1, q).mean(axis=1)
    n_taps = int(np.clip(round(3 * tdom * fs_m), 8, 120))
    n_taps = min(n_taps, max(4, u_m.size // 10))
    fg = np.geomspace(f_lo, max(min(f_exc, 0.45 * fs_m), 2 * f_lo), 40)
    mem = model_error_model(u_m, r_m, fs_m, n_taps, fg)
    mem["rate_hz"] = fs_m
    from hasel.lti import tf_freqresp

    gnom = np.abs(tf_freqresp(pipe.num, pipe.den, fg))
    rel = np.asarray(mem["mag"]) / np.maximum(gnom, 1e-300)
    mem["relative_to_nominal"] = rel.tolist()
    mem["significant_bands_hz"] = _bands(fg, np.asarray(mem["significant"]))
    out["frequency"] = {"excited_band_hz": [0.0, float(f_exc)], "residual_spectrum_bands": bands,
                        "model_error": mem,
                        "share_above_excited_band": float(sum(b["residual_power"] for b in bands
                                                              if b["f_lo_hz"] >= f_exc) /
                                                          max(sum(b["residual_power"] for b in bands), 1e-300))}

    # ---- delay signature --------------------------------------------------------------------
    dy = np.gradient(y_nom, 1.0 / fs)
    if np.std(dy) > 0 and np.std(r) > 0:
        rho_d = float(np.corrcoef(r, dy)[0, 1])
        d_est = float(-(r - r.mean()) @ (dy - dy.mean()) / ((dy - dy.mean()) @ (dy - dy.mean())))
    else:
        rho_d, d_est = 0.0, 0.0
    out["rate"] = {"corr_residual_vs_nominal_rate": rho_d, "lag_estimate_s": d_est}

    # ---- time ------------------------------------------------------------------------------------
    tt = t - t.mean()
    slope = float(tt @ (r - r.mean()) / (tt @ tt))
    e = r - r.mean() - slope * tt
    rho = float(np.corrcoef(e[:-1], e[1:])[0, 1]) if n > 3 and np.std(e) > 0 else 0.0
    rho = min(max(rho, 0.0), 0.999)
    n_eff = max(n * (1 - rho) / (1 + rho), 3.0)
    se = math.sqrt(float(np.var(e)) / (tt @ tt) * n / n_eff) if np.var(e) > 0 else float("inf")
    w_slow = int(max(20 * tdom * fs, n / 50))
    slow = _movavg(r, w_slow)
    blocks = np.array_split(np.arange(n), 10)
    out["time"] = {"trend_per_s": slope, "trend_t": float(slope / se) if se > 0 else 0.0,
                   "trend_share": float(slope * slope * (tt @ tt) / n / var_r) if var_r > 0 else 0.0,
                   "slow_share": float(np.var(slow) / var_r) if var_r > 0 else 0.0,
                   "slow_window_s": float(w_slow / fs),
                   "block_rms": [float(np.sqrt(np.mean(r[b] ** 2))) for b in blocks],
                   "block_mean": [float(np.mean(r[b])) for b in blocks]}

    out["time"]["repeats"] = _repeats(u, r, fs, tdom, sigma2)

    # ---- level, direction, amplitude -----------------------------------------------------------
    w_lvl = int(max(2 * tdom * fs, 3))
    lvl_u = _movavg(u, w_lvl)
    lvl_y = _movavg(y_nom, w_lvl)
    bu = _quantile_bins(lvl_u, 10)
    by = _quantile_bins(lvl_y, 10)
    share_u = _share_binned(r, bu)
    share_y = _share_binned(r, by)
    inst_y = _quantile_bins(y_nom, 10)
    share_inst = _share_binned(r, inst_y)
    dy_s = _movavg(dy, max(w_lvl // 4, 1))
    up = dy_s > 0
    share_dir = _share_binned(r, inst_y * 2 + up) - share_inst
    diffs, wts = [], []
    for b in np.unique(inst_y):
        m = inst_y == b
        a, c = r[m & up], r[m & ~up]
        if a.size > 5 and c.size > 5:
            diffs.append(a.mean() - c.mean())
            wts.append(min(a.size, c.size))
    up_down = float(np.average(diffs, weights=wts)) if diffs else 0.0

    def table(bins: np.ndarray, x: np.ndarray) -> dict:
        ids = np.unique(bins)
        return {"level": [float(np.mean(x[bins == i])) for i in ids],
                "residual_mean": [float(np.mean(r[bins == i])) for i in ids],
                "residual_rms": [float(np.sqrt(np.mean(r[bins == i] ** 2))) for i in ids]}

    out["level"] = {"share_input_level": share_u, "share_output_level": share_y,
                    "share_instant_output": share_inst, "by_input_level": table(bu, lvl_u),
                    "by_output_level": table(by, lvl_y), "level_window_s": float(w_lvl / fs)}
    du_s = _movavg(np.gradient(u), max(w_lvl // 4, 1))
    up_u = du_s > 0
    inst_u = _quantile_bins(u, 10)
    share_in = _share_binned(r, inst_u)
    share_in_dir = _share_binned(r, inst_u * 2 + up_u) - share_in
    out["direction"] = {"extra_share": float(max(share_dir, 0.0)), "rising_minus_falling": up_down,
                        "input_level_share": share_in, "input_direction_extra_share": float(max(share_in_dir, 0.0)),
                        "rising_minus_falling_over_noise": float(up_down / max(math.sqrt(sigma2), 1e-300)),
                        "rising_fraction": float(up.mean())}
    amp = np.sqrt(_movavg((u - lvl_u) ** 2, w_lvl))
    ba = _quantile_bins(amp, 6)
    tab = table(ba, amp)
    out["amplitude"] = {"by_excitation_amplitude": {"amplitude": tab["level"], "residual_rms": tab["residual_rms"]},
                        "corr_abs_residual_vs_amplitude": float(np.corrcoef(np.abs(r), amp)[0, 1])
                        if np.std(amp) > 0 and np.std(r) > 0 else 0.0}
    out["_arrays"] = {"f_hz": f, "psd": p, "noise_psd": noise_psd, "fg": fg, "gnom": gnom, "r": r, "t": t,
                      "lvl_u": lvl_u, "up": up, "y_nom": y_nom}
    return out
