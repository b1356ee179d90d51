"""Is an identified model usable? The checks a model must pass before anyone relies on it.

:func:`check_model` is what ``hasel identify`` runs on its own result (exit 1 and
``"usable": false`` when it fails); :func:`check_model_json` runs the same checks on
a MODEL.json (for ``diagnose`` and other consumers of a nominal model).

A model is usable when all of these hold:

1. every pole is in the open left half-plane, and none is near-marginal (damping
   ratio below ``MARGINAL_DAMPING``);
2. no lightly damped pole or zero (damping below ``LIGHT_DAMPING``) and no
   right-half-plane zero lies outside the band the data excite (from half the
   band's low edge to twice its top): the data cannot support it;
3. the static gain ``G(0)`` agrees with the slope of the measured static map (mean
   output against mean input) within ``max(3 standard errors, DC_REL_TOL)``;
4. the held-out time-domain compare fit is at least the stated threshold (default
   80 %) once the part of the error that the measurement noise explains is taken
   out: ``100 (1 - sqrt(max(NRMSE^2 - floor^2, 0)))`` with ``floor`` the noise's rms
   over the held-out output's (a noisy log cannot score higher than its noise allows,
   so a fixed threshold would refuse right models of noisy logs);
5. inside the excited band the model agrees with the measured non-parametric
   frequency response: a point disagrees when ``|G - H|`` exceeds both
   ``INBAND_Z`` of its standard errors and ``INBAND_REL_TOL`` (0.8 dB / 5.7 deg) of
   the larger of ``|H|`` and a tenth of the static gain (deep in the roll-off, 20 dB
   down, an error moves the output little);
   more than ``INBAND_MAX_SHARE`` of the points, or a run of them spanning more than
   an octave, make the model unusable (a good time-domain score can hide a
   model that is wrong over part of the band). Only points whose estimate has a
   coherence of at least ``INBAND_MIN_COHERENCE`` are judged. :func:`~hasel.ident.identify`
   runs it on leakage-free estimates only (whole periods of a periodic input), whose
   error bars hold;
6. the data pin the response: over the excited band, where ``|G|`` is within 20 dB of
   the static gain, the output-error fit's cluster-robust standard errors of ``|G|``
   (dB) and of its phase (deg), times ``SPREAD_Z``, stay within ``tol_db`` /
   ``tol_deg``. When the fit kept a timing offset between the channels, it is one of
   the parameters of that covariance (its bound, 1.5 samples by default, as a
   uniform prior): a phase the data cannot tell from a sampling convention's lead is
   not pinned; when the held-out data chose none, the covariance is conditional on
   that choice (with the offset always free, right tuning and campaign models read
   +-5-6 deg at 11-13 Hz). The standard errors are the
   delta method's through exact derivatives of ``log G``
   (:func:`~hasel.ident.timefit.response_uncertainty`). Calibrated on repeated noise
   draws of the tuning logs (``bench/tune_ident/coverage.py``, coverage.txt): with
   the earlier finite-difference derivatives the bound of over-parameterised orders
   (4/5-7/8, whose fastest pole scales the numerator's coefficients to 1e-17) was
   50-180 times the spread of the estimates across draws (+-6 dB / +-90 deg claimed
   on models 0.2 dB / 3 deg off); with exact ones the magnitude's standard error is
   0.6-1.0 times that spread. The bound covers the noise's share only: the error
   against the true response is mostly the order's and the sampling convention's
   bias, which no covariance holds (coverage.txt gives both);
7. no rival: the other model orders whose held-out error ties with the chosen one's
   (the order selection could not tell them apart) agree with it down to
   ``SPREAD_FLOOR`` of the static gain within ``RIVAL_FACTOR`` times
   ``tol_db`` / ``tol_deg`` wherever their difference exceeds the two models'
   combined 95 % uncertainty (``SPREAD_Z`` times the root sum of squares of both
   standard errors): a difference inside it is the noise of two estimates, not
   evidence that the data cannot single out the response. Each model is taken with
   its own timing offset (what it says the data do): the rivals are fitted before
   the offset is chosen, so a rival carries a sampling convention's lead in its
   phase (13-16 deg at 14 Hz for half a sample at 200 Hz), which refused right
   200 Hz PRBS and log-chirp tuning models before. ``RIVAL_FACTOR`` (2) and
   ``SPREAD_Z`` (2, a normal 95 %) were not re-tuned. A model the data cannot single
   out is not reported as right. On the drawn-conditions tuning logs
   (``varied.py`` seeds 1-2, 81 logs, varied_ical.txt) checks 6-7 as they stand
   refuse 3 right models (11 with the faulty bound) and pass 14 wrong ones (9): those
   are 5-55 deg off near the band's top by bias (order, a sampling lead), which
   neither check measures: check 8 does;
8. no bias against the data: the model's error as a frequency response, ``E(f) =
   H1(u, y - y_hat) + (H_sim - G)``, with ``y_hat`` the model's simulation of the whole log,
   ``H1`` Welch's estimate per operating point (pooled) and ``H_sim`` the simulation's exact,
   leakage-free sampled response (:func:`hasel.ident.identify._residual_response`). H1 is
   linear in the output, so the leakage and transients a non-periodic input's Welch estimate
   carries cancel between data and simulation: it runs on every log, periodic or not, and
   the H1 error bar of the residual holds. A point disagrees when ``|E|`` exceeds both
   ``RESID_Z`` standard errors and ``RESID_REL_TOL`` of the larger of ``|G|`` and a tenth of
   the static gain; more than ``RESID_MAX_SHARE`` of the points or a run over
   ``RESID_MAX_RUN_OCTAVES`` refuse the model. Only points with input-output coherence
   ``INBAND_MIN_COHERENCE`` or more and below an eighth of the analysis rate are judged
   (nearer Nyquist any continuous model's sampled response, the true one's too, departs from
   ``G``). The thresholds are check 5's (4 standard errors, 10 %, 20 %, one octave),
   checked on the drawn-conditions tuning logs (``varied.py`` seeds 1-2 at 200 Hz / 1 kHz,
   seed 1 at 10 kHz, 81 logs, varied_ical.txt): with them check 8 refuses no right model
   (good 58, right yet refused 3, as without it) and two wrong ones (seed 2's 200 Hz 5/6
   paper_chirp3 model, 1.9 dB / 55 deg off, whose poles at 179 and 475 Hz alias: its sampled
   simulation fits the data, ``G`` is 1.8 dB off it at 12 Hz; seed 1's 10 kHz PRBS 4/5,
   6.4 deg off): wrong yet usable 14 -> 12. Swept there: 3 or 6 standard errors change
   nothing; 15 % passes one more wrong model; 7 % refuses one more wrong model (11) and no
   right one, 5 % one more wrong and 3 right ones, 3 % 7 right ones: 10 % (under the 1 dB /
   5 deg tolerance's 12 % / 8.7 %, kept from check 5) was not tuned down to gain one log. The 12 left (5-20 deg near the
   band's top) agree with the data within their error bars: a sampling convention's lead
   taken into ``G``'s phase instead of the timing offset, which no comparison with these
   data can tell apart: check 9 refuses those it can show;
9. the timing offset is told from ``G``'s phase: when the held-out data did not decide
   between the chosen order without a timing offset and the same order refitted with
   one (:func:`hasel.ident.identify._timing_or_not`: neither criterion better nor worse,
   the offset inside its bound), the two fits say the same of the data but not of the
   plant. Their ``G`` (without the offsets) must agree within ``TIMING_FACTOR`` times
   ``tol_db`` / ``tol_deg`` wherever they differ beyond their combined 95 % uncertainty
   (the offset one of the parameters of the refitted one's covariance). A model whose
   phase near the band's top may be a sampling convention's lead is refused with the
   experiments that separate the two: a higher sample rate, an input of known latency,
   or the convention given. The same for a lower order kept with a tied timing offset
   that is no sampling convention (:func:`hasel.ident.identify._lower_order_with_offset`),
   judged against the higher order refitted with the offset free when that keeps the
   offset (the two agree on the timing and differ in the dynamics).

In 6, 7 and 9, as in 5, the tolerances are relative to the larger of ``|G|`` and a tenth
of the static gain: where the response is more than 20 dB down they widen by
``0.1 |G(0)| / |G|`` (an error there moves the output little).

Each failure comes with the experiment that would fix it.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np

__all__ = ["ModelCheck", "check_model", "check_model_json", "inband_errors", "MARGINAL_DAMPING", "LIGHT_DAMPING", "DC_REL_TOL",
           "MIN_COMPARE_FIT_PCT"]

#: Damping ratio below which a pole counts as near-marginal (unusable anywhere).
MARGINAL_DAMPING = 0.005
#: Damping ratio below which a pole or zero outside the excited band is unsupported.
LIGHT_DAMPING = 0.05
#: Without a static map, the excited band must start below this fraction of the slowest pole's
#: frequency for G(0) to count as measured (|G| is within 2 % of G(0) there for a real pole).
STATIC_BAND_FRACTION = 0.2
#: Smallest relative tolerance of G(0) against the static map's slope (3 %, 0.26 dB).
DC_REL_TOL = 0.03
#: Default threshold of the held-out compare fit, percent.
MIN_COMPARE_FIT_PCT = 80.0
#: In-band agreement: standard errors, relative tolerance, share of points, longest run (octaves).
INBAND_Z = 4.0
INBAND_REL_TOL = 0.1
INBAND_MAX_SHARE = 0.2
INBAND_MAX_RUN_OCTAVES = 1.0
INBAND_MIN_COHERENCE = 0.5
#: Residual bias (check 8): standard errors, relative tolerance, share of points, longest run (octaves).
RESID_Z = 4.0
RESID_REL_TOL = 0.1
RESID_MAX_SHARE = 0.2
RESID_MAX_RUN_OCTAVES = 1.0
#: Response spread (checks 6, 7): coverage factor of the standard errors (95 %), and the share of the static
#: gain below which the response is no longer judged (-20 dB, the roll-off; as check 5's floor).
SPREAD_Z = 2.0
SPREAD_FLOOR = 0.1
#: How check 6's reason begins (the data do not pin the model's response); identify's fallback to a lower
#: order looks for it.
UNPINNED_REASON = "the data pin the response only to"
#: Check 7 refuses when a tied rival differs by more than this many tolerances (a difference of one tolerance
#: between two models that fit alike bounds neither's error by it; twice it, one of them is off by more).
RIVAL_FACTOR = 2.0
#: Check 9 refuses when the same order with the timing offset the held-out data could not refuse differs in G
#: by more than this many tolerances (beyond both fits' combined 95 % uncertainty).
TIMING_FACTOR = 1.0


@dataclass(frozen=True)
class ModelCheck:
    """Outcome of :func:`check_model`.

    Attributes
    ----------
    usable : bool
        True when every check passed.
    reasons : list of str
        One sentence per failed check (what failed, with the numbers).
    fixes : list of str
        For each reason, the experiment that would fix it.
    details : dict
        The numbers behind each check (JSON-ready).
    """

    usable: bool
    reasons: list[str] = field(default_factory=list)
    fixes: list[str] = field(default_factory=list)
    details: dict[str, Any] = field(default_factory=dict)

    def one_line(self) -> str:
        """One line for stderr: what failed first (and how many more) and which experiment would fix it."""
        if self.usable:
            return "model usable"
        more = f" (and {len(self.reasons) - 1} more check(s) failed)" if len(self.reasons) > 1 else ""
        return f"model not usable: {self.reasons[0]}{more}; to fix: {self.fixes[0]}"

    def to_json(self) -> dict[str, Any]:
        """JSON-ready dict: ``usable``, ``reasons``, ``fixes``, ``details``."""
        return {"usable": self.usable, "reasons": list(self.reasons), "fixes": list(self.fixes),
                "details": self.details}


def _damping(r: np.ndarray) -> np.ndarray:
    """Damping ratio ``-Re / |r|`` of each root (1 for a root at 0 to avoid a division by zero)."""
    a = np.abs(r)
    return np.where(a > 0, -np.real(r) / np.where(a > 0, a, 1.0), 1.0)


def check_model(model: Any, *, band_hz: tuple[float, float] | None, static_slope: float | None = None,
                static_ci: float | None = None, heldout_nrmse: float | None = None,
                min_compare_fit_pct: float = MIN_COMPARE_FIT_PCT, rhp_zeros_shown: bool = False,
                noise_floor: float | None = None, measured: Any = None,
                timing_offset_s: float = 0.0, response_spread: dict[str, Any] | None = None,
                tol_db: float = 1.0, tol_deg: float = 5.0, residual_response: Any = None) -> ModelCheck:
    """Run the checks of this module on a continuous transfer function.

    Parameters
    ----------
    model : TFModel or any object with ``num``, ``den`` (descending powers of s, rad/s)
        The model, input unit -> output unit.
    band_hz : (float, float) or None
        Band the data excite, Hz (None skips the band checks).
    static_slope : float, optional
        Slope of the measured static map at the operating point, output/input unit.
    static_ci : float, optional
        Its standard error (same unit); None when unknown (then only ``DC_REL_TOL`` applies).
    heldout_nrmse : float, optional
        NRMSE of the model's simulation on held-out data.
    min_compare_fit_pct : float
        Threshold of the held-out compare fit, percent.
    rhp_zeros_shown : bool
        The held-out data showed that the right-half-plane zeros are needed (their
        mirror image fits worse): they are not held against the model.
    noise_floor : float, optional
        The measurement noise's rms over the held-out output's (centred) rms: the
        NRMSE a perfect model would score. None: no credit for noise.
    measured : FreqResp, optional
        The non-parametric frequency response over the excited band (with ``sigma``)
        for the in-band agreement check.
    timing_offset_s : float
        Timing offset estimated with the model, s: the measured response follows
        ``G(s) exp(-s timing_offset_s)``.
    response_spread : dict, optional
        For checks 6 and 7: ``f_hz`` (Hz), ``sd_db`` and ``sd_deg`` (standard errors
        of the response there, dB and deg, or None), ``rivals`` (``(nz, np, model,
        heldout_nrmse[, (sd_db, sd_deg) or None[, timing_offset_s]])`` of the tied
        orders: their own standard errors at ``f_hz`` and their own timing offset, s,
        ``timing_offset_s`` when not given) and ``score`` (the chosen model's
        held-out NRMSE).
    tol_db, tol_deg : float
        Tolerances of checks 6 and 7, dB and deg.
    residual_response : FreqResp, optional
        For check 8: the frequency response of the model's time-domain residual on the
        input (output unit per input unit, ``sigma`` its standard error, ``coherence``
        the input-output coherence at each point), over the excited band.

    Returns
    -------
    ModelCheck
    """
    num = np.atleast_1d(np.asarray(model.num, float))
    den = np.atleast_1d(np.asarray(model.den, float))
    poles = np.roots(den) if den.size > 1 else np.zeros(0, complex)
    zeros = np.roots(num) if num.size > 1 else np.zeros(0, complex)
    reasons: list[str] = []
    fixes: list[str] = []
    details: dict[str, Any] = {}
    hz = lambda r: float(abs(r) / (2 * math.pi))  # noqa: E731 - a unit conversion
    lo, hi = (band_hz[0] / 2.0, band_hz[1] * 2.0) if band_hz is not None else (0.0, math.inf)
    band_txt = f"{band_hz[0]:.3g}-{band_hz[1]:.3g} Hz" if band_hz is not None else "?"

    unstable = poles[np.real(poles) >= 0]
    zp = _damping(poles)
    marginal = poles[(np.real(poles) < 0) & (zp < MARGINAL_DAMPING)]
    details["poles_hz_damping"] = [[hz(p), float(d)] for p, d in zip(poles, zp)]
    if unstable.size:
        reasons.append(f"{unstable.size} unstable pole(s), the first at {hz(unstable[0]):.3g} Hz")
        fixes.append(f"log longer or repeated excitation over {band_txt} (an unstable fit means the data did not "
                     "pin the dynamics)")
    if marginal.size:
        p = marginal[0]
        reasons.append(f"near-marginal pole at {hz(p):.3g} Hz with damping {float(_damping(np.array([p]))[0]):.2g}")
        fixes.append(f"excite around {hz(p):.3g} Hz (several periods of it) or drop that mode with --order")
    if band_hz is not None:
        for kind, roots in (("pole", poles), ("zero", zeros)):
            d = _damping(roots)
            f = np.abs(roots) / (2 * math.pi)
            out = (f < lo) | (f > hi)
            light = roots[out & (d < LIGHT_DAMPING) & (np.abs(np.imag(roots)) > 0)]
            if kind == "pole":
                light = light[np.real(light) < 0]
                light = light[_damping(light) >= MARGINAL_DAMPING]
            rhp = roots[out & (np.real(roots) > 0)] if kind == "zero" and not rhp_zeros_shown else np.zeros(0)
            for r in list(light[np.imag(light) >= 0]):
                reasons.append(f"lightly damped {kind} pair at {hz(r):.3g} Hz (damping "
                               f"{float(_damping(np.array([r]))[0]):.2g}) outside the excited band {band_txt}")
                fixes.append(f"excite from {min(band_hz[0], hz(r) / 2):.3g} Hz to {max(band_hz[1], 2 * hz(r)):.3g} Hz "
                             "or give a lower --order")
            for r in list(rhp[np.imag(rhp) >= 0]):
                reasons.append(f"right-half-plane zero at {hz(r):.3g} Hz outside the excited band {band_txt}")
                fixes.append(f"excite up to {max(band_hz[1], 2 * hz(r)):.3g} Hz to show whether the phase is "
                             "non-minimum")
    g0 = float(num[-1] / den[-1]) if den[-1] != 0 else math.inf
    details["static_gain"] = g0 if math.isfinite(g0) else None
    if static_slope is not None and math.isfinite(static_slope):
        tol = max(3.0 * (static_ci or 0.0), DC_REL_TOL * abs(static_slope))
        details.update(static_slope=float(static_slope), static_slope_se=static_ci, static_tolerance=float(tol))
        if not math.isfinite(g0) or abs(g0 - static_slope) > tol:
            reasons.append(f"static gain G(0) = {g0:.4g} disagrees with the measured static map slope "
                           f"{static_slope:.4g} (tolerance {tol:.2g})")
            fixes.append("hold the input at 3 or more levels (offsets or steps, each longer than the settling "
                         "time) and excite down to lower frequencies")
    elif band_hz is not None and poles.size:
        # nothing measured the static gain: the excited band must then reach well below the slowest pole,
        # where |G| is already G(0), or G(0) is an extrapolation the data never saw
        f_slow = min(hz(p) for p in poles)
        if band_hz[0] > STATIC_BAND_FRACTION * f_slow:
            reasons.append(f"nothing pins the static gain: no static map levels, and the excited band starts at "
                           f"{band_hz[0]:.3g} Hz, above {STATIC_BAND_FRACTION:g} x the slowest pole ({f_slow:.3g} Hz)")
            fixes.append(f"hold the input at 3 or more levels, or excite down to "
                         f"{STATIC_BAND_FRACTION * f_slow:.3g} Hz")
    if heldout_nrmse is not None:
        pct = 100.0 * (1.0 - heldout_nrmse) if math.isfinite(heldout_nrmse) else -math.inf
        floor = float(noise_floor) if noise_floor is not None and math.isfinite(noise_floor) else 0.0
        # the model's own share of the error: what is left once the noise's share is taken out (noise and
        # model error are uncorrelated, so their squares add); the noise is credited at most to 90 % of it
        floor = min(max(floor, 0.0), 0.9 * heldout_nrmse) if math.isfinite(heldout_nrmse) else 0.0
        model_nrmse = math.sqrt(max(heldout_nrmse ** 2 - floor ** 2, 0.0)) if math.isfinite(heldout_nrmse) \
            else math.inf
        pct_model = 100.0 * (1.0 - model_nrmse) if math.isfinite(model_nrmse) else -math.inf
        details.update(heldout_compare_fit_pct=pct if math.isfinite(pct) else None,
                       noise_floor_nrmse=floor, heldout_model_fit_pct=pct_model if math.isfinite(pct_model) else None,
                       min_compare_fit_pct=float(min_compare_fit_pct))
        if pct_model < min_compare_fit_pct:
            reasons.append(f"held-out compare fit {pct:.1f} % ({pct_model:.1f} % with the noise's share "
                           f"{100 * floor:.2g} % taken out) is below {min_compare_fit_pct:g} %")
            fixes.append(f"repeat the excitation (several periods or chirps per offset) over {band_txt} so the "
                         "held-out part holds the same frequencies, or lower the noise")
    if measured is not None and band_hz is not None:
        _inband(model, measured, band_hz, timing_offset_s, reasons, fixes, details)
    if response_spread is not None:
        _spread(model, response_spread, tol_db, tol_deg, reasons, fixes, details, timing_offset_s)
    if residual_response is not None and band_hz is not None:
        _residual_bias(model, residual_response, band_hz, reasons, fixes, details)
    return ModelCheck(usable=not reasons, reasons=reasons, fixes=fixes, details=details)


def inband_errors(model: Any, measured: Any, band_hz: tuple[float, float], timing_offset_s: float = 0.0
                  ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray] | None:
    """The model against a measured response at its judged points (check 5 of the module).

    Returns ``(f_hz, G/H, rel, z)``: frequencies, the ratio of model (with its delay and
    timing offset) to measurement, ``|G/H - 1|`` measured against the larger of ``|H|``
    and a tenth of the static gain (errors deep in the roll-off, 20 dB down, count
    less), and ``|G - H|`` in standard errors of one real or imaginary part. None with
    fewer than four judged points.
    """
    num = np.atleast_1d(np.asarray(model.num, float))
    den = np.atleast_1d(np.asarray(model.den, float))
    f = np.asarray(measured.f_hz, float)
    H = np.asarray(measured.H, complex)
    sig = np.asarray(measured.sigma, float)
    coh = np.asarray(getattr(measured, "coherence", np.full(f.size, np.nan)), float)
    use = (f >= band_hz[0]) & (f <= band_hz[1]) & np.isfinite(H) & np.isfinite(sig) & (np.abs(H) > 0)
    # only where the estimate's error is small and near-Gaussian: coherence >= 0.5 (or, without a
    # coherence, a relative standard error <= 0.3); elsewhere the output is mostly noise
    with np.errstate(divide="ignore", invalid="ignore"):
        use &= np.where(np.isfinite(coh), coh >= INBAND_MIN_COHERENCE, sig / np.abs(H) <= 0.3)
    if np.count_nonzero(use) < 4:
        return None
    f, H, sig = f[use], H[use], sig[use]
    s = 2j * math.pi * f
    delay = float(getattr(model, "delay_s", 0.0) or 0.0)
    G = np.polyval(num, s) / np.polyval(den, s) * np.exp(-s * (delay + timing_offset_s))
    g0 = abs(float(num[-1] / den[-1])) if den[-1] != 0 else 0.0
    rel = np.abs(G - H) / np.maximum(np.abs(H), 0.1 * g0)
    z = np.abs(G - H) / np.maximum(sig / math.sqrt(2.0), 1e-300)   # per real/imaginary part
    return f, G / H, rel, z


def _response(m: Any, f_hz: np.ndarray) -> np.ndarray:
    """``m``'s response ``num(j w) / den(j w)`` at ``f_hz`` (Hz), its units (no delay or timing offset)."""
    s = 2j * math.pi * np.asarray(f_hz, float)
    num, den = np.atleast_1d(np.asarray(m.num, float)), np.atleast_1d(np.asarray(m.den, float))
    return np.polyval(num, s) / np.polyval(den, s)


def _longest_run_octaves(f: np.ndarray, bad: np.ndarray) -> float:
    """The longest run of neighbouring flagged points, in octaves (``f`` ascending, Hz)."""
    run, start = 0.0, None
    for i in range(f.size):
        if bad[i]:
            start = f[i] if start is None else start
            run = max(run, math.log2(f[i] / start))
        else:
            start = None
    return run


def _residual_bias(model: Any, resid: Any, band_hz: tuple[float, float], reasons: list[str], fixes: list[str],
                   details: dict[str, Any]) -> None:
    """Check 8 of the module: the residual's response to the input, against its error bars (appends a reason)."""
    num = np.atleast_1d(np.asarray(model.num, float))
    den = np.atleast_1d(np.asarray(model.den, float))
    f = np.asarray(resid.f_hz, float)
    E = np.asarray(resid.H, complex)
    sig = np.asarray(resid.sigma, float)
    coh = np.asarray(resid.coherence, float)
    use = (f >= band_hz[0]) & (f <= band_hz[1]) & np.isfinite(E) & np.isfinite(sig) & (sig > 0)
    use &= np.where(np.isfinite(coh), coh >= INBAND_MIN_COHERENCE, False)
    if np.count_nonzero(use) < 4:
        return
    f, E, sig = f[use], E[use], sig[use]
    G = _response(model, f)
    g0 = abs(float(num[-1] / den[-1])) if den[-1] != 0 else 0.0
    rel = np.abs(E) / np.maximum(np.abs(G), SPREAD_FLOOR * g0)
    z = np.abs(E) / np.maximum(sig / math.sqrt(2.0), 1e-300)
    bad = (z > RESID_Z) & (rel > RESID_REL_TOL)
    share = float(np.mean(bad))
    run = _longest_run_octaves(f, bad)
    details.update(residual_disagreeing_share=share, residual_longest_run_octaves=run,
                   residual_max_rel=float(np.max(rel)), residual_max_z=float(np.max(z)))
    if share > RESID_MAX_SHARE or run > RESID_MAX_RUN_OCTAVES:
        i = int(np.argmax(np.where(bad, rel, -1.0)))
        reasons.append(f"the model disagrees with the data at {100 * share:.0f} % of the excited band's points (a "
                       f"run of {run:.2g} octaves; the worst at {f[i]:.3g} Hz: an error of {100 * rel[i]:.2g} % of "
                       f"the response, {z[i]:.2g} standard errors of the residual's response to the input): the "
                       f"model is biased there")
        fixes.append("give --order (more poles), or check the sampling convention and timing between the channels; "
                     "a longer excitation over that band narrows the error bars")


def _inband(model: Any, measured: Any, band_hz: tuple[float, float],
            timing_offset_s: float, reasons: list[str], fixes: list[str], details: dict[str, Any]) -> None:
    """Check 5 of the module: the model against the measured response inside the band (appends a reason)."""
    got = inband_errors(model, measured, band_hz, timing_offset_s)
    if got is None:
        return
    f, ratio, rel, z = got
    bad = (z > INBAND_Z) & (rel > INBAND_REL_TOL)
    # the longest run of disagreeing neighbours, in octaves
    run = _longest_run_octaves(f, bad)
    share = float(np.mean(bad))
    err_db = 20 * np.log10(np.abs(ratio))
    err_deg = np.degrees(np.angle(ratio))
    details.update(inband_disagreeing_share=share, inband_longest_run_octaves=run,
                   inband_max_db=float(np.max(np.abs(err_db))), inband_max_deg=float(np.max(np.abs(err_deg))))
    if share > INBAND_MAX_SHARE or run > INBAND_MAX_RUN_OCTAVES:
        i = int(np.argmax(np.where(bad, rel, -1.0)))
        reasons.append(f"the model disagrees with the measured frequency response at {100 * share:.0f} % of the "
                       f"excited band's points (a run of {run:.2g} octaves; the worst at {f[i]:.3g} Hz: "
                       f"{err_db[i]:+.2g} dB, {err_deg[i]:+.2g} deg, {z[i]:.2g} standard errors)")
        fixes.append("give --order (more poles) or a longer, repeated excitation over that band; if the "
                     "response depends on the operating point, identify each operating point on its own")


def _spread(model: Any, spread: dict[str, Any], tol_db: float, tol_deg: float, reasons: list[str],
            fixes: list[str], details: dict[str, Any], timing_offset_s: float = 0.0) -> None:
    """Checks 6 and 7 of the module: the response's standard errors and the tied rival orders (appends reasons)."""
    f = np.asarray(spread["f_hz"], float)
    if f.size == 0:
        return
    span = f"{f[0]:.3g}-{f[-1]:.3g} Hz"

    G = _response(model, f)
    g0 = abs(float(np.asarray(model.num, float)[-1] / np.asarray(model.den, float)[-1]))
    widen = np.maximum(1.0, INBAND_REL_TOL * g0 / np.maximum(np.abs(G), 1e-300)) if math.isfinite(g0) \
        else np.ones(f.size)
    sd_db, sd_deg = spread.get("sd_db"), spread.get("sd_deg")
    if sd_db is not None and sd_deg is not None:
        # the covariance is judged where the response is within 20 dB of the static gain: nearer a notch or
        # deeper in the roll-off, the linearised phase error of a steep response (a lightly damped zero pair)
        # says more about the parameterisation than about what the data pin
        inside = np.abs(G) >= INBAND_REL_TOL * g0 if math.isfinite(g0) else np.ones(f.size, bool)
        u_db = np.where(inside, SPREAD_Z * np.asarray(sd_db), 0.0)
        u_deg = np.where(inside, SPREAD_Z * np.asarray(sd_deg), 0.0)
        details.update(response_u95_max_db=float(np.max(u_db)), response_u95_max_deg=float(np.max(u_deg)),
                       response_checked_hz=[float(f[0]), float(f[-1])], response_f_hz=[float(v) for v in f],
                       response_u95_db=[float(v) for v in u_db], response_u95_deg=[float(v) for v in u_deg])
        worse = np.maximum(u_db / tol_db, u_deg / tol_deg) / widen
        if np.max(worse) > 1.0:
            i = int(np.argmax(worse))
            reasons.append(f"{UNPINNED_REASON} +-{u_db[i]:.2g} dB / +-{u_deg[i]:.2g} deg at "
                           f"{f[i]:.3g} Hz (95 %, the output-error fit's covariance over {span}; tolerance "
                           f"{tol_db * widen[i]:.2g} dB / {tol_deg * widen[i]:.2g} deg there)")
            fixes.append(f"excite more around {f[i]:.3g} Hz: a chirp or multisine from {f[i] / 2:.3g} to "
                         f"{2 * f[i]:.3g} Hz repeated in whole periods, a longer log, or less noise; if the timing "
                         "between the input and output samples is unknown, log at a higher rate")
    worst = None
    c_db = np.asarray(sd_db, float) if sd_db is not None else np.zeros(f.size)
    c_deg = np.asarray(sd_deg, float) if sd_deg is not None else np.zeros(f.size)
    for rival in spread.get("rivals", []):
        nz, n_p, m, score = rival[:4]
        sd_r = rival[4] if len(rival) > 4 else None
        # what each model says the data do: with its own timing offset (a rival fitted without one carries
        # the sampling convention's lead in its phase, 13 deg at 14 Hz for half a sample at 200 Hz)
        tau_r = float(rival[5]) if len(rival) > 5 else timing_offset_s
        with np.errstate(all="ignore"):
            q = _response(m, f) / G * np.exp(-2j * math.pi * f * (tau_r - timing_offset_s))
        if not np.all(np.isfinite(q)):
            continue
        # the difference of two estimates from the same data is noise while it is within their combined
        # 95 % uncertainty (each model's own standard error; a rival without one counts as exact): only a
        # difference beyond it says the tied orders disagree about the response
        w, d_db, d_deg, u_db, u_deg = _beyond(q, c_db, c_deg, sd_r, tol_db, tol_deg, widen)
        i = int(np.argmax(w))
        if worst is None or w[i] > worst[0]:
            worst = (float(w[i]), nz, n_p, float(d_db[i]), float(d_deg[i]), float(f[i]), score,
                     tol_db * float(widen[i]), tol_deg * float(widen[i]), float(u_db[i]), float(u_deg[i]))
    if worst is not None:
        details.update(rival_max_db=worst[3], rival_max_deg=worst[4], rival_order=[worst[1], worst[2]],
                       rival_u95_db=worst[9], rival_u95_deg=worst[10])
        if worst[0] > RIVAL_FACTOR:
            reasons.append(f"a model of order {worst[1]}/{worst[2]} fits the held-out data as well (NRMSE "
                           f"{worst[6]:.3g} against {spread.get('score', float('nan')):.3g}) yet differs by "
                           f"{worst[3]:.2g} dB / {worst[4]:.2g} deg at {worst[5]:.3g} Hz (beyond their combined 95 % "
                           f"uncertainty +-{worst[9]:.2g} dB / +-{worst[10]:.2g} deg and {RIVAL_FACTOR:g} x the "
                           f"tolerance {worst[7]:.2g} dB / {worst[8]:.2g} deg there): the data do not single out the "
                           "response there")
            fixes.append(f"excite more around {worst[5]:.3g} Hz (a chirp or multisine through it, repeated in whole "
                         "periods per operating point), or fix the order with --order if it is known")
    _timing_rival(G, f, widen, c_db, c_deg, spread, tol_db, tol_deg, timing_offset_s, reasons, fixes, details)


def _beyond(q: np.ndarray, c_db: np.ndarray, c_deg: np.ndarray, sd_r: Any, tol_db: float, tol_deg: float,
            widen: np.ndarray) -> tuple[np.ndarray, ...]:
    """How far two models differ beyond their combined 95 % uncertainty, in (widened) tolerances.

    ``q``: the ratio of their responses; ``c_db`` / ``c_deg``: the first's standard errors (dB, deg);
    ``sd_r``: the second's ``(sd_db, sd_deg)`` or None (exact). Returns ``(w, d_db, d_deg, u_db, u_deg)``:
    per frequency the difference over the tolerance where it exceeds the uncertainty (else 0), the
    differences (dB, deg) and the combined 95 % uncertainties (dB, deg).
    """
    d_db, d_deg = np.abs(20 * np.log10(np.abs(q))), np.abs(np.degrees(np.angle(q)))
    r_db = np.asarray(sd_r[0], float) if sd_r is not None else np.zeros(q.size)
    r_deg = np.asarray(sd_r[1], float) if sd_r is not None else np.zeros(q.size)
    u_db = SPREAD_Z * np.sqrt(c_db ** 2 + r_db ** 2)
    u_deg = SPREAD_Z * np.sqrt(c_deg ** 2 + r_deg ** 2)
    w = np.maximum(np.where(d_db > u_db, d_db / tol_db, 0.0), np.where(d_deg > u_deg, d_deg / tol_deg, 0.0)) / widen
    return w, d_db, d_deg, u_db, u_deg


def _timing_rival(G: np.ndarray, f: np.ndarray, widen: np.ndarray, c_db: np.ndarray, c_deg: np.ndarray,
                  spread: dict[str, Any], tol_db: float, tol_deg: float, timing_offset_s: float,
                  reasons: list[str], fixes: list[str], details: dict[str, Any]) -> None:
    """Check 9 of the module: the timing offset the held-out data could not refuse, against ``G`` (appends a reason).

    ``G`` is the chosen model's response at ``f`` (Hz); ``c_db`` / ``c_deg`` its standard errors (dB, deg).
    ``spread["timing_rival"]``: one rival ``(model, offset s, (sd_db, sd_deg) or None, held-out NRMSE[, label[, how it fits]])``
    or a list of them (the worst is judged); the label names the rival's order (default "the same order").
    """
    tr = spread.get("timing_rival")
    if tr is None:
        return
    worst = None
    for t in (tr if isinstance(tr, list) else [tr]):
        m, tau_r, sd_r = t[0], float(t[1]), t[2]
        with np.errstate(all="ignore"):
            q = _response(m, f) / G
        if not np.all(np.isfinite(q)):
            continue
        # G against G: the two fits say the same of the data (their offsets differ by tau_r - timing_offset_s);
        # they differ in what they call the plant
        w, d_db, d_deg, u_db, u_deg = _beyond(q, c_db, c_deg, sd_r, tol_db, tol_deg, widen)
        i = int(np.argmax(w))
        if worst is None or w[i] > worst[0]:
            label = t[4] if len(t) > 4 and t[4] else "the same order (a sampling convention)"
            how = t[5] if len(t) > 5 and t[5] else "fits the held-out data as well"
            worst = (float(w[i]), i, tau_r, label, d_db, d_deg, u_db, u_deg, how)
    if worst is None:
        return
    wi, i, tau_r, label, d_db, d_deg, u_db, u_deg, how = worst
    details.update(timing_rival_offset_s=tau_r, timing_rival_max_db=float(np.max(d_db)),
                   timing_rival_max_deg=float(np.max(d_deg)), timing_rival_ratio=wi)
    if wi > TIMING_FACTOR:
        reasons.append(f"the timing offset between the channels cannot be told from the model's phase: with an "
                       f"offset of {1e3 * tau_r:+.3g} ms instead of "
                       f"{1e3 * timing_offset_s:+.3g} ms {label} {how} yet its G "
                       f"differs by {d_db[i]:.2g} dB / {d_deg[i]:.2g} deg at {f[i]:.3g} Hz (beyond their combined "
                       f"95 % uncertainty +-{u_db[i]:.2g} dB / +-{u_deg[i]:.2g} deg and the tolerance "
                       f"{tol_db * widen[i]:.2g} dB / {tol_deg * widen[i]:.2g} deg there)")
        fixes.append("log at a higher sample rate (a sampling convention's offset is a fraction of a sample: its "
                     "phase at the band's top shrinks with the sample period), or add an input whose latency is "
                     "known (a step logged with both channels on one clock); if the loggers' convention is known, "
                     "give it (--input-hold, or --max-timing-samples 0 for a plain zero-order hold)")


def check_model_json(model_json: dict[str, Any], *, min_compare_fit_pct: float = MIN_COMPARE_FIT_PCT) -> ModelCheck:
    """The checks of :func:`check_model` on a MODEL.json dict (as ``hasel identify`` writes it).

    A MODEL.json that says ``"usable": false`` stays unusable with its own reasons.
    Otherwise the checks are run on ``num``/``den`` with what the file holds (band,
    static map slope and its standard error, held-out NRMSE); missing items skip
    their check. For ``diagnose`` and any consumer of a nominal model.
    """
    class _M:
        num = np.asarray(model_json["num"], float)
        den = np.asarray(model_json["den"], float)

    if model_json.get("usable") is False:
        reasons = [str(r) for r in model_json.get("reasons", [])] or ["marked unusable by hasel identify"]
        fixes = [str(f) for f in model_json.get("fixes", [])] or ["identify again from a better experiment"]
        return ModelCheck(False, reasons, fixes + [fixes[-1]] * (len(reasons) - len(fixes)), {})
    band = model_json.get("frequency_band_hz")
    chk = model_json.get("checks", {}).get("details", {}) if isinstance(model_json.get("checks"), dict) else {}
    val = model_json.get("validation") or {}
    return check_model(_M(), band_hz=tuple(band) if band else None, static_slope=chk.get("static_slope"),
                       static_ci=chk.get("static_slope_se"), heldout_nrmse=val.get("nrmse"),
                       min_compare_fit_pct=min_compare_fit_pct)
