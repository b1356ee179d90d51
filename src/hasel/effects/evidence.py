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

__all__ = ["response_ratio", "resonance_hz", "load_or_delay", "magnitude_evidence"]


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


def magnitude_evidence(ctx: FitContext, without: dict[str, EffectFit], with_: dict[str, EffectFit], den,
                       min_db: float = 1.0, explained: float = 0.5) -> dict:
    """Whether the magnitude near the resonance shows a load: the measured-over-model magnitude within an
    octave of the resonance of ``den`` (RMS, dB) moves by at least ``min_db`` with the model ``without``
    the load, and the model ``with_`` it leaves at most ``explained`` of that (:func:`response_ratio`,
    :func:`hasel.effects.load.resonance_signature`). A delay moves only the phase and a slow drift
    nothing near the resonance, so a load that a delay or a drift would otherwise replace keeps its
    place when this holds. ``min_db`` is :func:`load_or_delay`'s threshold for a load's reading.

    Returns ``{"near_db_without", "near_db_with", "n_bins", "shown"}``."""
    from hasel.effects.load import resonance_signature

    fres = resonance_hz(den)
    f0, r0 = response_ratio(ctx, without)
    f1, r1 = response_ratio(ctx, with_)
    if not np.isfinite(fres) or f0.size < 4 or f1.size < 4:
        return {"near_db_without": float("nan"), "near_db_with": float("nan"), "n_bins": int(min(f0.size, f1.size)),
                "shown": False}
    a = resonance_signature(f0, r0, fres)["magnitude_near_resonance_rms_db"]
    b = resonance_signature(f1, r1, fres)["magnitude_near_resonance_rms_db"]
    shown = bool(np.isfinite(a) and np.isfinite(b) and a >= min_db and b <= explained * a)
    return {"near_db_without": float(a), "near_db_with": float(b), "n_bins": int(min(f0.size, f1.size)),
            "shown": shown}
