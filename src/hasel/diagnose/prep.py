"""Preparing a log for diagnosis: working rate, train/held-out split, noise floor, linear simulation.

Any SISO log (any units and rates) is brought to a *working rate* a few tens of times
the excited band, by averaging blocks of samples (a boxcar: the block mean of the
input is exactly the input held over that block, and input and output are
filtered alike). A continuous model is simulated with its input held over each working
interval (a zero-order hold, the convention of a DAC and of this project's plant) and
its output taken where the log's output sample lies in that interval: at its start for
an unaveraged zero-order-hold log, ``(q - 1) / 2q`` into it for block means of ``q``
samples (:attr:`Prepared.sample_offset`). Other conventions (a first-order hold, centred
samples, a fractional-sample offset between the input and output clocks) shift that
point by up to a sample; the diagnosis estimates the shift as a nuisance
(:func:`estimate_timing`) and reports it as a timing offset, not as a delay.

Held-out data come in two parts, so that the reported figures are honest: a
*validation* part, on which the diagnosis chooses (which effect, whether to accept
it, how to rank), and a *final* part, never used in any choice, on which "how far"
is reported. Without a separate held-out log, the record is cut into blocks (of
jittered lengths) and one block of every three is held out (interleaved, never two
held-out blocks in a row), the held-out blocks alternately validating and final, so
that all three parts span the levels, directions and events of the log. With a separate held-out log,
that log is the final part and one block of every three of the first log
validates. Models are always simulated over the whole record from its input alone
and scored on the masked samples only.

The noise floor comes from the data: the residual's spectral level in the band
above the excitation where nothing is excited (white-noise level times the working
band); for logs with no such band, from third differences of the residual.
"""
from __future__ import annotations

import math
import warnings
from dataclasses import dataclass, field

import numpy as np
from scipy import optimize, signal, stats

from hasel.errors import BadInputError
from hasel.ident.freqresp import excited_band
from hasel.lti import ZohAt, zoh_sos
from hasel.metrics import nrmse
from hasel.signals import uniform_grid

__all__ = ["Record", "Prepared", "LinearSim", "StartRun", "at_offset", "estimate_timing", "prepare", "estimate_noise", "excited_band_hz",
           "dominant_time_constant_s", "nrmse", "flat_extremes", "noise_trust", "rest_start"]


@dataclass
class Record:
    """One log at the working rate.

    Attributes
    ----------
    t_s, u, y : ndarray
        Times (s), input and output (their own units).
    train, hold : ndarray of bool
        Samples used for fitting, and the final held-out samples (reported, never chosen on).
    valid : ndarray of bool or None
        Validation samples (the diagnosis chooses on them); ``None``: none in this record.
    """

    t_s: np.ndarray
    u: np.ndarray
    y: np.ndarray
    train: np.ndarray
    hold: np.ndarray
    valid: np.ndarray | None = None

    def __post_init__(self) -> None:
        if self.valid is None:
            self.valid = np.zeros(self.t_s.size, bool)


@dataclass
class Prepared:
    """A diagnosis problem at the working rate.

    Attributes
    ----------
    records : list of Record
        The data log (and a separate held-out log, if given).
    rate_hz : float
        Working rate, Hz.
    decimation : int
        Original samples per working sample.
    f_excited_hz : float
        Upper edge of the input's excited band, Hz.
    split : str
        How the held-out part was chosen.
    sample_offset : float
        Where in its working interval each output sample is taken, working samples (see
        :class:`LinearSim`): ``(q - 1) / 2q`` for block means of ``q`` samples of a
        zero-order-hold log; the diagnosis refines it as a nuisance (a timing offset).
    exact_offset : bool
        Whether simulations read the output between interval starts exactly for the held
        input (:class:`LinearSim` ``exact``), or interpolate linearly between them. False when the
        nominal model is identified from the log: the identification's simulation
        (:mod:`hasel.ident.timefit`) interpolates, and a model is simulated the way it was fitted.
        False too for a given model whose JSON says ``"sample_read": "interpolated"`` (written by
        ``hasel identify`` and by this diagnosis's own identification): read exactly, ``make demo``'s
        identify-made model was given a spurious load of mass ratio +0.064 (with the paper's P(s) the
        exact read named the true effects only: ``bench/tune_diag/RESULT-l-offset.md``).
    """

    records: list[Record]
    rate_hz: float
    decimation: int
    f_excited_hz: float
    split: str
    info: dict = field(default_factory=dict)
    sample_offset: float = 0.0
    exact_offset: bool = True

    @property
    def dt_s(self) -> float:
        """Working sample period, s."""
        return 1.0 / self.rate_hz

    def sim(self, num: np.ndarray, den: np.ndarray, offset: float | None = None) -> "LinearSim":
        """The model ``num/den`` (descending powers of s) simulated at :attr:`rate_hz` with this
        problem's read: output ``offset`` working samples into each held interval (default
        :attr:`sample_offset`), read exactly or interpolated as :attr:`exact_offset` says.
        One place, so no caller can pair a rate, an offset and a read convention that disagree."""
        return LinearSim(num, den, self.rate_hz, self.sample_offset if offset is None else offset,
                         exact=self.exact_offset)

    def stacked(self, what: str, mask: str | None = None) -> np.ndarray:
        """Concatenate ``what`` ("u", "y", "t_s") over the records, optionally masked ("train"/"valid"/"hold")."""
        parts = []
        for r in self.records:
            x = getattr(r, what)
            parts.append(x[getattr(r, mask)] if mask else x)
        return np.concatenate(parts)


def _uniform(t: np.ndarray, u: np.ndarray, y: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, float]:
    t = np.asarray(t, float)
    u = np.asarray(u, float)
    y = np.asarray(y, float)
    if t.ndim != 1 or u.shape != t.shape or y.shape != t.shape:
        raise BadInputError(f"time, input and output must be 1-D of one length, got {t.shape}, {u.shape}, {y.shape}")
    ok = np.isfinite(t) & np.isfinite(u) & np.isfinite(y)
    if ok.sum() < 50:
        raise BadInputError(f"the log has {int(ok.sum())} finite samples; diagnosis needs at least 50")
    t, u, y = t[ok], u[ok], y[ok]
    order = np.argsort(t, kind="stable")
    t, u, y = t[order], u[order], y[order]
    dt = np.diff(t)
    if np.any(dt <= 0):
        keep = np.concatenate([[True], dt > 0])
        t, u, y = t[keep], u[keep], y[keep]
        dt = np.diff(t)
    if float(np.median(dt)) <= 0:
        raise BadInputError("the log's time stamps do not increase")
    t, (u, y), step, _ = uniform_grid(t, u, y)  # jitter or gaps: resampled on a uniform grid
    return t, u, y, 1.0 / step


def excited_band_hz(u: np.ndarray, rate_hz: float, rel_level: float = 3e-5) -> float:
    """Top of the input's excited band, Hz: :func:`hasel.ident.freqresp.excited_band` (the one definition).

    On the linearly detrended input (a staircase of offsets would otherwise set the
    reference level) at ``rel_level = 3e-5`` (-45 dB of the 1/8-octave smoothed
    periodogram, not identify's -20 dB): the working rate is chosen from it and must
    carry everything the input holds, not only its main band.
    """
    try:
        return excited_band(signal.detrend(np.asarray(u, float)), rate_hz, rel_level=rel_level)[1]
    except BadInputError:   # a constant input: nothing bounds the band
        return rate_hz / 2


def dominant_time_constant_s(den: np.ndarray) -> float:
    """Slowest time constant of a stable denominator, s (1 / smallest |real part| of its poles; 0 without poles)."""
    p = np.roots(np.asarray(den, float))
    if p.size == 0:
        return 0.0  # a static gain: no dynamics
    re = np.abs(np.real(p[np.abs(p) > 1e-12]))
    return float(1.0 / re.min()) if re.size and re.min() > 0 else float("inf")


def flat_extremes(y: np.ndarray, min_count: int = 5, min_share: float = 0.005,
                  pile_up: float = 3.0) -> dict[str, tuple[float, np.ndarray]]:
    """Ends of the range where a measured signal piles up on one value: the signature of a clip.

    A sensor or a physical limit that clips holds the signal at exactly its extreme value,
    so the samples pile up there: at least ``min_count`` and ``min_share`` of all samples
    sit at the extreme (within a millionth of the range), ``pile_up`` times as many as on
    any other single value in the outer fifth of the range. Noise, quantised or not,
    spreads the samples near an extreme over many values instead.

    Parameters
    ----------
    y : ndarray
        The measured signal.

    Returns
    -------
    dict
        ``{"upper"|"lower": (value, mask of the samples at it)}`` for the ends that clip.
    """
    y = np.asarray(y, float)
    span = float(np.ptp(y)) if y.size else 0.0
    out: dict[str, tuple[float, np.ndarray]] = {}
    if span <= 0:
        return out
    tol = 1e-6 * span
    for end, v in (("upper", float(y.max())), ("lower", float(y.min()))):
        at = np.abs(y - v) <= tol
        n = int(at.sum())
        if n < max(min_count, min_share * y.size):
            continue
        outer = (y >= v - 0.2 * span) if end == "upper" else (y <= v + 0.2 * span)
        _, counts = np.unique(y[outer & ~at], return_counts=True)
        if counts.size == 0 or n >= pile_up * counts.max():
            out[end] = (v, at)
    return out


def _block_mean(x: np.ndarray, q: int) -> np.ndarray:
    n = (x.size // q) * q
    return x[:n].reshape(-1, q).mean(axis=1)


def _interleave(n: int, n_blocks: int) -> tuple[np.ndarray, np.ndarray]:
    """Train/held-out masks: blocks of jittered lengths, one held out per run of three, never two adjacent.

    Which block of each three is held out, and the lengths, are drawn from a fixed seed:
    regular blocks would alias with a periodic excitation (three blocks of a third of a
    period would hold out the same phase every time).
    """
    rng = np.random.default_rng(20240611)
    w = rng.uniform(0.7, 1.3, n_blocks)
    edges = np.concatenate([[0], np.round(np.cumsum(w) / w.sum() * n)]).astype(int)
    hold = np.zeros(n, bool)
    last = -2
    for g in range(0, n_blocks, 3):
        # never two held-out blocks in a row: an event (a step's transient) is then always
        # seen in part by the training data too
        choices = [b for b in range(g, min(g + 3, n_blocks)) if b > last + 1]
        if not choices:
            continue
        b = choices[int(rng.integers(len(choices)))]
        hold[edges[b]:edges[b + 1]] = True
        last = b
    return ~hold, hold


def _split_runs(held: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The contiguous runs of ``held`` dealt alternately to two masks (validation, final)."""
    d = np.diff(np.concatenate([[0], held.astype(int), [0]]))
    a = np.zeros(held.size, bool)
    for k, (s0, s1) in enumerate(zip(np.flatnonzero(d == 1), np.flatnonzero(d == -1))):
        if k % 2 == 0:
            a[s0:s1] = True
    return a, held & ~a


def prepare(t_s: np.ndarray, u: np.ndarray, y: np.ndarray, *, heldout: tuple | None = None,
            model_den: np.ndarray | None = None, target_rate_hz: float | None = None,
            n_blocks: int = 30, max_samples: int = 60_000) -> Prepared:
    """Bring a log (and an optional held-out log) to the working rate and split it.

    Parameters
    ----------
    t_s, u, y : array_like, shape (n,)
        Times (s), input and output of the log.
    heldout : (t_s, u, y), optional
        A separate log for scoring; then all of the first log trains.
    model_den : array_like, optional
        Denominator of the nominal model (not used to set the rate: only the input's
        band is, since poles beyond it are simulated exactly by the hold).
    target_rate_hz : float, optional
        Force the working rate (rounded to a whole decimation factor).
    n_blocks : int
        Fewest interleaved blocks of a self-held-out split (one of every three is held
        out, alternately validating and final); short logs get blocks of about twelve
        samples, up to 240 blocks. With a separate held-out log, the same blocks of the
        first log, the held-out ones validating.
    max_samples : int
        Cap on working samples: the rate is lowered, never below 8 times the band; beyond
        that only the first ``max_samples`` working samples are diagnosed
        (``info["truncated_to_s"]`` says how many seconds).

    Returns
    -------
    Prepared
    """
    t, uu, yy, fs = _uniform(t_s, u, y)
    f_u = excited_band_hz(uu, fs)
    # the model's poles above the excited band need not be resolved: held inputs are
    # simulated exactly by the zero-order hold whatever the rate
    del model_den
    f_bw = f_u
    if target_rate_hz is None:
        target = max(25.0 * f_bw, fs * 2000.0 / t.size)
        span = t[-1] - t[0]
        if target * span > max_samples:
            target = max(max_samples / span, 8.0 * f_bw)
    else:
        target = float(target_rate_hz)
    q = max(1, int(np.floor(fs / target)))
    if target_rate_hz is None and t.size > q * max_samples:
        # rounding fs / target down to a whole factor can leave more than max_samples (a 2 kHz log whose
        # target is 1.2 kHz keeps q = 1), and the tail of the log would be cut: take the smallest factor that
        # fits the whole log, down to the lowest rate the band allows (8 x its top)
        q_fit = int(math.ceil(t.size / max_samples))
        q = max(q, min(q_fit, max(1, int(np.floor(fs / (8.0 * f_bw))))))
    records = []
    hold_log = None
    if heldout is not None:
        th, uh, yh, fsh = _uniform(*heldout)
        if abs(fsh - fs) > 0.01 * fs:
            raise BadInputError(f"the held-out log is sampled at {fsh:g} Hz, the log at {fs:g} Hz; they must match")
        hold_log = (th, uh, yh)
    tw, uw, yw = _block_mean(t, q), _block_mean(uu, q), _block_mean(yy, q)
    truncated = None
    if target_rate_hz is None and tw.size > max_samples:
        # the band does not allow a lower rate: diagnose the first max_samples working samples only
        # (every simulation runs over the whole record, so time grows with its length)
        truncated = float(tw[max_samples - 1] - tw[0])
        tw, uw, yw = tw[:max_samples], uw[:max_samples], yw[:max_samples]
    if hold_log is None:
        # blocks of about a dozen samples in short logs (an event such as a single step is then
        # shared by training and held-out data), up to 240 blocks in long ones
        nb = int(min(max(n_blocks, tw.size // 12), 240, max(6, tw.size // 20)))
        tr, held = _interleave(tw.size, nb)
        va, fi = _split_runs(held)
        records.append(Record(tw, uw, yw, tr, fi, va))
        split = (f"interleaved: one of every three of {nb} blocks held out, the held-out blocks alternately "
                 f"validating (choices) and final (reported)")
    else:
        nb = int(min(max(n_blocks, tw.size // 12), 240, max(6, tw.size // 20)))
        tr, va = _interleave(tw.size, nb)
        records.append(Record(tw, uw, yw, tr, np.zeros(tw.size, bool), va))
        th, uh, yh = (_block_mean(x, q) for x in hold_log)
        records.append(Record(th, uh, yh, np.zeros(th.size, bool), np.ones(th.size, bool)))
        split = "separate held-out log"
    return Prepared(records=records, rate_hz=fs / q, decimation=q, f_excited_hz=f_u, split=split,
                    info={"original_rate_hz": fs, "n_original": int(t.size), "truncated_to_s": truncated},
                    sample_offset=zoh_offset(q))


#: A record's start is unsettled when its input moves by more than this share of its range within the
#: model's slowest time constant of the first sample (a closed loop's first commands, a log cut mid-run).
START_MOVE_SHARE = 1e-3
#: ... and its first output is further from the model at rest with the first input than this share of the
#: output's range ...
START_GAP_SHARE = 0.05
#: ... and than this many times the rms of that simulation's residual after the first :data:`START_BURN_TAUS` time
#: constants (so "at rest with the first input before the log" is contradicted by the start, not by an effect that
#: bends the whole log: a map or a drift gives a start gap of the size of the residual everywhere). Set on the
#: tuning logs: those that start at rest with their first input (bench/tune_diag's sets, effects of every family)
#: reach 5.0 (combos.py seed 21 combo_16), the first corpus's closed-loop logs 7.0 (a large input map beside) to 430.
START_GAP_RMS = 6.0
#: Unsettled starts: the first this many slowest time constants are left out of every score (the state before
#: the log is a guess, and a wrong guess decays over them).
START_BURN_TAUS = 3.0


def rest_start(prep: Prepared, num: np.ndarray, den: np.ndarray) -> list[dict]:
    """Where a record starts unsettled, the rest before it is read from its first output (records changed in place).

    Every simulation here starts at rest with its first input sample. A closed-loop log whose controller
    commands 9 kV at its first sample while the stroke is still 0 mm contradicts that: the model starts
    12 mm off and every effect is judged on a transient that is an artefact of the assumed start. Where
    the input moves within the model's slowest time constant (:data:`START_MOVE_SHARE`) and the first
    output is far from the model at rest with the first input (:data:`START_GAP_SHARE` of the output's
    range and :data:`START_GAP_RMS` times the residual's rms after the start), one working sample is put
    before the record at the input level whose steady output under the model (``num``/``den``, input unit
    to output unit) is the first output (within the input's range widened by that range on either side),
    and the first :data:`START_BURN_TAUS` slowest time constants are left out of training, validation and
    final scores (the level is the linear model's, not the augmented chain's). Returns one note per
    changed record: ``record``, ``level`` (input unit), ``first_input``, ``left_out_s``.
    """
    num = np.atleast_1d(np.asarray(num, float))
    den = np.atleast_1d(np.asarray(den, float))
    g0 = float(np.polyval(num, 0.0) / np.polyval(den, 0.0)) if np.polyval(den, 0.0) != 0 else float("nan")
    tau = dominant_time_constant_s(den)
    if not (math.isfinite(g0) and g0 != 0.0 and math.isfinite(tau)):
        return []
    dt = prep.dt_s
    n_tau = max(3, int(math.ceil(tau / dt)))
    notes = []
    sim = None  # built only where a start is unsettled
    for i, r in enumerate(prep.records):
        if r.u.size < 4 * n_tau:
            continue
        u_rng, y_rng = float(np.ptp(r.u)), float(np.ptp(r.y))
        moves = float(np.ptp(r.u[:n_tau])) > START_MOVE_SHARE * u_rng
        y0 = float(r.y[0])
        gap = abs(y0 - g0 * float(r.u[0]))
        if not (moves and y_rng > 0 and gap > START_GAP_SHARE * y_rng):
            continue
        n_burn = min(int(math.ceil(START_BURN_TAUS * tau / dt)), r.u.size // 4)
        sim = sim or prep.sim(num, den)
        e = r.y - sim.run(r.u)
        if not gap > START_GAP_RMS * math.sqrt(float(np.mean(e[n_burn:] ** 2))):
            continue
        # bounded to the input's range widened by that range on either side (an output offset reads as a level)
        level = float(np.clip(y0 / g0, np.min(r.u) - u_rng, np.max(r.u) + u_rng))
        keep = np.ones(r.u.size, bool)
        keep[:n_burn] = False
        pre = np.zeros(1, bool)
        prep.records[i] = Record(np.concatenate([[r.t_s[0] - dt], r.t_s]), np.concatenate([[level], r.u]),
                                 np.concatenate([[y0], r.y]), np.concatenate([pre, r.train & keep]),
                                 np.concatenate([pre, r.hold & keep]), np.concatenate([pre, r.valid & keep]))
        notes.append({"record": i, "level": level, "first_input": float(r.u[0]), "left_out_s": n_burn * dt})
    return notes


def zoh_offset(q: int) -> float:
    """The output sampling point (working samples into each interval) of the zero-order-hold convention for block
    means of ``q`` original samples: the block's output sits ``(q - 1) / 2`` original samples into the interval over
    which its mean input is held."""
    return (q - 1) / (2.0 * q)


#: Exact fractional-offset discretisations already built: ``(sos, zi, d)`` by model, rate and offset.
_FRAC_CACHE: dict = {}


@dataclass(frozen=True)
class StartRun:
    """Interval-start outputs of one simulation (:meth:`LinearSim.run_start`), with the model and input
    that made them, so that the output between interval starts can be read exactly.

    Attributes
    ----------
    ys : ndarray
        The ``n + 1`` interval-start outputs (the last one after ``u[-1]``'s interval), times
        ``scale``; output units.
    sim : LinearSim or None
        The simulation, when it reads exactly (:class:`hasel.lti.ZohAt`); ``None``: outputs between
        interval starts are interpolated linearly (a model fitted that way).
    u : ndarray or None
        The held input (input units), with ``sim``.
    scale : float
        The factor the model's outputs were multiplied by (a fitted gain).
    cache : dict
        The model's states for ``u`` and Gram matrices (:func:`estimate_timing`), shared by scaled copies.
    """

    ys: np.ndarray
    sim: "LinearSim | None" = None
    u: "np.ndarray | None" = None
    scale: float = 1.0
    cache: dict = field(default_factory=dict, compare=False, repr=False)

    def scaled(self, k: float) -> "StartRun":
        """The same run times the scalar ``k`` (states and Gram matrices shared)."""
        return StartRun(float(k) * self.ys, self.sim, self.u, self.scale * float(k), self.cache)


class LinearSim:
    """Simulate a continuous transfer function on working-rate samples (input held over each interval).

    The input sample ``u[k]`` is held over the interval ``[t_k, t_{k+1})`` (a zero-order
    hold, as a DAC or a controller holding its command). The output sample ``k`` is the
    continuous output at ``t_k + offset dt``: ``offset = 0`` is the plain zero-order-hold
    convention (output sampled when input ``k`` starts, so it depends on inputs before
    ``k`` only); ``0.5`` is centred on the interval (block means, or a first-order hold,
    which leads a held input by half a sample); negative values sample earlier (an output
    that lags). Between the interval's ends the output is exact for the held input
    (:class:`hasel.lti.ZohAt`: ``C e^{A a T} x_k + (C Gamma(a) + D) u_k``, one filter as cheap
    as the interval-start one); ``offset = 0`` is exactly the interval-start simulation.

    Parameters
    ----------
    num, den : array_like
        The model, descending powers of s.
    rate_hz : float
        Working rate, Hz.
    offset : float
        Where in the interval the output is taken, in working samples (-1 to 1).
    exact : bool
        Read the output at ``offset`` exactly (:class:`hasel.lti.ZohAt`); False: interpolate
        linearly between interval starts (the simulation of :mod:`hasel.ident.timefit`, for a
        model identified with it), and :meth:`run_start` returns a plain array.
    """

    def __init__(self, num: np.ndarray, den: np.ndarray, rate_hz: float, offset: float = 0.0,
                 exact: bool = True) -> None:
        num = np.atleast_1d(np.asarray(num, float))
        den = np.atleast_1d(np.asarray(den, float))
        if num.size > den.size:
            raise BadInputError("the model must be proper (deg num <= deg den)")
        p = np.roots(den)
        if np.any(np.real(p) >= 0):
            raise BadInputError("the nominal model must be stable (all poles in the left half-plane) "
                                f"to be simulated; poles {np.round(p, 4).tolist()}")
        if not (math.isfinite(offset) and -1.0 <= offset <= 1.0):
            raise BadInputError(f"the output sampling offset must be within one sample, got {offset}")
        self.num, self.den, self.offset = num, den, float(offset)
        self.dc_gain = float(np.polyval(num, 0.0) / np.polyval(den, 0.0))
        num = np.trim_zeros(num, "f") if np.any(num) else num[-1:]
        self._model = (num, den, float(rate_hz))
        self._sos = self._zi = None
        self._frac = None
        self.exact = bool(exact)
        if self.exact and self.offset != 0.0:
            self._frac = self._build_frac(self.offset)
        if self._frac is None:
            self._build_zoh()   # (otherwise it is built only if run_start is called)

    def _build_zoh(self) -> None:
        """The zero-order-hold discretisation (``sos``, interval-start outputs) at the working rate."""
        num, den, rate_hz = self._model
        try:
            with np.errstate(all="ignore"), warnings.catch_warnings():
                warnings.simplefilter("ignore", signal.BadCoefficients)
                sos = zoh_sos(num, den, 1.0 / rate_hz, output="start")
            if not np.all(np.isfinite(sos)):
                raise ValueError("non-finite sections")
        except (StopIteration, ValueError, np.linalg.LinAlgError):
            # zeros at s = 0 or extreme pole spreads: plain ZOH through the polynomial form
            with np.errstate(all="ignore"), warnings.catch_warnings():
                warnings.simplefilter("ignore", signal.BadCoefficients)
                numd, dend, _ = signal.cont2discrete((num, den), 1.0 / rate_hz, method="zoh")
                sos = signal.tf2sos(np.atleast_1d(np.squeeze(numd)), dend)
            if not np.all(np.isfinite(sos)):
                raise BadInputError("the model cannot be discretised at the working rate (non-finite result)")
        self._sos, self._zi = sos, signal.sosfilt_zi(sos)

    def _zohat(self) -> ZohAt:
        """The model's :class:`hasel.lti.ZohAt` at the working rate (built once)."""
        z = getattr(self, "_zohat_obj", None)
        if z is None:
            num, den, rate_hz = self._model
            z = self._zohat_obj = ZohAt(num, den, 1.0 / rate_hz)
        return z

    def _build_frac(self, offset: float):
        """``(sos, zi, d, shift)`` of the exact output ``offset`` working samples into the interval, or ``None``.

        ``0 < offset <= 1``: the output at ``t_k + offset dt``; ``-1 <= offset < 0``: the output at
        ``t_{k-1} + (1 + offset) dt`` (``shift`` = 1: one sample later, at rest before).
        """
        num, den, rate_hz = self._model
        key = (num.tobytes(), den.tobytes(), float(rate_hz), float(offset))
        got = _FRAC_CACHE.get(key)
        if got is not None:
            return got
        a, shift = (float(offset), 0) if offset >= 0.0 else (1.0 + float(offset), 1)
        try:
            with np.errstate(all="ignore"), warnings.catch_warnings():
                warnings.simplefilter("ignore", signal.BadCoefficients)
                sos, d = self._zohat().parts(a)
                zi = signal.sosfilt_zi(sos) if sos is not None else None
            if sos is not None and not (np.all(np.isfinite(sos)) and np.all(np.isfinite(zi))):
                return None
            if not math.isfinite(d):
                return None
        except (BadInputError, ValueError, np.linalg.LinAlgError, StopIteration):
            return None   # the interval-start simulation interpolated linearly (below)
        got = (sos, zi, d, shift)
        if len(_FRAC_CACHE) > 256:
            _FRAC_CACHE.clear()
        _FRAC_CACHE[key] = got
        return got

    def _run_frac(self, u: np.ndarray, frac) -> np.ndarray:
        """Run the exact fractional-offset discretisation ``frac`` (from :meth:`_build_frac`) on ``u``."""
        sos, zi, d, shift = frac
        u = np.asarray(u, float)
        x = np.concatenate([u[:1], u[:-1]]) if shift else u
        if sos is None:
            return d * x
        y, _ = signal.sosfilt(sos, x, zi=zi * u[0])
        return y + d * x

    @property
    def sos(self) -> np.ndarray:
        """Second-order sections of the zero-order-hold discretisation (interval-start outputs)."""
        if self._sos is None:
            self._build_zoh()
        return self._sos

    def run_start(self, u: np.ndarray) -> StartRun:
        """Output at the interval starts for input ``u``, ``n + 1`` samples (the last one after
        ``u[-1]``'s interval), with this simulation when it reads exactly (:class:`StartRun`)."""
        u = np.asarray(u, float)
        x = np.concatenate([u, u[-1:]])
        sos = self.sos
        ys, _ = signal.sosfilt(sos, x, zi=self._zi * u[0])
        return StartRun(ys, self, u) if self.exact else StartRun(ys)

    def run(self, u: np.ndarray) -> np.ndarray:
        """Output at the working samples for input ``u`` (at rest with ``u[0]`` before), mm for kV.

        The input is held over each interval and the output read ``offset`` into it: exactly
        (:class:`hasel.lti.ZohAt`) when that discretisation could be built, else by linear
        interpolation between interval starts.
        """
        if self._frac is not None:
            return self._run_frac(u, self._frac)
        return np.asarray(at_offset(self.run_start(u), self.offset))


def at_offset(ys: "StartRun | np.ndarray", offset: float) -> np.ndarray:
    """Samples ``k + offset`` (``-1 <= offset <= 1``) of ``n + 1`` interval-start outputs ``ys``, ``n`` values.

    For a :class:`StartRun` that carries its simulation and ``offset != 0``: the model's exact
    output at that point for the input held over each interval (:class:`hasel.lti.ZohAt`; the
    same numbers as ``LinearSim(..., offset).run``, to rounding once :func:`estimate_timing` has
    filtered the states of this run, bit for bit before). Otherwise (a plain array, or a run
    without its simulation): linear interpolation between neighbours (exact only to second
    order: 6.3 um rms off for P(s) at 100 Hz). Before the first sample the output is at rest.
    Output unit of ``ys``.
    """
    if isinstance(ys, StartRun):
        run, ys = ys, ys.ys
        if run.sim is not None and offset != 0.0:
            sim, u = run.sim, run.u
            X = run.cache.get("X")
            if X is not None:   # the states are there already (the timing estimate): one row, no new filter
                c, d = sim._zohat().rows(offset if offset > 0 else 1.0 + offset)
                if offset > 0:
                    return run.scale * (X @ c + d * u)
                return run.scale * np.concatenate([[X[0] @ c + d * u[0]], X[:-1] @ c + d * u[:-1]])
            frac = sim._build_frac(float(offset))
            if frac is not None:
                return run.scale * sim._run_frac(u, frac)
    ys = np.asarray(ys)
    if offset >= 0.0:
        return ys[:-1] + offset * (ys[1:] - ys[:-1])
    prev = np.concatenate([ys[:1], ys[:-2]])
    return ys[:-1] + offset * (ys[:-1] - prev)


def _timing_linear(ys: np.ndarray, y: np.ndarray, mask: np.ndarray, lo: float, hi: float) -> tuple[float, float]:
    """:func:`estimate_timing` on the linear interpolation between interval starts (closed form per side)."""
    best = (0.0, float("inf"))
    for side_lo, side_hi in ((max(lo, 0.0), hi), (lo, min(hi, 0.0))):
        if side_lo > side_hi:
            continue
        a_mid = 0.5 * (side_lo + side_hi)
        base = at_offset(ys, 0.0)[mask]
        d = (at_offset(ys, 1.0 if a_mid >= 0 else -1.0)[mask] - base) * (1.0 if a_mid >= 0 else -1.0)
        r = y[mask] - base
        rc, dc = r - r.mean(), d - d.mean()
        a = float(rc @ dc / max(dc @ dc, 1e-300))
        a = min(max(a, side_lo), side_hi)
        e = rc - a * dc
        sse = float(e @ e)
        if sse < best[1]:
            best = (a, sse)
    return best


def _timing_exact(run: StartRun, y: np.ndarray, mask: np.ndarray, lo: float,
                  hi: float) -> tuple[float, float] | None:
    """:func:`estimate_timing` on the model's exact output between interval starts (``None``: not available).

    The output ``a`` into the interval is ``c(a) . x_k + d(a) u_k`` (:meth:`hasel.lti.ZohAt.rows`,
    the states ``x_k`` filtered once per model and input); with the output offset removed the
    residual sum of squares is then a small quadratic form in ``(c(a), d(a))`` (a Gram matrix of
    the masked, centred states and input), so each trial offset costs one small matrix
    exponential. Per side of zero (a held input changes there), a grid of 1/10 sample, then a
    bounded scalar search (to 1e-4 sample) around the best grid point.
    """
    sim, u, cache = run.sim, run.u, run.cache
    k = run.scale
    try:
        z = sim._zohat()
        if "X" not in cache:
            with np.errstate(all="ignore"):
                X = z.states(u)
            cache["X"] = X if np.all(np.isfinite(X)) else None
        X = cache["X"]
        if X is None:
            return None
        m = np.asarray(mask, bool)
        key = ("gram", m.tobytes())
        if key not in cache:
            # the states for a >= 0 (x_k, u_k) and for a < 0 (x_{k-1}, u_{k-1}, at rest before the start)
            phi_p = np.column_stack([X, u])
            phi_n = np.vstack([phi_p[:1], phi_p[:-1]])
            grams = []
            for phi in (phi_p, phi_n):
                pc = phi[m] - phi[m].mean(axis=0)
                grams.append((pc.T @ pc, pc))
            cache[key] = grams
        grams = cache[key]
    except (BadInputError, ValueError, np.linalg.LinAlgError, StopIteration):
        return None
    yc = np.asarray(y, float)[mask]
    yc = yc - yc.mean()
    yy = float(yc @ yc)

    def side_cost(g, b):
        def cost(a: float) -> float:
            c, d = z.rows(a)
            w = k * np.concatenate([c, [d]])
            return yy - 2.0 * float(w @ b) + float(w @ g @ w)
        return cost

    best = None
    for (side_lo, side_hi), (g, pc), sign in (((max(lo, 0.0), hi), grams[0], 1), ((lo, min(hi, 0.0)), grams[1], -1)):
        if side_lo > side_hi:
            continue
        b = pc.T @ yc
        cost = side_cost(g, b)
        to_a = (lambda t: t) if sign > 0 else (lambda t: 1.0 + t)   # the fraction into the (previous) interval
        if side_hi - side_lo < 1e-12:
            cands = [(cost(to_a(side_lo)), side_lo)]
        else:
            count = max(3, int(math.ceil((side_hi - side_lo) * 10)) + 1)
            grid = np.linspace(side_lo, side_hi, count)
            cg, dg = z.rows_grid(to_a(side_lo), float(grid[1] - grid[0]), count)
            w = k * np.column_stack([cg, dg])
            cs = yy - 2.0 * (w @ b) + np.einsum("ij,jk,ik->i", w, g, w)
            i = int(np.argmin(cs))
            cands = [(float(cs[i]), float(grid[i]))]
            lo_t, hi_t = grid[max(i - 1, 0)], grid[min(i + 1, grid.size - 1)]
            if hi_t > lo_t:
                res = optimize.minimize_scalar(lambda t: cost(to_a(t)), bounds=(lo_t, hi_t), method="bounded",
                                               options={"xatol": 1e-4})
                cands.append((float(res.fun), float(res.x)))
        c_best = min(cands)
        if best is None or c_best[0] < best[1]:
            best = (c_best[1], c_best[0])
    if best is None or not math.isfinite(best[1]):
        return None
    return best[0], max(best[1], 0.0)


def estimate_timing(ys: "StartRun | np.ndarray", y: np.ndarray, mask: np.ndarray, lo: float,
                    hi: float) -> tuple[float, float]:
    """Output sampling offset (working samples, within ``[lo, hi]``) that best fits ``y`` on ``mask``.

    ``ys`` are the model's interval-start outputs (``n + 1``: a :class:`StartRun` of
    :meth:`LinearSim.run_start`, possibly :meth:`StartRun.scaled`, or a plain array), ``y`` the
    measured output (its unit); an output offset is fitted alongside (a nuisance too). For a run
    that carries its simulation the model's output at each trial offset is exact for the held
    input (:func:`_timing_exact`: a grid and a bounded scalar search per side of zero); otherwise
    the linear interpolation between interval starts, piecewise linear in the offset, is fitted
    in closed form per side.

    Returns
    -------
    (offset, sse) : the offset (working samples) and the residual sum of squares there (output unit squared).
    """
    if isinstance(ys, StartRun):
        if ys.sim is not None:
            got = _timing_exact(ys, y, mask, lo, hi)
            if got is not None:
                return got
        ys = ys.ys
    return _timing_linear(np.asarray(ys, float), y, mask, lo, hi)


def estimate_noise(r: np.ndarray, rate_hz: float, f_excited_hz: float) -> tuple[float, str]:
    """Noise variance (output unit squared) in a residual ``r`` at the working rate.

    Returns the variance and the method: ``"spectral"`` (median residual spectrum
    above ``3 f_excited`` times the working band, for white noise) or
    ``"differences"`` (``var(diff(r, 3)) / 20``, exact for white noise on a smooth
    signal, an upper bound otherwise).
    """
    r = signal.detrend(np.asarray(r, float))
    nper = int(min(r.size, 1024))
    f, p = signal.welch(r, fs=rate_hz, nperseg=nper)
    band = f >= 3.0 * f_excited_hz
    if band.sum() >= 8 and 3.0 * f_excited_hz < 0.4 * rate_hz:
        # the median of a Welch estimate (chi-square with 2K dof over 2K) is below its mean
        k = max(1.0, 2.0 * r.size / nper - 1.0)
        bias = float(stats.chi2.median(2.0 * k) / (2.0 * k))
        return float(np.median(p[band]) / bias * rate_hz / 2.0), "spectral"
    d3 = np.diff(r, 3)
    return float(np.var(d3) / 20.0), "differences"


def noise_trust(r: np.ndarray, rate_hz: float, f_excited_hz: float, sigma2: float, method: str) -> dict:
    """How far to trust a noise estimate ``sigma2`` of residual ``r`` (the verdict's ``noise`` entry).

    Two checks of the white-noise assumption behind the estimate: the slope of the residual's
    spectrum over the band above the excitation (coloured noise rises towards the band, so
    the level above it under-states the noise in it), and the slow part of the residual
    (a moving average over a second: a sensor offset wander or a drift, which no spectral
    level above the band sees). Either makes the floor a lower bound; effects are then
    accepted only on the held-out block test, which does not use the floor. ``trust`` says
    so in words ("low: ..." or "good: ..."), ``trust_notes`` lists the reasons (empty when good).
    """
    r = signal.detrend(np.asarray(r, float))
    out = {"estimator": {"spectral": "median residual spectrum above 3x the excited band (white noise assumed)",
                         "differences": "variance of third differences / 20 (white noise on a smooth signal; an "
                                        "upper bound otherwise)"}.get(method, method),
           "rms": math.sqrt(max(sigma2, 0.0)), "repeats_used": False}
    notes = []
    nper = int(min(r.size, 1024))
    f, p = signal.welch(r, fs=rate_hz, nperseg=nper)
    lo = (f >= 3.0 * f_excited_hz) & (f < 6.0 * f_excited_hz)
    hi = f >= 0.5 * f.max()
    if method == "spectral" and lo.sum() >= 3 and hi.sum() >= 3:
        ratio = float(np.median(p[lo]) / max(np.median(p[hi]), 1e-300))
        out["spectrum_slope_ratio"] = ratio
        if ratio > 2.0:
            notes.append(f"the noise is coloured (its spectrum just above the band is {ratio:.3g} x its level at "
                         f"the top): the floor under-states the noise in the band")
    n = max(1, int(round(rate_hz)))
    if r.size > 4 * n:
        slow = np.convolve(r, np.ones(n) / n, mode="valid")
        slow_ratio = float(np.var(slow) / max(sigma2 / n, 1e-300))
        out["slow_over_white"] = slow_ratio
        if slow_ratio > 20.0 and float(np.var(slow)) > 0.1 * sigma2:
            notes.append("the residual has a slow part well above what white noise gives (a sensor offset wander "
                         "or a drift): the floor leaves it out")
    out["trust"] = "low: " + "; ".join(notes) if notes else "good: the residual above the band is white and has no " \
                                                            "slow excess"
    # the reasons also as a list: a reader (the report) takes them from here, not by cutting the text above
    out["trust_notes"] = notes
    return out
