"""Whether a given nominal model's gain and sign agree with the log at all.

The diagnosis explains a gap between a log and a nominal model by effects. A model in the
wrong units (m for mm, V for kV) or with the wrong sign leaves a gap that a static map or a
sensor curve can "explain" by a factor of 1000 or -1: a units error would leave as physics at
exit 0. So before any effect is fitted, the measured output is regressed on the nominal
simulation ``y_hat`` over the training samples, ``y ~ a * y_hat + b``, both band-passed (the
same causal filter) in a three-octave band ending at a quarter of the model's slowest pole: there
the model's phase is small, so a delay or a load that moves the phase in the band cannot turn
the scale; the band's lower edge keeps out a slow drift or wander (which would otherwise
decorrelate the two); and noise, being uncorrelated with the simulation, only adds spread. The
model is refused (exit 1) when ``a`` is not positive or lies outside ``[1 / max_factor,
max_factor]``; the check is skipped (and says so) when the log has too little content in the
band to read a scale.

Against a right model, the effects change that scale: a clip or a saturation flattens the top
(``a`` below 1: 0.15 on a tuning pair whose output is clipped to a tenth of the model's swing,
a drift beside it), a sensor curve or a static map bends the range, a load or a delay moves
the dynamics (little in the band). ``max_factor`` = 10 was set on the tuning corpora of
``bench/tune_diag`` (``cases.py`` seed 7, ``combos.py`` seed 21, ``other_pairs.py`` seed 5,
``loads.py`` seed 3: 99 logs with the exact model, ``a`` in :data:`SCALE_SEEN`, 6.7x the
farthest); the units errors it guards against are 1000 (m for mm, V for kV) and 25.4 (inches).
A log saturated to less than a tenth of the model's swing would be refused too: the message
names the gain as a cause, and ``DiagnoseOptions`` cannot switch the check off (a model that far
from the log leaves nothing to diagnose against).
"""
from __future__ import annotations

import numpy as np
from scipy import signal

__all__ = ["MAX_FACTOR", "SCALE_SEEN", "MIN_BAND_SHARE", "BAND_RATIO", "cutoff_hz", "band_pass", "gain_check",
           "scale_check"]

#: Largest factor between the log's output scale and the nominal simulation's that is not
#: taken for a units error (either way).
MAX_FACTOR = 10.0
#: The scale's band spans this ratio of frequencies (3 octaves).
BAND_RATIO = 8.0
#: Least share of the simulation's variance in the band for the scale to be read.
MIN_BAND_SHARE = 0.05
#: Range of the band's regression scale ``a`` over the 99 tuning logs with the exact model (effects included).
SCALE_SEEN = (0.15, 1.54)


def cutoff_hz(den, rate_hz: float) -> float:
    """Upper edge (Hz) of the scale's band: a quarter of the slowest pole's natural frequency of
    ``den`` (a tenth of the rate without a finite non-zero pole), at most a tenth of ``rate_hz``."""
    p = np.roots(np.asarray(den, float))
    w = np.abs(p[np.abs(p) > 0])
    f = 0.25 * float(w.min()) / (2 * np.pi) if w.size else 0.1 * rate_hz
    return float(min(f, 0.1 * rate_hz))


def band_pass(x: np.ndarray, f_hz: float, rate_hz: float) -> np.ndarray:
    """``x`` through a causal 2nd-order Butterworth band-pass from ``f_hz / BAND_RATIO`` to ``f_hz``,
    its first value removed (so it starts at rest)."""
    sos = signal.butter(2, [f_hz / BAND_RATIO, f_hz], btype="bandpass", fs=rate_hz, output="sos")
    x = np.asarray(x, float)
    return signal.sosfilt(sos, x - x[0])


def gain_check(y: np.ndarray, y_hat: np.ndarray, mask: np.ndarray, max_factor: float = MAX_FACTOR) -> dict:
    """Regress the measured output ``y`` on the nominal simulation ``y_hat`` over ``mask``.

    Parameters
    ----------
    y, y_hat : ndarray
        Measured and simulated output (output units), the same samples.
    mask : ndarray of bool
        Samples to use (training samples: no choice may see the final part).
    max_factor : float
        The largest scale factor (either way) not taken for a units error.

    Returns
    -------
    dict
        ``scale`` (a, output units per simulated unit), ``offset`` (b, output units),
        ``ok`` (bool), ``reason`` (str, empty when ok).
    """
    yy, hh = np.asarray(y, float)[mask], np.asarray(y_hat, float)[mask]
    hv = hh - hh.mean()
    den = float(hv @ hv)
    if yy.size < 3 or den <= 0.0:
        # a constant simulation: nothing to compare the scale with
        return {"scale": float("nan"), "offset": float("nan"), "r2": float("nan"), "ok": True, "reason": ""}
    yv = yy - yy.mean()
    a = float(hv @ yv / den)
    b = float(yy.mean() - a * hh.mean())
    # share of the output's variance a scaled copy of the simulation explains (a units or sign
    # error keeps the shape; a clip or a saturation that shrinks the scale does not)
    r2 = float((hv @ yv) ** 2 / max(den * float(yv @ yv), 1e-300))
    if a <= 0.0:
        reason = (f"the log's output moves against the nominal model (best scale {a:.3g}): the model's sign, "
                  f"or the input or output column, is wrong")
    elif not (1.0 / max_factor <= a <= max_factor):
        reason = (f"the log's output is {a:.3g} times the nominal model's (more than {max_factor:g}x either "
                  f"way): the model's units (mm vs m, kV vs V), its gain, or the columns' units are wrong")
    else:
        reason = ""
    return {"scale": a, "offset": b, "r2": r2, "ok": not reason, "reason": reason}


def scale_check(ys: list[np.ndarray], y_hats: list[np.ndarray], masks: list[np.ndarray], den, rate_hz: float,
                max_factor: float = MAX_FACTOR) -> dict:
    """:func:`gain_check` on records band-passed below :func:`cutoff_hz` (each record filtered on its own).

    Parameters
    ----------
    ys, y_hats : list of ndarray
        Measured and nominal simulated output of each record (output units).
    masks : list of ndarray of bool
        Training samples of each record.
    den : array_like
        The nominal model's denominator (descending powers of s).
    rate_hz : float
        Sample rate of the records.

    Returns
    -------
    dict
        :func:`gain_check`'s keys, with ``cutoff_hz``, ``band_hz`` (the band's edges, Hz) and
        ``band_share`` (share of the simulation's training variance in the band); ``checked``
        is False (and ``ok`` True) when that share is below :data:`MIN_BAND_SHARE`.
    """
    fc = cutoff_hz(den, rate_hz)
    band = (fc / BAND_RATIO, fc)
    m = np.concatenate(masks)
    h = np.concatenate(y_hats)[m]
    yl = np.concatenate([band_pass(y, fc, rate_hz) for y in ys])
    hl = np.concatenate([band_pass(y, fc, rate_hz) for y in y_hats])
    share = float(np.var(hl[m]) / max(np.var(h), 1e-300)) if h.size > 2 else 0.0
    if share < MIN_BAND_SHARE:
        return {"scale": float("nan"), "offset": float("nan"), "r2": float("nan"), "ok": True, "reason": "",
                "checked": False, "cutoff_hz": fc, "band_hz": band, "band_share": share}
    g = gain_check(yl, hl, m, max_factor)
    return {**g, "checked": True, "cutoff_hz": fc, "band_hz": band, "band_share": share}
