"""Frequency-domain evidence shared by the families' signature hooks.

:func:`response_ratio` estimates how the measured response differs from the model's
(measured over simulated, from the same input, by Welch cross-spectra); the families
read it their own way: a delay (:func:`hasel.effects.delay.phase_signature`) moves only
the phase, linearly in frequency; a load
(:func:`hasel.effects.load.resonance_signature`) moves the magnitude near the
resonance. :func:`load_or_delay` puts the two side by side.
"""
from __future__ import annotations

import numpy as np
from scipy import signal

from hasel.effects.base import EffectFit, FitContext

__all__ = ["response_ratio", "resonance_hz", "load_or_delay"]


def response_ratio(ctx: FitContext, effects: dict[str, EffectFit], min_coherence: float = 0.9,
                   f_max_hz: float | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Measured over modelled frequency response, from the input the linear part sees.

    For every record: ``H_meas = S_xy / S_xx`` and ``H_model = S_xyhat / S_xx`` (Welch,
    segments of a quarter of the record, at most 4096 samples), ``x`` the chain's
    input to the linear part (``x_eff``) with ``effects`` in place; their ratio where the
    measured coherence is at least ``min_coherence`` (and below ``f_max_hz``,
    default the excited band's top).

    Returns
    -------
    (freqs_hz, ratio) : ndarray, ndarray of complex
    """
    fs = ctx.prep.rate_hz
    f_top = f_max_hz if f_max_hz is not None else float(getattr(ctx.prep, "f_excited_hz", 0.45 * fs) or 0.45 * fs)
    fr, rr = [], []
    for ri, rec in enumerate(ctx.prep.records):
        st = ctx.stages(effects, ri)
        x, y, yh = st["x_eff"], rec.y, st["y"]
        n = int(min(4096, max(64, x.size // 4)))
        if x.size < 2 * n or np.ptp(x) <= 0:
            continue
        f, sxx = signal.welch(x - x.mean(), fs, nperseg=n)
        _, sxy = signal.csd(x - x.mean(), y - y.mean(), fs, nperseg=n)
        _, sxh = signal.csd(x - x.mean(), yh - yh.mean(), fs, nperseg=n)
        _, syy = signal.welch(y - y.mean(), fs, nperseg=n)
        coh = np.abs(sxy) ** 2 / np.maximum(sxx * syy, 1e-300)
        ok = (coh >= min_coherence) & (f > 0) & (f <= f_top) & (np.abs(sxh) > 0)
        fr.append(f[ok])
        rr.append(sxy[ok] / sxh[ok])
    if not fr:
        return np.zeros(0), np.zeros(0, complex)
    f = np.concatenate(fr)
    order = np.argsort(f, kind="stable")
    return f[order], np.concatenate(rr)[order]


def resonance_hz(den) -> float:
    """Natural frequency (Hz) of the lowest complex pole pair of ``den`` (nan without one)."""
    p = np.roots(np.asarray(den, float))
    c = p[np.abs(p.imag) > 1e-9 * np.maximum(1.0, np.abs(p))]
    return float(np.min(np.abs(c)) / (2 * np.pi)) if c.size else float("nan")


def load_or_delay(ctx: FitContext, effects: dict[str, EffectFit], den) -> dict:
    """Both readings of the response ratio: a delay's (phase linear in frequency, magnitude flat) and a
    load's (magnitude moved near the resonance of ``den``), and which one the data favour.

    ``"favours"``: ``"time_delay"`` when the magnitude stays within 0.5 dB RMS over the
    band and a delay of at least half a sample explains the phase to within 3 degrees
    RMS; ``"load_mass"`` when the magnitude near the resonance moves by more than 1 dB
    RMS and no delay explains the phase (3 degrees or more left); ``"none"`` when neither
    magnitude nor phase moves; else ``"unclear"``. It chooses between these two linear
    readings only: a nonlinear effect moves the linear ratio too (its gap reads as
    ``"load_mass"`` or ``"unclear"``), so it is evidence for a load *against a delay*, not
    a detector. On the tuning corpus (``python -m hasel_bench.othersim``, seed 0, nominal model):
    both delays read ``time_delay`` (19.4 and 19.0 ms, magnitude 0.07 and 0.05 dB RMS),
    both loads ``load_mass`` (1.1 and 4.6 dB, 5.9 and 20.9 degrees left after a delay),
    all six effect-free logs ``none``.
    """
    from hasel.effects.delay import phase_signature
    from hasel.effects.load import resonance_signature

    f, r = response_ratio(ctx, effects)
    if f.size < 4:
        return {"favours": "unclear", "n_bins": int(f.size)}
    fres = resonance_hz(den)
    ph = phase_signature(f, r)
    ld = resonance_signature(f, r, fres) if np.isfinite(fres) else {}
    near = ld.get("magnitude_near_resonance_rms_db", float("nan"))
    mag, phres, d = ph["magnitude_rms_db"], ph["phase_residual_rms_deg"], abs(ph["delay_s"])
    if mag < 0.5 and phres < 3.0:
        fav = "time_delay" if d >= 0.5 * ctx.prep.dt_s else "none"
    elif np.isfinite(near) and near > 1.0 and phres >= 3.0:
        fav = "load_mass"
    else:
        fav = "unclear"
    return {"favours": fav, "n_bins": int(f.size), "band_hz": [float(f[0]), float(f[-1])], "delay": ph, "load": ld}
