"""Noise on the recorded input (errors in variables) and its share of the nominal residual.

A recorded voltage ``u = s + n`` carries the measurement noise ``n`` of its monitor; the actuator
was driven by ``s``. The nominal simulation of ``u`` then holds ``P n``, which the stroke never
had, so the nominal residual holds ``-P n``: noise, but coloured by the model and invisible to
an output-side noise estimate (third differences or the spectrum above the band see only the
part of ``P n`` that reaches high frequencies). A function of the recorded voltage can remove
part of it (a static map flattened on the levels of a PRBS removes most), which passes a
held-out test as well as physics does: the false alarms of ``free_indep.py``'s ``vnoise`` form
(PRBS at 200 Hz with 19 and 37 V rms named a static map, sessions 34-35).

The check has two independent views of the same noise:

- the input's own: the k-th differences of ``u`` (k = 1-4, the order whose robust scale is
  least: it cancels the most signal), with the switches of a stepped input left out, give
  ``sigma_u`` (kV) if the rest is white noise;
- the output's: measurement noise on ``u`` puts ``-P n`` in the residual, so the residual's
  cross-correlation with the input's k-th difference ``w`` is ``-sigma^2 q(j)`` at lag ``j``,
  ``q`` the model's impulse response convolved with the difference's coefficients. A fitted
  amplitude ``a`` with ``a / sigma_u^2 = share`` near 1 says the input's noise is measurement
  noise; near 0 that it was really applied (a controller's dither, or the signal itself), for
  then the stroke holds ``P n`` too and the residual does not.

Only when both agree (``share`` significantly above zero, at most ``SHARE_MAX``, and the noise it
implies in the residual no more than the residual itself) is the noise counted: the floor's
variance grows by the part of ``P n`` the output-side estimator did not already see.
"""
from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from hasel.metrics import robust_sd

__all__ = ["InputNoise", "input_noise", "SHARE_T_MIN", "SHARE_MIN", "SHARE_MAX"]

#: t statistic the cross-correlation amplitude needs (above zero) [seen free_indep 127-146: the 40
#: ``vnoise`` logs 2.0-24 where open-loop; effect-free logs of the other forms and the effect logs of forms3 11-12 and
#: multi2 35-36 below 3 except three PRBS at 100-200 Hz whose noise estimate is the PRBS itself, refused by
#: consistency]
SHARE_T_MIN = 3.0
#: share of the input's difference noise the residual must show (measurement noise gives 1) [same data: 0.5-2.6
#: on the open-loop ``vnoise`` logs with t >= 3; closed-loop logs negative]
SHARE_MIN = 0.5
#: above this the two views disagree too much to count anything
SHARE_MAX = 3.0
#: the noise implied in the residual may exceed the residual's variance by this factor (estimation scatter)
RESIDUAL_SLACK = 1.2


@dataclass(frozen=True)
class InputNoise:
    """The input-noise check's result.

    Attributes
    ----------
    sigma_u : float
        Noise of the recorded input from its ``order``-th differences (input unit rms, kV).
    order : int
        Difference order used (1-4).
    share, t : float
        Cross-correlation amplitude over ``sigma_u**2`` (1 = all measurement noise) and its t statistic.
    residual_var : float
        Variance of the propagated noise ``share * sigma_u**2 * sum(h**2)`` (output unit squared), ``share``
        capped at 1.
    floor_add : float
        What it adds to the noise floor's variance (output unit squared): ``residual_var`` less the part the
        floor's own estimator already sees; 0 when not ``counted``.
    counted : bool
        Whether both views agree (see the module's docstring).
    reason : str
        Why it was or was not counted, in words.
    """

    sigma_u: float
    order: int
    share: float
    t: float
    residual_var: float
    floor_add: float
    counted: bool
    reason: str

    def as_dict(self) -> dict:
        """JSON-ready fields (``sigma_u`` in input units, variances in output units squared)."""
        return {"sigma_u": self.sigma_u, "order": self.order, "share": self.share, "t": self.t,
                "residual_var": self.residual_var, "floor_add": self.floor_add, "counted": self.counted,
                "reason": self.reason}


def _switches(u: np.ndarray) -> np.ndarray:
    """First differences that are steps of the signal, not noise (bool, ``u.size - 1``)."""
    d1 = np.diff(u)
    c = float(np.median(d1))
    s1 = robust_sd(d1)
    jump = np.abs(d1 - c) > 6.0 * s1
    # many switches bias the robust scale up: once more on what is left
    if jump.any() and (~jump).sum() > 10:
        jump = np.abs(d1 - c) > 5.0 * robust_sd(d1[~jump])
    return jump


def _difference_noise(u: np.ndarray) -> tuple[int, float, np.ndarray, np.ndarray]:
    """Order ``k``, noise rms (input unit), the k-th difference ``w`` with switches zeroed, and its mask of
    samples kept."""
    scales = [robust_sd(np.diff(u, k)) / math.sqrt(math.comb(2 * k, k)) for k in (1, 2, 3, 4)]
    k = int(np.argmin(scales)) + 1
    d = np.diff(u, k)
    c = math.sqrt(math.comb(2 * k, k))
    # np.diff's sample t spans u[t..t+k]: a step between u[j] and u[j+1] spoils t in [j-k+1, j]
    bad = np.convolve(_switches(u).astype(float), np.ones(k))[k - 1:k - 1 + d.size] > 0
    bad |= np.abs(d - np.median(d)) > 6.0 * scales[k - 1] * c
    keep = ~bad
    sigma = float(np.std(d[keep]) / c) if keep.sum() > 100 else scales[k - 1]
    return k, sigma, np.where(keep, d, 0.0), keep


def input_noise(u: np.ndarray, r0: np.ndarray, impulse: np.ndarray,
                floor_view: Callable[[float], float]) -> InputNoise:
    """Measurement noise on the recorded input ``u`` (working rate) and its share of the residual ``r0``.

    Parameters
    ----------
    u : ndarray
        Recorded input at the working rate (kV).
    r0 : ndarray
        Nominal residual, same samples (output unit).
    impulse : ndarray
        The nominal model's response at the working samples to a unit input sample (output unit per input unit),
        starting at rest; its length bounds the lags looked at.
    floor_view : callable
        ``floor_view(sigma_u)``: the variance the floor's own estimator assigns to ``P n`` for white ``n`` of rms
        ``sigma_u`` (so that only the rest is added).

    Returns
    -------
    InputNoise
    """
    u, r0, h = np.asarray(u, float), np.asarray(r0, float), np.asarray(impulse, float)
    if u.size < 200 or r0.size != u.size or not np.all(np.isfinite(u)) or not np.all(np.isfinite(r0)):
        return InputNoise(0.0, 0, 0.0, 0.0, 0.0, 0.0, False, "too few samples for the check")
    k, sigma, w, keep = _difference_noise(u)
    hh = float(h @ h)
    if sigma <= 0.0 or hh <= 0.0:
        return InputNoise(sigma, k, 0.0, 0.0, 0.0, 0.0, False, "no noise on the recorded input")
    energy = np.cumsum(h ** 2)
    n_lag = min(int(np.searchsorted(energy, 0.999 * energy[-1])) + k + 1, h.size, u.size // 4)
    coef = np.array([(-1.0) ** (k - i) * math.comb(k, i) for i in range(k + 1)])
    # q(j) = sum_i coef_i h(j - i): what -P n looks like against n's k-th difference at lag j, per unit variance
    hp = np.concatenate([np.zeros(k), h[:n_lag]])
    q = np.array([float(coef @ hp[j + k - np.arange(k + 1)]) for j in range(n_lag)])
    cc = np.empty(n_lag)
    kept = keep.astype(float)
    for j in range(n_lag):
        # r0[t] against w[t - j], t = j .. j + w.size - 1
        stop = min(u.size, j + w.size)
        cc[j] = float(r0[j:stop] @ w[:stop - j]) / max(float(kept[:stop - j].sum()), 1.0)
    qq = float(q @ q)
    a = -float(cc @ q) / qq
    res = cc + a * q
    se = math.sqrt(float(res @ res) / max(n_lag - 1, 1) / qq)
    t = a / se if se > 0 else 0.0
    share = a / sigma ** 2
    resid = min(max(share, 0.0), 1.0) * sigma ** 2 * hh
    r_var = float(np.var(r0))
    if t < SHARE_T_MIN:
        why = f"the residual does not follow the recorded input's noise (t {t:.2g} < {SHARE_T_MIN:g})"
    elif not SHARE_MIN <= share <= SHARE_MAX:
        why = (f"the residual shows {share:.2g} of the input's difference noise (measurement noise gives 1; "
               f"counted in {SHARE_MIN:g}-{SHARE_MAX:g})")
    elif resid > RESIDUAL_SLACK * r_var:
        why = (f"the noise it implies ({math.sqrt(resid):.3g} rms) exceeds the residual ({math.sqrt(r_var):.3g} "
               f"rms): the input's differences are signal, not noise")
    else:
        add = max(resid - min(max(share, 0.0), 1.0) * floor_view(sigma), 0.0)
        return InputNoise(sigma, k, share, t, resid, add, True,
                          f"measurement noise on the recorded input: {share:.2g} of its difference noise is in "
                          f"the residual (t {t:.3g})")
    return InputNoise(sigma, k, share, t, resid, 0.0, False, why)
