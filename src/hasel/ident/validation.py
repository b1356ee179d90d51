"""Time-domain validation: simulate a fitted model on data and score it like MATLAB ``compare``.

``NRMSE = ||y - y_hat|| / ||y - mean(y)||`` and ``fit = 100 (1 - NRMSE) %``, on held-out
data. The model is simulated by exact zero-order-hold discretisation
(:func:`hasel.lti.zoh_sos`). A ZOH of sampled inputs lags the continuous response by
half a sample, and block-averaged (decimated) data sit half a block after the block's
start; averaging consecutive simulated samples compensates both, so the simulation
lines up with the data at any rate.
"""
from __future__ import annotations

import numpy as np
from scipy import signal

from hasel.ident.tffit import TFModel
from hasel.lti import zoh_sos
from hasel.metrics import nrmse
from hasel.validate import positive

__all__ = ["nrmse", "compare_fit", "simulate"]


def compare_fit(y: np.ndarray, y_hat: np.ndarray) -> float:
    """MATLAB ``compare`` fit, ``100 (1 - NRMSE)`` percent (100 is perfect; it can be negative)."""
    return 100.0 * (1.0 - nrmse(y, y_hat))


def simulate(model: TFModel, u: np.ndarray, rate_hz: float, *, aligned: bool = True) -> np.ndarray:
    """Response of ``model`` to ``u`` from rest (zero state), sampled at ``rate_hz``.

    Parameters
    ----------
    model : TFModel
        Continuous model (s in rad/s); its delay is rounded to whole samples.
    u : ndarray, shape (n,)
        Input deviations from the operating point (the model starts at rest, so
        ``u`` should start near 0).
    rate_hz : float
        Sample rate, Hz.
    aligned : bool
        Average consecutive samples of the ZOH simulation (see the module's notes),
        which lines the result up with sampled or block-averaged data.

    Returns
    -------
    ndarray, shape (n,)
    """
    rate_hz = positive("rate_hz", rate_hz)
    x = np.asarray(u, float)
    sos = zoh_sos(model.num, model.den, 1.0 / rate_hz)
    lag = int(round(model.delay_s * rate_hz))
    if lag > 0:
        x = np.concatenate([np.zeros(min(lag, x.size)), x[: max(x.size - lag, 0)]])
    if not aligned:
        return signal.sosfilt(sos, x)
    y = signal.sosfilt(sos, np.concatenate([x, x[-1:]]))
    return 0.5 * (y[:-1] + y[1:])
