"""Output-error refinement of a continuous transfer function on the whole log (time domain).

The frequency-domain fit (:mod:`hasel.ident.tffit`) sees only the band the input
excites inside each operating point. The log holds more: the steps between operating
points, the holds, a pre-conditioning, the slow start of a sweep. All of it pins the
static gain and the slow poles. This module fits ``y = c + G(s) (u - u_0)`` to the
samples themselves (an output-error fit, the maximum-likelihood fit for white output
noise), starting from the frequency-domain estimate, on interleaved estimation
blocks, and scores it on the held-out blocks in between (which the fit never sees).

Sampling convention (``hold``):

- ``"zoh"`` (default): each input sample is held until the next one (a DAC, a
  controller holding its command, this project's plant). The continuous model is
  discretised exactly by zero-order hold.
- ``"centred"``: the input samples are instantaneous readings of a smooth signal;
  the simulation is advanced by half a sample.

With block-averaged data (``M`` raw samples per block) the block mean of the output
sits ``(M - 1) / 2`` raw samples after the block's start; the simulation is
interpolated there.

Timing offset: loggers differ in how the input and output samples line up (an input
held or interpolated over each sample, an output read at the sample's start or in its
middle, a fractional-sample skew between channels). That is a shift of at most about
one raw sample between the channels, not dynamics. :func:`oe_fit` estimates it (bounded
to ``max_shift`` samples) so that it does not end up in ``G(s)`` as phase; it is
reported on its own.

The simulation is the sum of first- and second-order sections in parallel (the
partial fractions of ``G``), each discretised by its exact ZOH formula: fast enough
to evaluate hundreds of times on 10^5 samples, well conditioned for lightly damped
poles. The same sections, one per mode (:func:`modal_basis`), and the ARX regression
of :func:`arx_start` (:func:`arx_lstsq`) serve the variable-projection mode of the fit
(:mod:`hasel.ident.varpro`).
"""
from __future__ import annotations

import warnings
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from scipy import signal

from hasel.errors import BadInputError
from hasel.ident.tffit import TFModel
from hasel.lti import ZohAt, zoh_sos

__all__ = ["simulate_zoh", "modal_basis", "Pieces", "OEResult", "oe_fit", "arx_start", "arx_lstsq", "HOLDS"]

#: Accepted sampling conventions of the input.
HOLDS = ("zoh", "centred")
#: How :func:`simulate_zoh` reads the output between interval starts by default: ``"blocks"``, exactly for
#: the held input (:func:`_sim_modal_at`) where the data are means of blocks of at least :data:`EXACT_BLOCK_MIN`
#: raw samples (each block's mean of its raw samples' exact outputs) and by linear interpolation between interval
#: starts otherwise;
#: ``"exact"`` everywhere; ``"interpolated"`` everywhere (the read of every fit before session 14).
#: Set on the 115 identification tuning logs (bench/tune_ident/RESULT_h-ident4.md): the exact read of block
#: means moved the 10 kHz and most 1 kHz models closer to P(s) (read at the block's mean time, the interpolation
#: droops -0.16 dB at 15 Hz of a 250 Hz working rate, the block mean itself -0.05 dB: the fitted G made up the
#: difference near the band's top); the exact read of raw 200 Hz samples too turned 7 good 200 Hz models wrong at
#: exit 0 (2/3 models with a fractional offset 2 deg further off at 15 Hz, up to 21 deg where a higher order
#: then took the lead into G: the interpolation's droop had happened to follow the paper's plant's approach to
#: its notch at 19.45 Hz).
READ = "blocks"
#: The ``read`` values of :func:`simulate_zoh`.
READS = ("blocks", "exact", "interpolated")
#: Smallest block (raw samples per working sample) read exactly under ``READ = "blocks"``. Set on the 115
#: identification tuning logs (bench/tune_ident/RESULT_h-ident4.md): read exactly, the 10 kHz logs (blocks of 40)
#: all moved closer to P(s) or stayed (3 wrong models right, one wrong at exit 0 right); the 1 kHz logs (blocks of 4)
#: were mixed (two right chirp models lost, a plain 1 kHz paper chirp of src/tests/designs.py, seed 3, went from
#: 3.4 deg to 5.4 deg at exit 0), the 500 Hz ones (blocks of 2) gave one more wrong model at exit 0.
EXACT_BLOCK_MIN = 8
#: Bound of the output-error parameters (logs of scaled polynomial coefficients): e^60 is far beyond any
#: physical pole ratio, and keeps products of them finite
_THETA_MAX = 60.0


def _pole_sections(poles: np.ndarray, residues: np.ndarray, dt: float) -> list[np.ndarray]:
    """One second-order section ``[b0, b1, b2, 1, a1, a2]`` per real pole or conjugate pair (exact ZOH)."""
    secs = []
    used = np.zeros(poles.size, bool)
    for i, (p, r) in enumerate(zip(poles, residues)):
        if used[i]:
            continue
        used[i] = True
        if abs(p.imag) <= 1e-9 * max(abs(p), 1e-12):
            secs.append(_mode_section(p, r, dt, True))
            continue
        # its conjugate: mark it used (the pair is one real section)
        j = np.argmin(np.where(used, np.inf, np.abs(poles - np.conj(p))))
        used[j] = True
        secs.append(_mode_section(p, r, dt, False))
    return secs


def _mode_section(p: complex, r: complex, dt: float, real: bool) -> np.ndarray:
    """The section ``[b0, b1, b2, 1, a1, a2]`` of ``r / (s - p)``, with its conjugate unless ``real`` (exact ZOH, step dt s)."""
    a = np.exp(p * dt)
    b = (a - 1.0) / p if abs(p) > 1e-300 else dt
    if real:
        return np.array([0.0, float(np.real(r * b)), 0.0, 1.0, -float(np.real(a)), 0.0])
    rb = r * b
    return np.array([0.0, 2.0 * rb.real, -2.0 * float(np.real(rb * np.conj(a))), 1.0, -2.0 * a.real, float(abs(a) ** 2)])


def simulate_zoh(model: TFModel, u: np.ndarray, rate_hz: float, *, hold: str = "zoh", block: int = 1,
                 shift: float = 0.0, read: str | None = None) -> np.ndarray:
    """Output of ``model`` for the input ``u`` (deviation from rest), sampled at ``rate_hz``.

    Parameters
    ----------
    model : TFModel
        Continuous model, s in rad/s (its delay is rounded to whole samples).
    u : ndarray, shape (n,)
        Input samples minus the level the system rests at, input unit.
    rate_hz : float
        Sample rate of ``u``, Hz.
    hold : {"zoh", "centred"}
        Sampling convention of the input (see the module).
    block : int
        Raw samples averaged into each sample of ``u`` and of the data compared with
        (1 for raw data).
    shift : float
        Where the data's output samples sit on the simulation's time axis, in samples
        of ``u``: ``y_data[k] = y_sim(k + shift)`` (linear interpolation). Positive
        when the data's output is ahead of the model (a first-order hold of the
        input), negative when it lags (a skew of the output channel).
    read : {"blocks", "exact", "interpolated"}, optional
        How the output is read between interval starts (default :data:`READ`): exactly for
        the held input (``"exact"``: each block's mean of the raw samples' exact outputs), by
        linear interpolation between interval starts at the block's mean time
        (``"interpolated"``, the read of models fitted before session 14), or exactly only
        when ``block >= EXACT_BLOCK_MIN`` (``"blocks"``).

    Returns
    -------
    ndarray, shape (n,)
        Output, output unit, on the data's sample times.
    """
    if hold not in HOLDS:
        raise BadInputError(f"hold must be one of {', '.join(HOLDS)}, got {hold!r}")
    x = np.asarray(u, float)
    lag = int(round(model.delay_s * rate_hz))
    if lag > 0:
        x = np.concatenate([np.zeros(min(lag, x.size)), x[: max(x.size - lag, 0)]])
    num, den, dt = np.asarray(model.num, float), np.asarray(model.den, float), 1.0 / rate_hz
    # where the data's sample sits between two simulated samples, in samples: the block's raw samples at
    # i / block (i = 0 .. block - 1) into its working interval, plus the convention's and the offset's shift
    extra = (0.5 if hold == "centred" else 0.0) + float(shift)
    rd = read if read is not None else READ
    if rd not in READS:
        raise BadInputError(f"read must be one of {', '.join(READS)}, got {rd!r}")
    if (rd == "exact" and (block > 1 or extra != 0.0)) or (rd == "blocks" and block >= EXACT_BLOCK_MIN):
        y = _sim_modal_at(num, den, x, dt, np.arange(block) / block + extra)
        if y is not None:
            return y
    y = _sim_modal(num, den, x, dt)
    return _at_shift(y, (block - 1) / (2.0 * block) + extra)


def _sim_modal_at(num: np.ndarray, den: np.ndarray, u: np.ndarray, dt: float, fracs: np.ndarray) -> np.ndarray | None:
    """The mean over ``fracs`` of the output read ``frac`` samples after each interval start, exact for the held input.

    ``out[k] = mean_i y(t_k + fracs[i] dt)`` (``fracs`` in samples, any sign; a read before the first
    or after the last interval start takes the end sample's interval). Each mode ``r / (s - p)`` of
    the partial fractions has the state ``x_k`` at the interval starts (``x_{k+1} = e^{p dt} x_k +
    (e^{p dt} - 1) / p u_k``, from rest) and, ``a`` (0 <= a < 1) into the interval,
    ``x = e^{p a dt} x_k + (e^{p a dt} - 1) / p u_k``: the mean over the fractions is a
    combination of ``x_k`` and ``u_k`` (per whole sample of the fractions) with the mean of
    ``e^{p a dt}`` as its weight, as cheap as one read. For (nearly) repeated poles, where the
    partial fractions lose their accuracy, the state-space form's exact read
    (:class:`hasel.lti.ZohAt`). Output unit; None when neither can be built (the caller
    interpolates).
    """
    if not (np.all(np.isfinite(num)) and np.all(np.isfinite(den))) or den[0] == 0:
        return np.full(u.shape, np.nan)
    den = den / den[0]
    num = num / den[0] if num.size else num
    n_p = den.size - 1
    d = float(num[0]) if num.size == den.size else 0.0
    strictly = np.polysub(num, d * den) if d != 0.0 else num
    fr = np.asarray(fracs, float)
    whole = np.floor(fr).astype(int)
    a = fr - whole
    n = u.size
    out = np.zeros(n)
    ks = np.arange(n)
    groups = [(int(w), a[whole == w]) for w in np.unique(whole)]
    idx = {w: np.clip(ks + w, 0, n - 1) for w, _ in groups}
    if d != 0.0:
        for w, aw in groups:
            out += d * (aw.size / fr.size) * u[idx[w]]
    if n_p == 0:
        return out
    poles = np.roots(den)
    sep = np.where(np.eye(n_p, dtype=bool), np.inf, np.abs(poles[:, None] - poles[None, :]))
    if np.min(sep) < 1e-5 * max(float(np.max(np.abs(poles))), 1e-12):
        # (nearly) repeated poles: the state-space form's exact read (hasel.lti.ZohAt), from rest
        try:
            z = ZohAt(num, den, dt)
            # from a zero state (as the partial fractions): at rest with 0 one sample before u[0]
            X = z.states(np.concatenate([[0.0], u]))[1:]
        except (BadInputError, ValueError, np.linalg.LinAlgError, StopIteration):
            return None
        for w, aw in groups:
            for ai in aw:
                c, dd = z.rows(float(ai))
                out += (X[idx[w]] @ c + (dd - d) * u[idx[w]]) / fr.size
        return out
    res = np.polyval(strictly, poles) / np.polyval(np.polyder(den), poles)
    uc = u.astype(complex)
    for p, r in zip(poles, res):
        if p.imag < 0 and abs(p.imag) > 1e-9 * max(abs(p), 1e-12):
            continue   # the pair's other pole: counted twice through the real part below
        real = abs(p.imag) <= 1e-9 * max(abs(p), 1e-12)
        if real:
            p, r = complex(p.real, 0.0), complex(np.real(r), 0.0)
        E = np.exp(p * dt)
        b = (E - 1.0) / p if abs(p) > 1e-300 else dt
        x = signal.lfilter([0.0, b], [1.0, -E], uc)
        acc = np.zeros(n, complex)
        for w, aw in groups:
            ea = np.exp(p * aw * dt)
            cx = ea.sum() / fr.size
            cu = ((ea.sum() - aw.size) / p if abs(p) > 1e-300 else aw.sum() * dt) / fr.size
            acc += cx * x[idx[w]] + cu * u[idx[w]]
        out += (1.0 if real else 2.0) * np.real(r * acc)
    return out


def _at_shift(y: np.ndarray, frac: float) -> np.ndarray:
    """``y`` read ``frac`` samples later, ``out[k] = y(k + frac)``: linear interpolation, the end samples held."""
    whole = int(np.floor(frac))
    frac -= whole
    if whole > 0:
        y = np.concatenate([y[whole:], np.repeat(y[-1:], whole)])
    elif whole < 0:
        y = np.concatenate([np.repeat(y[:1], -whole), y[:whole]])
    if frac > 0:
        yn = np.concatenate([y[1:], y[-1:]])
        y = (1.0 - frac) * y + frac * yn
    return y


def _sim_modal(num: np.ndarray, den: np.ndarray, u: np.ndarray, dt: float) -> np.ndarray:
    if not (np.all(np.isfinite(num)) and np.all(np.isfinite(den))) or den[0] == 0:
        return np.full(u.shape, np.nan)   # a diverged parameter set: its residual is rejected by the caller
    den = den / den[0]
    num = num / den[0] if num.size else num
    n_p = den.size - 1
    d = float(num[0]) if num.size == den.size else 0.0
    strictly = np.polysub(num, d * den) if d != 0.0 else num
    poles = np.roots(den)
    sep = np.where(np.eye(n_p, dtype=bool), np.inf, np.abs(poles[:, None] - poles[None, :]))
    if np.min(sep) < 1e-5 * max(float(np.max(np.abs(poles))), 1e-12):
        # (nearly) repeated poles: partial fractions lose their accuracy, use the state-space ZOH
        return signal.sosfilt(zoh_sos(num, den, dt), u)
    dprime = np.polyder(den)
    res = np.polyval(strictly, poles) / np.polyval(dprime, poles)
    y = d * u
    if n_p == 0:
        return y
    for sec in _pole_sections(poles, res, dt):
        y = y + signal.sosfilt(sec[None, :], u)
    return y


def modal_basis(poles: np.ndarray, u: np.ndarray, rate_hz: float, *, shift: float = 0.0) -> list[np.ndarray]:
    """Responses to ``u`` of the modes of ``poles``: every model with these poles is a combination of them.

    One column per real pole (the response of ``1/(s - p)``) and two per pole of positive
    imaginary part (the responses of the real and of the imaginary part of ``1/(s - p)``,
    its conjugate implied), each the exact ZOH section of :func:`simulate_zoh`'s
    simulation (:func:`_pole_sections`), started at rest with ``u[0]`` and read ``shift``
    samples (``-1 .. 1``) into each interval, interpolated as :func:`simulate_zoh` does.

    Parameters
    ----------
    poles : ndarray of complex
        Real poles (imaginary part exactly 0) and one pole of each conjugate pair, rad/s.
    u : ndarray, shape (n,)
        Input, input unit, at ``rate_hz`` (Hz).
    shift : float
        Where the output samples sit, samples of ``u`` (as :func:`simulate_zoh`'s ``shift``).

    Returns
    -------
    list of ndarray, shape (n,)
        The columns, output unit per input unit times s.
    """
    dt = 1.0 / rate_hz
    u0 = float(u[0])
    # two zeros before (the taps below read the recursion one and two samples late) and one sample
    # more (the interpolation at the last sample has its right neighbour)
    du = np.empty(u.size + 3)
    du[:2] = 0.0
    du[2:-1] = u
    du[-1] = u[-1]
    du[2:] -= u0
    cols = []
    for p in np.asarray(poles, complex):
        rest = -u0 / p   # the mode at rest with u[0]
        if p.imag == 0:
            parts = [(_mode_section(p, 1.0, dt, True), rest.real)]
        else:
            # the residues of the real and of the imaginary part of 1/(s - p)
            parts = [(_mode_section(p, 0.5, dt, False), rest.real), (_mode_section(p, -0.5j, dt, False), rest.imag)]
        # the sections of one mode share their denominator: its recursion runs once (and is read
        # at the shifted times once: the reading is linear), each section's numerator (b0 = 0,
        # b1, b2) is then two taps of it
        w = signal.lfilter([1.0], parts[0][0][3:4 + len(parts)], du)
        if shift != 0.0:
            w = _at_shift(w, shift)
        w1, w2 = w[1:-2], w[:-3]
        for sec, level in parts:
            cols.append(sec[1] * w1 + level if len(parts) == 1 else sec[1] * w1 + sec[2] * w2 + level)
    return cols


@dataclass(frozen=True)
class Pieces:
    """How the log is simulated and split: contiguous pieces, each from rest at its start.

    Attributes
    ----------
    bounds : list of (int, int)
        Sample ranges ``i0 <= i < i1`` simulated separately (each with its own level
        ``u[i0]`` and output constant).
    estimate : ndarray of bool
        Samples used by the fit.
    heldout : ndarray of bool
        Samples kept out of the fit and used to score it.
    """

    bounds: list[tuple[int, int]]
    estimate: np.ndarray
    heldout: np.ndarray


def interleaved(n: int, bounds: Sequence[tuple[int, int]], block: int, holdout_fraction: float,
                skip: int) -> Pieces:
    """Pieces with every ``round(1 / holdout_fraction)``-th block of ``block`` samples held out.

    The first ``skip`` samples of each piece (its start-up transient) are in neither set.
    """
    est = np.zeros(n, bool)
    held = np.zeros(n, bool)
    every = int(round(1.0 / holdout_fraction)) if holdout_fraction > 0 else 0
    for i0, i1 in bounds:
        j0 = min(i0 + skip, i1)
        idx = np.arange(j0, i1)
        if every:
            k = (idx - j0) // max(block, 1)
            h = (k % every) == every // 2
        else:
            h = np.zeros(idx.size, bool)
        est[idx[~h]] = True
        held[idx[h]] = True
    return Pieces(list(bounds), est, held)


@dataclass(frozen=True)
class OEResult:
    """An output-error fit.

    Attributes
    ----------
    model : TFModel
    nrmse_estimate, nrmse_heldout : float
        ``||y - y_hat|| / ||y - mean(y)||`` on the estimation and held-out samples
        (each piece centred on its own mean).
    levels : list of float
        The fitted output constant of each piece.
    y_hat : ndarray
        The simulation over the whole log.
    shift : float
        Estimated timing offset, samples of the data, as :func:`simulate_zoh`'s
        ``shift`` (0 when not estimated).
    """

    model: TFModel
    nrmse_estimate: float
    nrmse_heldout: float
    levels: list[float]
    y_hat: np.ndarray
    shift: float = 0.0


def _to_theta(model: TFModel, w0: float) -> tuple[np.ndarray, int, int]:
    """Parameters: numerator in x = s / w0 (ascending) and the log of each quadratic/linear factor's coefficients."""
    den = np.asarray(model.den, float) / model.den[0]
    num = np.asarray(model.num, float) / model.den[0]
    n_p, nz = den.size - 1, num.size - 1
    roots = np.roots(den) / w0
    roots = np.where(np.real(roots) >= 0, -np.abs(roots) - 1e-9, roots)
    cplx = roots[np.imag(roots) > 1e-12 * np.maximum(np.abs(roots), 1.0)]
    real = np.sort(-np.real(roots[np.abs(np.imag(roots)) <= 1e-12 * np.maximum(np.abs(roots), 1.0)]))
    params = []
    for p in cplx:
        params += [np.log(max(-2.0 * p.real, 1e-12)), np.log(max(abs(p) ** 2, 1e-12))]
    i = 0
    while i + 1 < real.size:
        params += [np.log(real[i] + real[i + 1]), np.log(real[i] * real[i + 1])]
        i += 2
    if i < real.size:
        params.append(np.log(real[i]))
    b = num[::-1] * w0 ** np.arange(nz + 1) / w0 ** n_p
    return np.concatenate([b, params]), nz, n_p


def _from_theta(theta: np.ndarray, nz: int, n_p: int, w0: float) -> TFModel:
    b = theta[: nz + 1]
    q = theta[nz + 1:]
    den = np.array([1.0])
    for k in range(n_p // 2):
        den = np.polymul(den, [1.0, np.exp(q[2 * k]), np.exp(q[2 * k + 1])])
    if n_p % 2:
        den = np.polymul(den, [1.0, np.exp(q[-1])])
    num_s = b[::-1] / w0 ** np.arange(nz, -1, -1)
    den_s = den / w0 ** np.arange(n_p, -1, -1)
    return TFModel(num=num_s / den_s[0], den=den_s / den_s[0])


def oe_fit(model0: TFModel, u: np.ndarray, y: np.ndarray, rate_hz: float, pieces: Pieces, *, hold: str = "zoh",
           block: int = 1, max_nfev: int = 60, log_pmin: float | None = None, max_shift: float = 0.0,
           shift0: float = 0.0, offset: float = 0.0, drift_s: float = 0.0) -> OEResult:
    """Refine ``model0`` (same orders) by output error on ``pieces.estimate``; score on ``pieces.heldout``.

    Parameters
    ----------
    model0 : TFModel
        Start (from the frequency-domain fit); its orders are kept, its delay ignored.
    u, y : ndarray, shape (n,)
        Input and output at ``rate_hz`` (block means if ``block > 1``).
    rate_hz : float
        Their rate, Hz.
    pieces : Pieces
        Pieces simulated from rest, estimation and held-out samples.
    hold, block :
        As for :func:`simulate_zoh`.
    max_nfev : int
        Budget of the least-squares refinement (function evaluations).
    log_pmin : float, optional
        Natural log of the smallest pole magnitude allowed, rad/s (default: none).
    max_shift : float
        Largest timing offset estimated, samples of ``u`` (0: none estimated).
    shift0 : float
        Start of the timing offset, samples (within ``max_shift``).
    offset : float
        A fixed timing offset added to the estimated one, samples (as
        :func:`simulate_zoh`'s ``shift``).
    drift_s : float
        Knot spacing of a slow output baseline fitted with the model, s (0: one
        constant per piece). A sensor that wanders (thermal drift of a laser, a
        strain gauge) adds a slow offset that an output-error fit would otherwise
        bend the model's slow poles and static gain to follow. The baseline is
        piecewise linear between knots ``drift_s`` apart, fitted by least squares on
        the estimation samples only (linear in its coefficients: projected out at
        each evaluation) and interpolated across the held-out blocks; pieces shorter
        than two knot spacings keep one constant.

    Returns
    -------
    OEResult
    """
    w0 = float(np.max(np.abs(np.roots(model0.den)))) if model0.den.size > 1 else 1.0
    w0 = max(w0, 1e-6)
    theta0, nz, n_p = _to_theta(model0, w0)
    n_th = theta0.size
    if max_shift > 0:
        # the offset enters as max_shift * tanh(theta[-1]): bounded, smooth
        theta0 = np.append(theta0, np.arctanh(np.clip(shift0 / max_shift, -0.99, 0.99)))
    est = pieces.estimate
    lo_bound = None
    if log_pmin is not None:
        lo_bound = log_pmin - np.log(w0)

    def clip(theta: np.ndarray) -> np.ndarray:
        # only the logs of the factors' coefficients are bounded (the numerator is free)
        out = theta.copy()
        out[nz + 1:] = np.clip(out[nz + 1:], -_THETA_MAX, _THETA_MAX)
        return out

    def shift_of(theta: np.ndarray) -> float:
        return float(max_shift * np.tanh(theta[n_th])) if max_shift > 0 else 0.0

    def total_shift(theta: np.ndarray) -> float:
        return offset + shift_of(theta)

    bases = [_baseline_basis(i1 - i0, est[i0:i1], rate_hz, drift_s) for i0, i1 in pieces.bounds]

    def sim(theta: np.ndarray) -> tuple[np.ndarray, list[float]]:
        sh = total_shift(theta)
        th = theta[:n_th]
        if lo_bound is not None:
            th = th.copy()
            q = th[nz + 1:]
            q[1:2 * (n_p // 2):2] = np.maximum(q[1:2 * (n_p // 2):2], 2 * lo_bound)
            if n_p % 2:
                q[-1] = max(q[-1], lo_bound)
        return _simulate_pieces(_from_theta(th, nz, n_p, w0), u, y, rate_hz, pieces, bases, hold=hold, block=block,
                                shift=sh)

    scale = float(np.std(y[est])) or 1.0

    def resid(theta: np.ndarray) -> np.ndarray:
        with np.errstate(all="ignore"):
            try:
                yh, _ = sim(clip(theta))
            except (np.linalg.LinAlgError, ValueError, ZeroDivisionError, StopIteration):
                # StopIteration: hasel.lti's pairing of (nearly) repeated poles gives up on a diverged set
                return np.full(int(np.count_nonzero(est)), 1e3)
        r = (y[est] - yh[est]) / scale
        return np.where(np.isfinite(r), r, 1e3)

    r0 = resid(theta0)
    theta = theta0 if max_nfev <= 0 else _levenberg_marquardt(resid, theta0, r0, max_iter=max(1, max_nfev // 3))
    theta = clip(theta)
    with np.errstate(all="ignore"):   # a diverged start is scored (as NaN), not warned about
        model = _from_theta(theta[:n_th], nz, n_p, w0)
        try:
            yh, levels = sim(theta)
        except (np.linalg.LinAlgError, ValueError, ZeroDivisionError, StopIteration):
            yh, levels = np.full(y.shape, np.nan), [float("nan")] * len(pieces.bounds)
    return OEResult(model, _nrmse(y, yh, pieces, est), _nrmse(y, yh, pieces, pieces.heldout), levels, yh,
                    shift_of(theta))


def _simulate_pieces(m: TFModel, u: np.ndarray, y: np.ndarray, rate_hz: float, pieces: Pieces,
                     bases: list["_Baseline | None"], *, hold: str, block: int,
                     shift: float) -> tuple[np.ndarray, list[float]]:
    """The model's output over every piece (each simulated from rest, input relative to its first
    sample), plus each piece's output level: its slow baseline (``bases``) where it has one, else the
    constant that best fits its estimation samples (all its samples when it has none).

    Returns the simulated output (output unit) and each piece's mean level.
    """
    est = pieces.estimate
    out = np.empty_like(y)
    levels = []
    for (i0, i1), basis in zip(pieces.bounds, bases):
        ys = simulate_zoh(m, u[i0:i1] - u[i0], rate_hz, hold=hold, block=block, shift=shift)
        e = est[i0:i1]
        if basis is not None:
            base = basis(y[i0:i1][e] - ys[e])
            out[i0:i1] = ys + base
            levels.append(float(np.mean(base)))
            continue
        c = float(np.mean(y[i0:i1][e] - ys[e])) if np.any(e) else float(np.mean(y[i0:i1] - ys))
        out[i0:i1] = ys + c
        levels.append(c)
    return out, levels


class _Baseline:
    """A piecewise-linear baseline over one piece, knots ``drift_s`` apart, fitted on its estimation samples.

    The hat functions are sparse (two per sample): their Gram matrix and right-hand side are
    sums over the samples, so one fit costs O(n), not O(n K).
    """

    def __init__(self, n: int, est: np.ndarray, rate_hz: float, drift_s: float):
        k = int(np.floor(n / (drift_s * rate_hz)))
        x = np.arange(n, dtype=float) * (k / max(n - 1.0, 1.0))
        self.j = np.minimum(np.floor(x).astype(int), k - 1)
        self.w = x - self.j
        self.k = k
        self.est = est
        je, we = self.j[est], self.w[est]
        gram = np.zeros((k + 1, k + 1))
        np.add.at(gram, (je, je), (1 - we) ** 2)
        np.add.at(gram, (je + 1, je + 1), we ** 2)
        np.add.at(gram, (je, je + 1), (1 - we) * we)
        np.add.at(gram, (je + 1, je), (1 - we) * we)
        ev = np.linalg.eigvalsh(gram)
        self.ok = bool(ev[0] > 1e-9 * ev[-1])
        self.inv = np.linalg.inv(gram) if self.ok else None
        self.je, self.we = je, we

    def __call__(self, r_est: np.ndarray) -> np.ndarray:
        """The least-squares baseline of the residual ``r_est`` (on the estimation samples) over the whole piece."""
        rhs = (np.bincount(self.je, (1 - self.we) * r_est, self.k + 1)
               + np.bincount(self.je + 1, self.we * r_est, self.k + 1))
        c = self.inv @ rhs
        return c[self.j] * (1 - self.w) + c[self.j + 1] * self.w


def _baseline_basis(n: int, est: np.ndarray, rate_hz: float, drift_s: float) -> _Baseline | None:
    """The slow baseline of a piece of ``n`` samples (see :class:`_Baseline`), or None.

    None when ``drift_s`` is 0, the piece is shorter than two knot spacings, or the fit
    would be ill-posed (a knot interval without estimation samples).
    """
    if drift_s <= 0 or n < 2 * drift_s * rate_hz or np.count_nonzero(est) < 16:
        return None
    b = _Baseline(n, est, rate_hz, drift_s)
    return b if b.ok else None


def _levenberg_marquardt(resid, theta0: np.ndarray, r0: np.ndarray, max_iter: int) -> np.ndarray:
    """Minimise ``||resid(theta)||^2`` from ``theta0``: Levenberg-Marquardt on the normal equations.

    The Jacobian is taken by forward differences; the normal equations (parameters x
    parameters) are solved instead of a factorisation of the tall Jacobian, which on
    10^5 samples is what makes the fit fast. Never returns a worse point than ``theta0``.
    """
    theta, r = theta0.copy(), r0
    cost = float(r @ r)
    lam = 1e-3
    for _ in range(max_iter):
        h = 1e-6 * np.maximum(np.abs(theta), 1e-2)
        J = np.empty((r.size, theta.size))
        for i in range(theta.size):
            tp = theta.copy()
            tp[i] += h[i]
            J[:, i] = (resid(tp) - r) / h[i]
        J = np.nan_to_num(J, nan=0.0, posinf=0.0, neginf=0.0)
        g = J.T @ r
        A = J.T @ J
        d = np.sqrt(np.maximum(np.diag(A), 1e-30))
        An = A / np.outer(d, d)
        gn = g / d
        improved = False
        rel = 0.0
        for _ in range(8):
            try:
                step = -np.linalg.solve(An + lam * np.eye(theta.size), gn) / d
            except (np.linalg.LinAlgError, ValueError):
                lam *= 10
                continue
            rn = resid(theta + step)
            cn = float(rn @ rn)
            if cn < cost:
                rel = (cost - cn) / cost
                theta, r, cost = theta + step, rn, cn
                lam = max(lam / 5, 1e-9)
                improved = True
                break
            lam *= 10
        if not improved or rel < 1e-6:
            break
    return theta


def _nrmse(y: np.ndarray, yh: np.ndarray, pieces: Pieces, mask: np.ndarray) -> float:
    """NRMSE over ``mask``, each contiguous run of it centred on its own mean.

    Centring each run (not the whole log) scores the dynamics: the level changes
    between operating points would otherwise dominate the denominator.
    """
    num = den = 0.0
    idx = np.flatnonzero(mask)
    if idx.size == 0:
        return float("nan")
    cut = np.flatnonzero(np.diff(idx) > 1) + 1
    for run in np.split(idx, cut):
        yy, hh = y[run], yh[run]
        num += float(np.sum((yy - hh) ** 2))
        den += float(np.sum((yy - yy.mean()) ** 2))
    return float(np.sqrt(num / den)) if den > 0 else float("nan")


def arx_lstsq(segments: Sequence[tuple[np.ndarray, np.ndarray, np.ndarray]], n: int, *, constant: bool = False,
              min_rows: int = 1) -> np.ndarray | None:
    """Least-squares ARX coefficients over the masked samples of one or more segments.

    The model ``y[k] = -sum a_i y[k-i] + sum b_i u[k-i] (+ c)``, ``i = 1..n``, is linear in
    its parameters; its rows are the samples ``k >= n`` of each segment ``(u, y, mask)``
    where ``mask[k]`` is true (input and output in their own units, one rate). The
    columns are scaled to unit norm for the solve.

    Returns ``[a_1..a_n, b_1..b_n]`` (and ``c``, output unit, with ``constant``), or None
    with fewer than ``min_rows`` rows.
    """
    blocks, rhs = [], []
    for u, y, mask in segments:
        k = np.arange(n, y.size)
        k = k[mask[k]]
        cols = [-y[k - i] for i in range(1, n + 1)] + [u[k - i] for i in range(1, n + 1)]
        if constant:
            cols.append(np.ones(k.size))
        blocks.append(np.column_stack(cols))
        rhs.append(y[k])
    if not blocks or sum(b.shape[0] for b in blocks) < max(min_rows, 1):
        return None
    X, b = (blocks[0], rhs[0]) if len(blocks) == 1 else (np.vstack(blocks), np.concatenate(rhs))
    scale = np.linalg.norm(X, axis=0)
    scale[scale == 0] = 1.0
    return np.linalg.lstsq(X / scale, b, rcond=None)[0] / scale


def arx_start(u: np.ndarray, y: np.ndarray, rate_hz: float, n_p: int, pieces: Pieces) -> TFModel | None:
    """A continuous start of ``n_p`` poles from a least-squares ARX fit on the estimation samples.

    ``y[k] = -sum a_i y[k-i] + sum b_i u[k-i] + c`` (``i = 1..n_p``) is linear in its
    parameters, so it needs no start itself and uses every sample (steps, levels,
    transitions). The discrete model is made continuous by the matrix logarithm of
    its zero-order-hold state-space form. Returns None when that is impossible (a
    pole on the negative real axis of z) or the result is unstable.
    """
    from scipy import linalg

    n = n_p
    theta = arx_lstsq([(u, y, pieces.estimate)], n, constant=True, min_rows=4 * (2 * n + 1))
    if theta is None:
        return None
    a = np.concatenate([[1.0], theta[:n]])
    b = np.concatenate([[0.0], theta[n:2 * n]])
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")   # tf2ss/ss2tf warn of tiny leading numerator terms; they are trimmed
            A, B, C, D = signal.tf2ss(b, a)
        dt = 1.0 / rate_hz
        big = np.zeros((n + 1, n + 1))
        big[:n, :n] = A
        big[:n, n:] = B
        big[n, n] = 1.0
        L = linalg.logm(big) / dt
        if np.max(np.abs(np.imag(L))) > 1e-6 * max(np.max(np.abs(L)), 1.0):
            return None
        Ac, Bc = np.real(L[:n, :n]), np.real(L[:n, n:])
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")   # ss2tf warns of tiny leading numerator terms; they are trimmed
            num, den = signal.ss2tf(Ac, Bc, C, D)
    except (ValueError, np.linalg.LinAlgError):
        return None
    num = np.trim_zeros(np.atleast_1d(num[0]), "f")
    if num.size == 0 or not np.all(np.isfinite(den)) or np.any(np.real(np.roots(den)) >= 0):
        return None
    num = num[-n:] if num.size > n else num
    return TFModel(num=np.asarray(num, float) / den[0], den=np.asarray(den, float) / den[0])


def _oe_covariance(oe: OEResult, u: np.ndarray, y: np.ndarray, rate_hz: float, pieces: Pieces, *, hold: str,
                  block: int, max_shift: float, drift_s: float, cluster_s: float) -> tuple | None:
    """The cluster-robust covariance of :func:`oe_fit`'s parameters (see :func:`response_uncertainty`).

    Returns ``(cov, theta, nz, n_p, w0)`` (the timing offset last when ``max_shift > 0``,
    in samples of ``u``), or None when the simulation fails or there are too few clusters.
    """
    m0 = oe.model
    w0 = float(np.max(np.abs(np.roots(m0.den)))) if m0.den.size > 1 else 1.0
    w0 = max(w0, 1e-6)
    theta, nz, n_p = _to_theta(m0, w0)
    n_th = theta.size
    shift_free = max_shift > 0
    est = pieces.estimate
    bases = [_baseline_basis(i1 - i0, est[i0:i1], rate_hz, drift_s) for i0, i1 in pieces.bounds]

    def sim(th: np.ndarray, sh: float) -> np.ndarray:
        out, _ = _simulate_pieces(_from_theta(th, nz, n_p, w0), u, y, rate_hz, pieces, bases, hold=hold, block=block,
                                  shift=sh)
        return out[est]

    with np.errstate(all="ignore"):
        try:
            base = sim(theta, oe.shift)
            r = y[est] - base
            cols = []
            for i in range(n_th + (1 if shift_free else 0)):
                if i < n_th:
                    h = 1e-6 * max(abs(theta[i]), 1e-2)
                    tp = theta.copy()
                    tp[i] += h
                    cols.append((sim(tp, oe.shift) - base) / h)
                else:
                    h = 1e-4
                    cols.append((sim(theta, oe.shift + h) - base) / h)
        except (np.linalg.LinAlgError, ValueError, ZeroDivisionError, StopIteration):
            return None
    J = np.column_stack(cols)
    if not np.all(np.isfinite(J)) or not np.all(np.isfinite(r)):
        return None
    d = np.sqrt(np.maximum(np.sum(J * J, axis=0), 1e-300))
    Jn = J / d
    A = Jn.T @ Jn
    prior = np.zeros(A.shape[0])
    if shift_free:
        # the timing offset is bounded to +-max_shift by construction: a uniform prior there (standard deviation
        # max_shift / sqrt(3)) as one pseudo-observation of the residuals' own variance, so a shift the data do not
        # pin trades with the phase at most as far as it can move (unbounded, 1.5 raw samples of a 10 kHz log read
        # as +-6 deg at 11 Hz of the working rate's samples)
        s2 = float(r @ r) / max(r.size, 1)
        prior[-1] = s2 / ((max_shift / np.sqrt(3.0)) * d[-1]) ** 2
        A = A + np.diag(prior)
    # a pseudo-inverse: directions the data do not see at all (a nearly cancelling pole-zero pair moved
    # together) carry no information, and change the response little; their numerical noise is dropped
    try:
        w, V = np.linalg.eigh(A)
    except np.linalg.LinAlgError:
        return None
    keep = w > 1e-10 * max(float(np.max(w)), 1e-300)
    Ainv = (V[:, keep] / w[keep]) @ V[:, keep].T
    # clusters: runs of estimation samples cut every cluster_s seconds
    idx = np.flatnonzero(est)
    L = max(int(round(cluster_s * rate_hz)), 8)
    cut = np.flatnonzero((np.diff(idx) > 1) | (np.diff(idx // L) > 0)) + 1
    meat = np.zeros_like(A)
    pos = np.concatenate([[0], cut, [idx.size]])
    for a, b in zip(pos[:-1], pos[1:]):
        g = Jn[a:b].T @ r[a:b]
        meat += np.outer(g, g)
    n_cl = pos.size - 1
    p_all = J.shape[1]
    if n_cl <= p_all:
        return None
    # the prior's pseudo-observation adds its own share (precision times the residuals' variance) to the meat
    cov_n = Ainv @ (meat * (n_cl / (n_cl - p_all)) + np.diag(prior * s2 if shift_free else prior)) @ Ainv
    cov = cov_n / np.outer(d, d)
    return cov, theta, nz, n_p, w0


def response_uncertainty(oe: OEResult, u: np.ndarray, y: np.ndarray, rate_hz: float, pieces: Pieces,
                         f_hz: np.ndarray, *, hold: str = "zoh", block: int = 1, max_shift: float = 0.0,
                         drift_s: float = 0.0, cluster_s: float = 2.0) -> tuple[np.ndarray, np.ndarray] | None:
    """Standard errors of ``oe.model``'s response at ``f_hz`` in dB and deg, from the output-error fit's covariance.

    The parameters are those of :func:`oe_fit` (with the timing offset when
    ``max_shift > 0``: its trade-off with the model's phase is part of the error;
    its bound ``+-max_shift`` enters as a uniform prior, one pseudo-observation).
    The response's sensitivities to them are exact derivatives of ``log G``.
    Their covariance is the cluster-robust (sandwich) estimate
    ``(J'J)^-1 (sum_c J_c' r_c r_c' J_c) (J'J)^-1`` over contiguous clusters of
    ``cluster_s`` seconds of estimation samples: it holds for coloured noise, sensor
    wander and the part of a model error that looks like noise, where the white-noise
    ``s^2 (J'J)^-1`` is optimistic. Directions of the parameters the data do not
    see at all (eigenvalues of ``J'J`` below 1e-10 of the largest, e.g. a nearly
    cancelling pole-zero pair) are left out (a pseudo-inverse). Returns None when the
    simulation fails.

    Parameters
    ----------
    oe : OEResult
        The fit (its model and timing offset are the point of expansion).
    u, y, rate_hz, pieces, hold, block, drift_s :
        As given to :func:`oe_fit`.
    f_hz : ndarray
        Frequencies, Hz.
    max_shift : float
        As given to :func:`oe_fit` (0: the timing offset was not estimated).
    cluster_s : float
        Length of the clusters, s.

    Returns
    -------
    (sd_db, sd_deg) : tuple of ndarray, or None
    """
    got = _oe_covariance(oe, u, y, rate_hz, pieces, hold=hold, block=block, max_shift=max_shift, drift_s=drift_s,
                         cluster_s=cluster_s)
    if got is None:
        return None
    cov, theta, nz, n_p, w0 = got
    n_th, p_all = theta.size, cov.shape[0]
    # the response's sensitivities: log G at f against the model's parameters (the timing offset is not part
    # of G: its covariance with them still widens G's phase through the cross terms). Exact derivatives of
    # G = N(x) / D(x), x = s / w0, N = sum b_k x^k, D a product of x^2 + e^q0 x + e^q1 and x + e^q: a finite
    # step (1e-6 of max(|theta|, 1e-2)) is many times a numerator coefficient that w0 scales to 1e-17, where
    # log G is far from linear in it (a 200 Hz paper chirp's 4/5 model: derivatives wrong by 1e6)
    x = 2j * np.pi * np.asarray(f_hz, float) / w0
    D = np.zeros((x.size, p_all), complex)
    N = np.polyval(theta[: nz + 1][::-1], x)
    for k in range(nz + 1):
        D[:, k] = x ** k / N
    q = theta[nz + 1: n_th]
    for k in range(n_p // 2):
        a, c = np.exp(q[2 * k]), np.exp(q[2 * k + 1])
        quad = x * x + a * x + c
        D[:, nz + 1 + 2 * k] = -a * x / quad
        D[:, nz + 2 + 2 * k] = -c / quad
    if n_p % 2:
        e = np.exp(q[-1])
        D[:, n_th - 1] = -e / (x + e)
    var_re = np.einsum("fi,ij,fj->f", np.real(D), cov, np.real(D))
    var_im = np.einsum("fi,ij,fj->f", np.imag(D), cov, np.imag(D))
    sd_db = 20.0 / np.log(10.0) * np.sqrt(np.maximum(var_re, 0.0))
    sd_deg = np.degrees(np.sqrt(np.maximum(var_im, 0.0)))
    return sd_db, sd_deg


def shift_standard_error(oe: OEResult, u: np.ndarray, y: np.ndarray, rate_hz: float, pieces: Pieces, *,
                         hold: str = "zoh", block: int = 1, max_shift: float = 0.0, drift_s: float = 0.0,
                         cluster_s: float = 2.0) -> float:
    """Standard error of ``oe.shift`` (samples of ``u``) from the covariance of :func:`response_uncertainty`.

    The timing offset and the model's parameters are estimated together (their
    trade-off widens it); the bound ``+-max_shift`` is its uniform prior. NaN when the
    offset was not estimated (``max_shift <= 0``) or the covariance fails.
    """
    if max_shift <= 0:
        return float("nan")
    got = _oe_covariance(oe, u, y, rate_hz, pieces, hold=hold, block=block, max_shift=max_shift, drift_s=drift_s,
                         cluster_s=cluster_s)
    return float("nan") if got is None else float(np.sqrt(max(got[0][-1, -1], 0.0)))
