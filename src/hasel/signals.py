"""Excitation signals for identification, the paper's whole chirp campaign, and resampling.

Three excitations, all sampled at a given rate:

- :func:`paper_chirp`: the paper's formula (4)-(5), ``v = A sin(2 pi f(t) t)`` with
  ``f(t) = (f_f - f_0) t / t_tot``. Its phase is ``2 pi k t^2`` (``k`` the slope), so
  its *instantaneous* frequency is ``2 k t``: it sweeps from 0 Hz up to about
  ``2 f_f`` (40 Hz for Table I), and ``f_0`` drops out. This is what the paper's
  equations describe, so it is the default of :func:`protocol_schedule`.
- :func:`linear_chirp`: the textbook linear sweep, instantaneous frequency from
  ``f_0`` to ``f_1`` over ``duration_s``.
- :func:`odd_multisine`: a random-phase odd multisine (Pintelon & Schoukens): only
  odd harmonics of ``1/period`` are excited and one odd line in every group of
  consecutive odd lines is left out as a detection line. In the response, power at
  the non-excited odd lines reveals odd nonlinear distortion, power at the even lines
  even distortion, and the noise floor is their level in a linear system.

:func:`protocol_schedule` builds a whole campaign (Table I): for each DC offset a
charge-reversing pre-conditioning hold, a settling hold at the offset, then the
excitation repeated back to back, as one command array (kV) with segment records.

:func:`uniform_grid` puts irregularly sampled records on a uniform time grid (the one
resampler of identification and diagnosis).
"""
from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from hasel import paper
from hasel.errors import BadInputError, UnsafeParameterError
from hasel.validate import finite, positive

__all__ = [
    "paper_chirp", "linear_chirp", "Multisine", "odd_multisine", "SegmentRecord", "Schedule",
    "protocol_schedule", "EXCITATION_KINDS", "uniform_grid", "JITTER_TOLERANCE",
]

#: Largest step deviation, relative to the median step, still taken as uniform sampling.
JITTER_TOLERANCE = 0.01

#: Names accepted by ``protocol_schedule(kind=...)``.
EXCITATION_KINDS = ("paper", "linear", "multisine")


def _times(t: np.ndarray | Sequence[float]) -> np.ndarray:
    arr = np.asarray(t, dtype=float)
    if arr.ndim != 1 or not np.all(np.isfinite(arr)):
        raise BadInputError("t must be a 1-D array of finite times (s)")
    return arr


def paper_chirp(t: np.ndarray | Sequence[float], f0_hz: float, f1_hz: float, duration_s: float,
                amplitude: float = 1.0) -> np.ndarray:
    """The paper's chirp (4)-(5): ``A sin(2 pi f(t) t)``, ``f(t) = (f1 - f0) t / duration``.

    Parameters
    ----------
    t : array_like, shape (n,)
        Times from the start of the chirp, s.
    f0_hz, f1_hz : float
        The paper's ``f_0`` and ``f_f``, Hz.
    duration_s : float
        The paper's ``t_tot``, s.
    amplitude : float
        ``A``, in the unit of the result (kV in the paper).

    Returns
    -------
    ndarray, shape (n,)
        The chirp at ``t``.

    Notes
    -----
    The phase is ``2 pi k t^2`` with ``k = (f1 - f0) / duration``, so the
    instantaneous frequency is ``2 k t``: the sweep starts at 0 Hz (not ``f0``) and
    ends near ``2 f1`` (40 Hz for the paper's 20 Hz). Use :func:`linear_chirp` for a
    sweep that really goes from ``f0`` to ``f1``.

    Examples
    --------
    >>> import numpy as np
    >>> t = np.arange(0, 20, 1e-4)
    >>> v = paper_chirp(t, 0.001, 20.0, 20.0)
    >>> round(float(np.max(np.abs(v))), 3)
    1.0
    """
    tt = _times(t)
    duration_s = positive("duration_s", duration_s)
    k = (finite("f1_hz", f1_hz) - finite("f0_hz", f0_hz)) / duration_s
    return finite("amplitude", amplitude) * np.sin(2.0 * np.pi * k * tt * tt)


def linear_chirp(t: np.ndarray | Sequence[float], f0_hz: float, f1_hz: float, duration_s: float,
                 amplitude: float = 1.0) -> np.ndarray:
    """Linear sweep whose instantaneous frequency goes from ``f0_hz`` to ``f1_hz``.

    ``A sin(2 pi (f0 t + (f1 - f0) t^2 / (2 duration)))``, so that
    ``d(phase)/dt / 2 pi = f0 + (f1 - f0) t / duration``.

    Parameters
    ----------
    t : array_like, shape (n,)
        Times from the start of the sweep, s.
    f0_hz, f1_hz : float
        Start and end instantaneous frequencies, Hz.
    duration_s : float
        Sweep duration, s.
    amplitude : float
        Amplitude, in the unit of the result.

    Returns
    -------
    ndarray, shape (n,)
    """
    tt = _times(t)
    duration_s = positive("duration_s", duration_s)
    f0 = finite("f0_hz", f0_hz)
    k = (finite("f1_hz", f1_hz) - f0) / duration_s
    return finite("amplitude", amplitude) * np.sin(2.0 * np.pi * (f0 * tt + 0.5 * k * tt * tt))


@dataclass(frozen=True)
class Multisine:
    """One period of an odd random-phase multisine.

    Attributes
    ----------
    signal : ndarray, shape (n,)
        One period, sampled at ``rate_hz``; repeat it (``np.tile``) for more periods.
    rate_hz : float
        Sample rate, Hz.
    period_s : float
        Period, s; the frequency grid is ``k / period_s``.
    excited : ndarray of int
        Harmonic indices ``k`` that carry power (all odd).
    detection_odd : ndarray of int
        Odd harmonics inside the band deliberately left out (detection lines).
    phases_rad : ndarray
        Phase of each excited line, rad.
    """

    signal: np.ndarray
    rate_hz: float
    period_s: float
    excited: np.ndarray
    detection_odd: np.ndarray
    phases_rad: np.ndarray

    @property
    def excited_hz(self) -> np.ndarray:
        """Frequencies of the excited lines, Hz."""
        return self.excited / self.period_s


def odd_multisine(rate_hz: float, period_s: float, f_min_hz: float, f_max_hz: float, *,
                  amplitude: float = 1.0, group_size: int = 4, log_spaced: bool = False,
                  rng: np.random.Generator | None = None) -> Multisine:
    """Odd random-phase multisine with one detection line per group of odd lines.

    Parameters
    ----------
    rate_hz : float
        Sample rate, Hz; ``rate_hz * period_s`` must be a whole number of samples.
    period_s : float
        Period, s (frequency resolution ``1 / period_s``).
    f_min_hz, f_max_hz : float
        Band of excited lines, Hz (``f_max_hz`` below the Nyquist frequency).
    amplitude : float
        Peak value of the signal (the lines have equal amplitudes, scaled so that
        ``max |signal| == amplitude``), in the unit of the result.
    group_size : int
        Consecutive odd lines per group; one of each group, chosen at random, is
        left out (``group_size >= 2``).
    log_spaced : bool
        If true, groups grow with frequency (about ``group_size`` groups per octave)
        so that a wide band is not dominated by its high-frequency lines; the excited
        lines stay odd and there is still one detection line per group.
    rng : numpy.random.Generator, optional
        Source of the random phases and detection lines (seed it for reproducibility).

    Returns
    -------
    Multisine

    Raises
    ------
    BadInputError
        If the band holds too few odd lines or the period is not a whole number of samples.
    """
    rate_hz = positive("rate_hz", rate_hz)
    period_s = positive("period_s", period_s)
    f_min_hz = positive("f_min_hz", f_min_hz)
    f_max_hz = positive("f_max_hz", f_max_hz)
    if group_size < 2:
        raise BadInputError(f"group_size must be >= 2, got {group_size}")
    n = round(rate_hz * period_s)
    if abs(n - rate_hz * period_s) > 1e-6 * n or n < 4:
        raise BadInputError(f"rate_hz * period_s must be a whole number of samples >= 4, got {rate_hz * period_s}")
    if f_max_hz >= rate_hz / 2 or f_min_hz >= f_max_hz:
        raise BadInputError(f"need 0 < f_min_hz < f_max_hz < rate_hz/2, got {f_min_hz}, {f_max_hz}, {rate_hz}")
    rng = rng if rng is not None else np.random.default_rng()
    k_lo, k_hi = int(np.ceil(f_min_hz * period_s)), int(np.floor(f_max_hz * period_s))
    odd = np.arange(k_lo + (1 - k_lo % 2), k_hi + 1, 2)
    if odd.size < group_size:
        raise BadInputError(f"the band {f_min_hz}-{f_max_hz} Hz holds only {odd.size} odd lines of "
                            f"1/{period_s} s; widen it or lengthen the period")
    if log_spaced:
        # group boundaries at a geometric progression: about group_size groups per octave
        edges = np.unique(np.searchsorted(odd, odd[0] * 2.0 ** (np.arange(0, 64) / group_size)))
        edges = edges[edges < odd.size]
        groups = [odd[a:b] for a, b in zip(edges, list(edges[1:]) + [odd.size])]
    else:
        groups = [odd[i:i + group_size] for i in range(0, odd.size, group_size)]
    dropped = [g[rng.integers(g.size)] for g in groups if g.size >= 2]
    excited = np.setdiff1d(odd, dropped)
    phases = rng.uniform(0.0, 2.0 * np.pi, excited.size)
    spectrum = np.zeros(n // 2 + 1, complex)
    spectrum[excited] = np.exp(1j * phases)
    x = np.fft.irfft(spectrum, n)
    x *= finite("amplitude", amplitude) / np.max(np.abs(x))
    return Multisine(signal=x, rate_hz=rate_hz, period_s=period_s, excited=excited,
                     detection_odd=np.asarray(sorted(dropped), int), phases_rad=phases)


@dataclass(frozen=True)
class SegmentRecord:
    """One part of a campaign.

    Attributes
    ----------
    start_s, end_s : float
        Times of the first sample and just after the last sample, s.
    offset : float
        DC level of the part (kV): the operating point, or the pre-conditioning level.
    kind : str
        ``"precondition"``, ``"settle"`` or ``"excitation"``.
    excitation : str
        For ``"excitation"`` parts, the excitation used: ``"paper"`` (the paper's
        chirp formula), ``"linear"`` or ``"multisine"``; ``""`` otherwise.
    """

    start_s: float
    end_s: float
    offset: float
    kind: str
    excitation: str = ""


@dataclass(frozen=True)
class Schedule:
    """A whole campaign: the command, its sample times and its parts.

    Attributes
    ----------
    t_s : ndarray
        Sample times from 0, s.
    command_kv : ndarray
        Commanded voltage, kV.
    rate_hz : float
        Sample rate, Hz.
    records : list of SegmentRecord
        The parts in time order.
    """

    t_s: np.ndarray
    command_kv: np.ndarray
    rate_hz: float
    records: list[SegmentRecord]

    def markers(self) -> list[tuple[float, float, float]]:
        """``(t_start_s, t_end_s, offset_kv)`` of the excitation parts (for ``identify(segments=...)``)."""
        return [(r.start_s, r.end_s, r.offset) for r in self.records if r.kind == "excitation"]


def protocol_schedule(offsets_kv: Sequence[float] = paper.CHIRP_PROTOCOL["offsets_kv"],
                      amplitude_kv: float = paper.CHIRP_PROTOCOL["amplitude_kv"],
                      f0_hz: float = paper.CHIRP_PROTOCOL["f0_hz"],
                      f1_hz: float = paper.CHIRP_PROTOCOL["f1_hz"],
                      duration_s: float = paper.CHIRP_PROTOCOL["duration_s"],
                      repeats: int = paper.CHIRP_PROTOCOL["repeats"],
                      rate_hz: float = paper.CHIRP_PROTOCOL["rate_hz"],
                      kind: str = "paper",
                      precondition_kv: float = paper.CHIRP_PROTOCOL["precondition_kv"],
                      precondition_s: float = 2.0,
                      settle_s: float = 0.0,
                      rng: np.random.Generator | None = None) -> Schedule:
    """The paper's identification campaign (Table I) as one command array, kV.

    For each offset ``v_s``: ``precondition_kv`` held for ``precondition_s`` (charge
    reversal), ``v_s`` held for ``settle_s``, then ``v_s`` plus the excitation
    repeated ``repeats`` times back to back. Defaults: Table I (offsets 2..7 kV,
    A = 1 kV, f_0 = 0.001 Hz, f_f = 20 Hz, 20 s, three chirps, 10 kHz, -1 kV before
    each test); the paper gives no pre-conditioning duration and no settling hold.

    Parameters
    ----------
    offsets_kv : sequence of float
        Operating points ``v_s``, kV.
    amplitude_kv : float
        Excitation amplitude ``A`` (peak), kV.
    f0_hz, f1_hz : float
        Band of the excitation, Hz (for ``kind="paper"``, the formula's ``f_0``/``f_f``).
    duration_s : float
        Length of one excitation (the chirp's ``t_tot`` or the multisine's period), s.
    repeats : int
        Excitations back to back per offset.
    rate_hz : float
        Sample rate, Hz.
    kind : {"paper", "linear", "multisine"}
        The paper's chirp formula, a true linear chirp, or an odd random-phase
        multisine (peak ``amplitude_kv``).
    precondition_kv : float
        Level held before each test, kV (the paper: -1 kV reverses accumulated charge).
    precondition_s : float
        Duration of that hold, s (0 to skip it).
    settle_s : float
        Hold at the offset before the excitation starts, s.
    rng : numpy.random.Generator, optional
        For the multisine's phases.

    Returns
    -------
    Schedule

    Raises
    ------
    UnsafeParameterError
        If any commanded voltage would exceed the breakdown ceiling (9 kV).
    BadInputError
        For other invalid arguments.
    """
    if kind not in EXCITATION_KINDS:
        raise BadInputError(f"kind must be one of {EXCITATION_KINDS}, got {kind!r}")
    offsets = [finite("offsets_kv", v) for v in offsets_kv]
    if not offsets:
        raise BadInputError("offsets_kv must hold at least one offset")
    amplitude_kv = finite("amplitude_kv", amplitude_kv)
    rate_hz = positive("rate_hz", rate_hz)
    duration_s = positive("duration_s", duration_s)
    precondition_kv = finite("precondition_kv", precondition_kv)
    if precondition_s < 0 or settle_s < 0:
        raise BadInputError(f"precondition_s and settle_s must be >= 0, got {precondition_s}, {settle_s}")
    if int(repeats) != repeats or repeats < 1:
        raise BadInputError(f"repeats must be a positive integer, got {repeats}")
    peak = max(max(abs(v) + abs(amplitude_kv) for v in offsets), abs(precondition_kv))
    if peak > paper.V_MAX_KV:
        raise UnsafeParameterError(f"the schedule would command {peak:g} kV, above the {paper.V_MAX_KV:g} kV "
                                   "breakdown ceiling; lower the offsets or the amplitude")
    n_exc = round(duration_s * rate_hz)
    t_exc = np.arange(n_exc) / rate_hz
    if kind == "paper":
        one = paper_chirp(t_exc, f0_hz, f1_hz, duration_s, amplitude_kv)
    elif kind == "linear":
        one = linear_chirp(t_exc, f0_hz, f1_hz, duration_s, amplitude_kv)
    else:
        ms = odd_multisine(rate_hz, n_exc / rate_hz, max(f0_hz, 1.0 / duration_s), f1_hz,
                           amplitude=amplitude_kv, rng=rng)
        one = ms.signal
    excitation = np.tile(one, int(repeats))
    n_pre, n_settle = round(precondition_s * rate_hz), round(settle_s * rate_hz)
    parts: list[np.ndarray] = []
    records: list[SegmentRecord] = []
    i = 0
    for v in offsets:
        for n_part, level, what in ((n_pre, precondition_kv, "precondition"), (n_settle, v, "settle"),
                                    (excitation.size, v, "excitation")):
            if n_part == 0:
                continue
            x = level + excitation if what == "excitation" else np.full(n_part, level)
            parts.append(x)
            records.append(SegmentRecord(i / rate_hz, (i + n_part) / rate_hz, level, what,
                                         kind if what == "excitation" else ""))
            i += n_part
    command = np.concatenate(parts)
    return Schedule(t_s=np.arange(command.size) / rate_hz, command_kv=command, rate_hz=rate_hz,
                    records=records)


def uniform_grid(t_s: np.ndarray, *signals: np.ndarray,
                 tol: float = JITTER_TOLERANCE) -> tuple[np.ndarray, list[np.ndarray], float, bool]:
    """Signals sampled at strictly increasing times, on a uniform grid of their median step.

    If every step is within ``tol`` (relative) of the median step, the samples are
    returned as they are. Otherwise (jitter or gaps) each signal is linearly
    interpolated onto ``t_s[0] + k * step``, ``k = 0 .. floor((t_s[-1] - t_s[0]) / step)``.

    Parameters
    ----------
    t_s : ndarray, shape (n,)
        Sample times, s, strictly increasing (n >= 2).
    *signals : ndarray, shape (n,)
        Values at those times (any unit).
    tol : float
        Relative step deviation still taken as uniform.

    Returns
    -------
    t_s : ndarray
        The uniform times, s.
    signals : list of ndarray
        The signals at those times.
    step_s : float
        The median step, s.
    resampled : bool
        True if the samples were interpolated.
    """
    t = np.asarray(t_s, float)
    xs = [np.asarray(x, float) for x in signals]
    dt = np.diff(t)
    step = float(np.median(dt))
    if np.max(np.abs(dt - step)) <= tol * step:
        return t, xs, step, False
    grid = t[0] + step * np.arange(int(np.floor((t[-1] - t[0]) / step)) + 1)
    return grid, [np.interp(grid, t, x) for x in xs], step, True
