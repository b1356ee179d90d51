"""Held-out significance of a candidate effect, and explanations that the data cannot separate.

:func:`block_test` (a signed-rank test over held-out blocks, :mod:`hasel.effects.heldout`) and
:func:`coloured_z` (a z score against noise of the measured colour) decide whether an effect's
improvement is more than noise;
:func:`_alike` finds another explanation that scores like the chosen one, with the experiment
that would separate them (:data:`_SEPARATING`).
"""
from __future__ import annotations

import math

import numpy as np
from scipy.signal import lfilter

from hasel.diagnose.augment import LINEAR
from hasel.diagnose.options import DiagnoseOptions
from hasel.effects.heldout import block_test, moving_average

__all__ = ["block_test", "coloured_z", "white_z", "ar_whitener", "whitened_scores"]


def coloured_z(e_old: np.ndarray, e_new: np.ndarray, max_lag: int, slow_n: int = 0) -> float:
    """Validation improvement ``e_old -> e_new`` against noise of the measured colour (a z score).

    The drop of the squared error, ``sum(e_old^2 - e_new^2)``, would under noise alone have a
    standard deviation of ``2 sqrt(delta' R delta)`` (``delta`` the change of the prediction,
    ``R`` the noise covariance). ``R`` is taken from the autocovariance of ``e_new`` up to
    ``max_lag`` samples with Bartlett weights (a Newey-West estimate: coloured noise and slow
    wander within that span widen it; the model error still in ``e_new`` only makes it larger).
    Unlike :func:`block_test` it credits an effect that shows in a few places only (steps'
    transients, a clip). Both residuals first lose their slow part (a moving average over
    ``slow_n`` samples), so that a fit to slow sensor wander earns nothing here.
    """
    if slow_n > 1:
        e_old = e_old - moving_average(e_old, slow_n)
        e_new = e_new - moving_average(e_new, slow_n)
    delta = e_old - e_new
    r = e_new - e_new.mean()
    n = r.size
    lag = int(max(0, min(max_lag, n // 4)))
    nfft = 1 << int(np.ceil(np.log2(2 * n)))
    fr, fd = np.fft.rfft(r, nfft), np.fft.rfft(delta, nfft)
    acov = np.fft.irfft(fr * np.conj(fr), nfft)[:lag + 1] / n
    cd = np.fft.irfft(fd * np.conj(fd), nfft)[:lag + 1]
    w = 1.0 - np.arange(lag + 1) / (lag + 1.0)
    var = float(acov[0] * cd[0] + 2.0 * np.sum(w[1:] * acov[1:] * cd[1:]))
    var = max(var, float(acov[0] * cd[0]), 1e-300)
    return float(np.sum(e_old ** 2 - e_new ** 2) / (2.0 * math.sqrt(var)))


#: The experiment that separates two explanations that score alike (either order).
_SEPARATING = {
    frozenset(("static_nonlinearity", "sensor_nonlinearity")):
        "an input-side and an output-side map differ in how their harmonics pass the dynamics: a band that "
        "reaches above the resonance (the input-side map's harmonics are filtered there, the sensor's are not), "
        "or slow steps at several levels with a fast sweep on top, separates them",
    frozenset(("hysteresis", "static_nonlinearity")):
        "a static map has no loop and a hysteresis keeps its loop at any rate: the same amplitude swept very "
        "slowly (well below the first resonance) in both directions, at two amplitudes, separates them",
    frozenset(("hysteresis", "sensor_nonlinearity")):
        "a very slow sweep in both directions: a sensor curve has no loop, a hysteresis keeps one",
    frozenset(("load_mass", "time_delay")):
        "a load moves the magnitude near the resonance, a delay only the phase (linear in frequency): a "
        "sweep through the resonance with enough amplitude there separates them",
    frozenset(("saturation", "sensor_nonlinearity")):
        "a clip piles samples on one value and an end stop flattens one end with the rest straight, where a "
        "sensor curve bends the whole range: a larger amplitude that drives the output further into the limit "
        "separates them",
    frozenset(("saturation", "static_nonlinearity")):
        "a larger amplitude: a limit flattens the response beyond one value, a map bends the whole range",
    frozenset(("charge_drift", "load_mass")):
        "a drift follows the history of the input: a long hold at a high level then at a low one separates it "
        "from a change of the dynamics",
    frozenset(("asymmetric_dynamics", "hysteresis")):
        "a direction-dependent lag fades at slow rates, a hysteresis does not: the same steps at two rates "
        "separate them",
}


def _alike(results: list[tuple], eff_new: dict, e_new: np.ndarray, mse_ho: float, gain: float,
           labels_va: np.ndarray, opts: DiagnoseOptions, to_nrmse, slow_n: int = 0) -> dict | None:
    """The best other explanation when it scores like the chosen one on validation, else None.

    Another explanation (a candidate set holding none of the newly chosen effects) is alike
    when it removes at least ``opts.alike_share`` of what the chosen removes and the held-out
    block test does not prefer the chosen one by ``opts.t_min``.
    """
    new = [k for k in eff_new if k != LINEAR and not k.startswith("_")]
    for r in results:
        names = [k for k in r[6] if k != LINEAR]
        if set(names) & set(new) or not names:
            continue
        g_alt = (mse_ho - r[0]) / mse_ho if mse_ho > 0 else 0.0
        if g_alt <= 0 or g_alt < opts.alike_share * gain:
            return None  # sorted by validation error: no later one is alike either
        pref = block_test(r[5], e_new, labels_va, slow_n)
        if pref >= opts.t_min:
            continue
        key = frozenset((new[-1], names[-1])) if new else frozenset()
        return {"chosen": " + ".join(new), "alternative": " + ".join(names),
                "validation_nrmse": {"chosen": to_nrmse(mse_ho * (1 - gain)), "alternative": to_nrmse(r[0])},
                "gap_removed": {"chosen": gain, "alternative": g_alt}, "preference": pref,
                "experiment": _SEPARATING.get(key, "another band, another rate or another amplitude, where the two "
                                                   "explanations predict different outputs")}
    return None


def white_z(e_old: np.ndarray, e_new: np.ndarray, var: float) -> float:
    """Paired z of the validation SSE drop ``e_old -> e_new`` against white noise of variance ``var`` (output unit
    squared): with that noise a change ``delta`` of the prediction drops the SSE by a quantity of sd
    ``2 sqrt(var) ||delta||``."""
    return float(np.sum(e_old ** 2 - e_new ** 2)
                 / (2.0 * math.sqrt(var) * max(float(np.linalg.norm(e_old - e_new)), 1e-300)))


def ar_whitener(e: np.ndarray, labels: np.ndarray, max_order: int) -> np.ndarray:
    """Coefficients ``a`` (``a[0] = 1``) of the prediction-error filter ``A(q)`` of an AR model of ``e``.

    The autocovariance is summed within the blocks of ``labels`` only (stacked blocks are not
    neighbours in time); the order (at most ``max_order``) is the one of least AIC along the
    Levinson-Durbin recursion. ``A(q) e`` is then close to white: what ``e``'s own past predicts is gone.
    """
    e = e - e.mean()
    n = e.size
    p_max = int(max(0, min(max_order, n // 10)))
    if p_max == 0 or n == 0:
        return np.ones(1)
    r = np.zeros(p_max + 1)
    cuts = np.flatnonzero(np.diff(labels)) + 1
    for seg in np.split(e, cuts):
        m = seg.size
        for k in range(min(p_max + 1, m)):
            r[k] += float(np.dot(seg[:m - k], seg[k:]))
    r /= n
    if r[0] <= 0:
        return np.ones(1)
    a, v = np.ones(1), r[0]
    best_a, best_aic = a.copy(), n * math.log(v)
    for k in range(1, p_max + 1):
        refl = -(r[k] + float(np.dot(a[1:], r[k - 1:0:-1]))) / v
        a = np.concatenate([a, [0.0]])
        a = a + refl * a[::-1]
        v *= 1.0 - refl * refl
        if v <= 0:
            break
        aic = n * math.log(v) + 2 * k
        if aic < best_aic:
            best_a, best_aic = a.copy(), aic
    return best_a


def whitened_scores(e_old: np.ndarray, e_new: np.ndarray, labels: np.ndarray, a: np.ndarray) -> tuple[float, float]:
    """Block score and white-noise z of ``e_old -> e_new`` after both pass the whitening filter ``a``.

    Each held-out block is filtered on its own and loses its first ``len(a) - 1`` samples (the
    filter's start-up). Under the null the whitened residual's sample at ``t`` is the noise's
    innovation, which no function of earlier inputs predicts: a fit that predicts coloured noise
    through a feedback loop (the applied voltage carries the controller's reaction to past noise)
    earns nothing here, where the plain scores credit it.
    """
    p = a.size - 1
    cuts = np.flatnonzero(np.diff(labels)) + 1
    wo, wn, lab = [], [], []
    for i, (so, sn) in enumerate(zip(np.split(e_old, cuts), np.split(e_new, cuts))):
        if so.size <= p + 1:
            continue
        wo.append(lfilter(a, [1.0], so)[p:])
        wn.append(lfilter(a, [1.0], sn)[p:])
        lab.append(np.full(so.size - p, i))
    if not wo:
        return 0.0, 0.0
    w_old, w_new, lab_w = np.concatenate(wo), np.concatenate(wn), np.unique(np.concatenate(lab), return_inverse=True)[1]
    t = block_test(w_old, w_new, lab_w, 0)
    return t, white_z(w_old, w_new, max(float(np.mean(w_new ** 2)), 1e-300))
