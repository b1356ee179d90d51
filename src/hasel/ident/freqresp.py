"""Non-parametric frequency responses: the paper's FFT ratio and a Welch H1 with bounds.

Both take equally spaced samples ``u`` (input) and ``y`` (output) of one operating
point at ``rate_hz``; frequencies are in Hz, the response in output units per input
unit (mm/kV for the actuator).

- :func:`fft_ratio` is the paper's method, ``FFT(y) / FFT(u)``, over the excited
  lines. Given the period of a periodic input (three chirps back to back are
  periodic), it uses a whole number of periods, where the ratio has no leakage, and
  averages the periods, whose spread gives the uncertainty.
- :func:`welch_h1` is the H1 estimator ``S_uy / S_uu`` with the magnitude-squared
  coherence ``|S_uy|^2 / (S_uu S_yy)``. Its resolution follows the frequency
  (constant relative resolution, :data:`DEFAULT_BINS_PER_OCTAVE` bins per octave):
  each octave is estimated from Hann segments just long enough for it, with 50 %
  overlap, so high frequencies get many averages and low ones the longest segments
  the record allows. The variance of H1 is the standard one (Bendat & Piersol),
  ``|H|^2 (1 - gamma^2) / (n gamma^2)``, computed from the residual spectrum with the
  ``n - 1`` of the fitted H1 and the exact correlation of 50 %-overlapping Hann
  segments.
"""
from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, replace

import numpy as np
from numpy.lib.stride_tricks import sliding_window_view
from scipy import fft as sp_fft

from hasel.errors import BadInputError
from hasel.validate import positive

__all__ = ["FreqResp", "fft_ratio", "welch_h1", "welch_plan", "WelchLevel", "pool", "excited_band",
           "detect_period", "log_bin", "DEFAULT_BINS_PER_OCTAVE"]

#: Frequency points per octave of :func:`welch_h1` (resolution df = f / 16 .. f / 32).
DEFAULT_BINS_PER_OCTAVE = 16


@dataclass(frozen=True)
class FreqResp:
    """A measured frequency response.

    Attributes
    ----------
    f_hz : ndarray, shape (n,)
        Frequencies, Hz, increasing.
    H : ndarray of complex, shape (n,)
        Response, output unit per input unit.
    sigma : ndarray, shape (n,)
        Standard deviation of ``H`` as a complex number, ``sqrt(E|H_est - H|^2)``
        (each of the real and imaginary parts has ``sigma / sqrt(2)``); ``inf``
        where it cannot be estimated.
    coherence : ndarray, shape (n,)
        Magnitude-squared coherence in [0, 1] (``nan`` for methods without one).
    n_avg : ndarray of int, shape (n,)
        Number of averaged segments or periods behind each point.
    method : str
        ``"welch_h1"``, ``"fft_ratio"`` or ``"pooled"``.
    offset : float
        Operating point (mean input over the data), input unit; ``nan`` if pooled.
    """

    f_hz: np.ndarray
    H: np.ndarray
    sigma: np.ndarray
    coherence: np.ndarray
    n_avg: np.ndarray
    method: str
    offset: float = float("nan")

    @property
    def magnitude_db(self) -> np.ndarray:
        """``20 log10 |H|``, dB."""
        return 20.0 * np.log10(np.maximum(np.abs(self.H), 1e-300))

    @property
    def phase_deg(self) -> np.ndarray:
        """Unwrapped phase of ``H``, degrees."""
        return np.degrees(np.unwrap(np.angle(self.H)))

    @property
    def rel_sigma(self) -> np.ndarray:
        """``sigma / |H|``: relative error of the magnitude (and phase error in rad) times sqrt(2)."""
        with np.errstate(divide="ignore", invalid="ignore"):
            return self.sigma / np.abs(self.H)

    def bounds_db(self, k: float = 2.0) -> tuple[np.ndarray, np.ndarray]:
        """Lower and upper magnitude bounds at ``k`` standard deviations, dB."""
        e = np.minimum(k * self.rel_sigma / np.sqrt(2.0), 0.999)
        mag = np.abs(self.H)
        return 20 * np.log10(np.maximum(mag * (1 - e), 1e-300)), 20 * np.log10(mag * (1 + e))

    def phase_bound_deg(self, k: float = 2.0) -> np.ndarray:
        """Half-width of the phase band at ``k`` standard deviations, degrees (capped at 180)."""
        return np.minimum(np.degrees(np.arcsin(np.minimum(k * self.rel_sigma / np.sqrt(2.0), 1.0))), 180.0)

    def select(self, mask: np.ndarray) -> FreqResp:
        """The points where ``mask`` is true."""
        return replace(self, f_hz=self.f_hz[mask], H=self.H[mask], sigma=self.sigma[mask],
                       coherence=self.coherence[mask], n_avg=self.n_avg[mask])


def _check_pair(u: np.ndarray, y: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    u = np.asarray(u, float)
    y = np.asarray(y, float)
    if u.ndim != 1 or u.shape != y.shape:
        raise BadInputError(f"u and y must be 1-D arrays of the same length, got {u.shape} and {y.shape}")
    if u.size < 16:
        raise BadInputError(f"need at least 16 samples for a frequency response, got {u.size}")
    return u, y


def _band(band_hz: Sequence[float] | None, rate_hz: float) -> tuple[float, float]:
    if band_hz is None:
        return 0.0, rate_hz / 2
    lo, hi = float(band_hz[0]), float(band_hz[1])
    if not (0.0 <= lo < hi):
        raise BadInputError(f"band_hz must be (low, high) with 0 <= low < high, got {tuple(band_hz)}")
    return lo, min(hi, rate_hz / 2)


def detect_period(u: np.ndarray, rate_hz: float, *, min_period_s: float | None = None,
                  threshold: float = 0.9) -> float | None:
    """Period of a repeated input (s), from its autocorrelation; ``None`` if not periodic.

    The input (mean removed) counts as periodic with period ``P`` when its normalised
    autocorrelation at lag ``P`` reaches ``threshold`` and the record holds at least
    two periods. The smallest such lag that is a local maximum is returned, refined to
    a fraction of a sample by a parabola through the peak.

    Parameters
    ----------
    u : ndarray, shape (n,)
        Input samples.
    rate_hz : float
        Sample rate, Hz.
    min_period_s : float, optional
        Shortest period considered, s (default 20 samples).
    threshold : float
        Normalised correlation required, in (0, 1].

    Returns
    -------
    float or None
    """
    rate_hz = positive("rate_hz", rate_hz)
    x = np.asarray(u, float) - np.mean(u)
    n = x.size
    if n < 8 or not np.any(x):
        return None
    nfft = 1 << int(np.ceil(np.log2(2 * n)))
    spec = np.fft.rfft(x, nfft)
    acf = np.fft.irfft(spec * np.conj(spec), nfft)[: n // 2 + 1]
    # normalise by the energy of the overlapping parts (unbiased for a periodic signal)
    c2 = np.cumsum(x * x)
    lags = np.arange(acf.size)
    e_head = c2[n - 1 - lags]                      # sum of x[0 : n-lag]^2
    e_tail = c2[-1] - np.concatenate([[0.0], c2[: acf.size - 1]])  # sum of x[lag : n]^2
    with np.errstate(invalid="ignore", divide="ignore"):
        r = acf / np.sqrt(e_head * e_tail)
    r = np.where(np.isfinite(r), r, 0.0)   # lags whose overlap holds no energy correlate with nothing
    lo = max(2, int(round((min_period_s or 0.0) * rate_hz)), 20)
    if lo >= r.size - 1:
        return None
    cand = np.flatnonzero((r[lo:-1] >= threshold) & (r[lo:-1] >= r[lo - 1:-2]) & (r[lo:-1] >= r[lo + 1:])) + lo
    if cand.size == 0:
        return None
    k = int(cand[0])
    # climb to the top of this peak (a plateau of high correlation may start before it)
    while k + 1 < r.size and r[k + 1] > r[k]:
        k += 1
    a, b, c = r[k - 1], r[k], r[k + 1] if k + 1 < r.size else r[k]
    den = a - 2 * b + c
    frac = 0.5 * (a - c) / den if den < 0 else 0.0
    return (k + float(np.clip(frac, -0.5, 0.5))) / rate_hz


def excited_band(u: np.ndarray, rate_hz: float, *, rel_level: float = 0.1) -> tuple[float, float]:
    """Band where the input (mean removed) carries power, Hz.

    The input's periodogram is smoothed over 1/8-octave bands; the band runs from the
    lowest to the highest smoothed level within ``rel_level`` (-10 dB) of its
    maximum.

    Parameters
    ----------
    u : ndarray, shape (n,)
        Input samples.
    rate_hz : float
        Sample rate, Hz.
    rel_level : float
        Power level relative to the maximum that counts as excited.

    Returns
    -------
    (f_low_hz, f_high_hz) : tuple of float

    Raises
    ------
    BadInputError
        If the input is constant (no excitation).
    """
    rate_hz = positive("rate_hz", rate_hz)
    x = np.asarray(u, float) - np.mean(u)
    if x.size < 16 or np.std(x) <= 1e-12 * max(1.0, float(np.max(np.abs(u)))):
        raise BadInputError("the input has no excitation (it is constant)")
    nfft = sp_fft.next_fast_len(x.size, real=True)
    p = np.abs(sp_fft.rfft(x, nfft)) ** 2
    f = np.fft.rfftfreq(nfft, 1.0 / rate_hz)
    f1 = f[1]
    edges = f1 * 2.0 ** np.arange(0.0, np.log2(f[-1] / f1) + 0.125, 0.125)
    idx = np.searchsorted(edges, f[1:], side="right")
    sums = np.bincount(idx, weights=p[1:], minlength=edges.size + 1)
    counts = np.bincount(idx, minlength=edges.size + 1)
    with np.errstate(invalid="ignore", divide="ignore"):
        level = sums / counts
    centers = np.concatenate([[f1], np.sqrt(edges[:-1] * edges[1:]), [f[-1]]])[: level.size]
    ok = np.isfinite(level) & (level >= rel_level * np.nanmax(level))
    band_lo = float(centers[np.flatnonzero(ok)[0]])
    hi_i = int(np.flatnonzero(ok)[-1])
    band_hi = float(min(edges[hi_i] if hi_i < edges.size else f[-1], f[-1]))
    return max(band_lo, f1), max(band_hi, 2 * f1)


def _smooth(x: np.ndarray, half: int) -> np.ndarray:
    """Moving average over ``2 half + 1`` neighbours (shorter at the ends)."""
    if half <= 0 or x.size < 2:
        return x
    c = np.concatenate([[0.0], np.cumsum(x)])
    i = np.arange(x.size)
    lo, hi = np.maximum(i - half, 0), np.minimum(i + half + 1, x.size)
    return (c[hi] - c[lo]) / (hi - lo)


def fft_ratio(u: np.ndarray, y: np.ndarray, rate_hz: float, *, band_hz: Sequence[float] | None = None,
              period_s: float | None = None, rel_level: float = 1e-3, smooth_lines: int = 8) -> FreqResp:
    """The paper's estimate ``FFT(y) / FFT(u)`` at the excited frequencies, with uncertainty.

    Parameters
    ----------
    u, y : ndarray, shape (n,)
        Input and output samples at ``rate_hz``.
    rate_hz : float
        Sample rate, Hz.
    band_hz : (float, float), optional
        Frequencies kept, Hz (default: all above 0).
    period_s : float, optional
        Period of a periodic input, s. The data are then cut to the last whole
        number of periods (``round(period_s * rate_hz)`` samples each), where the
        ratio has no leakage; the periods' spectra are averaged.
    rel_level : float
        Lines whose input power is below ``rel_level`` times the largest in the band
        are not excited and are left out.
    smooth_lines : int
        The output-noise power is averaged over ``2 smooth_lines + 1`` neighbouring
        lines (the noise spectrum is smooth; single lines have too few degrees of
        freedom).

    Returns
    -------
    FreqResp
        ``method="fft_ratio"``. ``sigma`` comes from the output noise at each line:
        with two or more periods from their spread about the mean; with one period
        from the difference between each line and the mean of its two neighbours
        (a smooth response cancels there, noise does not). ``coherence`` is the
        signal-to-noise coherence ``|H U|^2 / (|H U|^2 + var(Y))`` of the averaged
        spectra.
    """
    u, y = _check_pair(u, y)
    rate_hz = positive("rate_hz", rate_hz)
    lo, hi = _band(band_hz, rate_hz)
    offset = float(np.mean(u))
    n_per, m = u.size, 1
    if period_s is not None:
        p = positive("period_s", period_s) * rate_hz
        if u.size >= round(p) >= 8:
            n_per = int(round(p))
            m = u.size // n_per
    u, y = u[u.size - m * n_per:], y[y.size - m * n_per:]
    U = sp_fft.rfft((u - u.mean()).reshape(m, n_per), axis=1)
    Y = sp_fft.rfft((y - y.mean()).reshape(m, n_per), axis=1)
    f = np.fft.rfftfreq(n_per, 1.0 / rate_hz)
    Um, Ym = U.mean(axis=0), Y.mean(axis=0)
    pu = np.abs(Um) ** 2
    inband = (f > 0) & (f >= lo) & (f <= hi)
    if not np.any(inband):
        raise BadInputError(f"no frequency line of the data falls in the band {lo:g}-{hi:g} Hz")
    keep = inband & (pu >= rel_level * np.max(pu[inband]))
    Uk, Yk = Um[keep], Ym[keep]
    H = Yk / Uk
    if m >= 2:
        resid = Y[:, keep] - H * U[:, keep]
        var_line = np.sum(np.abs(resid) ** 2, axis=0) / (m - 1) / m   # variance of the mean spectrum
    elif H.size >= 3:
        # each line against the mean of its neighbours: e = U_l (H_l - (H_l-1 + H_l+1)/2)
        Hn = np.empty_like(H)
        Hn[1:-1] = 0.5 * (H[:-2] + H[2:])
        Hn[0], Hn[-1] = 2 * H[1] - H[2], 2 * H[-2] - H[-3]
        au2 = np.abs(Uk) ** 2
        gain = np.empty_like(au2)
        gain[1:-1] = 1.0 + 0.25 * au2[1:-1] * (1.0 / au2[:-2] + 1.0 / au2[2:])
        gain[0] = 1.0 + au2[0] * (4.0 / au2[1] + 1.0 / au2[2])
        gain[-1] = 1.0 + au2[-1] * (4.0 / au2[-2] + 1.0 / au2[-3])
        var_line = np.abs(Uk * (H - Hn)) ** 2 / gain
    else:
        var_line = np.full(H.size, np.inf)
    var_y = _smooth(var_line, smooth_lines) if np.all(np.isfinite(var_line)) else var_line
    with np.errstate(divide="ignore", invalid="ignore"):
        sigma = np.sqrt(var_y) / np.abs(Uk)
        sig_p = np.abs(Yk) ** 2
        coh = np.where(np.isfinite(var_y), sig_p / (sig_p + var_y), np.nan)
    return FreqResp(f_hz=f[keep], H=H, sigma=sigma, coherence=coh,
                    n_avg=np.full(H.size, m, dtype=int), method="fft_ratio", offset=offset)


def log_bin(resp: FreqResp, *, per_octave: int = 32) -> FreqResp:
    """Average a dense response into log-spaced bands (inverse-variance weights).

    Dense line estimates (hundreds per octave at high frequencies) are merged into
    bands ``per_octave`` per octave, so that a transfer-function fit works on a few
    hundred points; bands holding one point keep it unchanged.

    Parameters
    ----------
    resp : FreqResp
        Response with finite ``sigma`` where it should count.
    per_octave : int
        Bands per octave.

    Returns
    -------
    FreqResp
        Frequencies are the weighted means of the members', ``sigma`` the
        inverse-variance combination, ``coherence`` the mean, ``n_avg`` the sum.
    """
    f = resp.f_hz
    if f.size == 0:
        return resp
    band = np.floor(np.log2(f / f[0]) * per_octave + 1e-9).astype(int)
    _, idx = np.unique(band, return_inverse=True)
    nb = int(idx.max()) + 1
    with np.errstate(divide="ignore", invalid="ignore"):
        w = np.where(np.isfinite(resp.sigma) & (resp.sigma > 0), 1.0 / resp.sigma**2, 0.0)
    ws = np.bincount(idx, weights=w, minlength=nb)
    cnt = np.bincount(idx, minlength=nb)
    wu = np.where(ws[idx] > 0, w, 1.0)  # bands without finite sigma: plain mean
    wsum = np.bincount(idx, weights=wu, minlength=nb)
    Hb = (np.bincount(idx, weights=wu * resp.H.real, minlength=nb)
          + 1j * np.bincount(idx, weights=wu * resp.H.imag, minlength=nb)) / wsum
    fb = np.bincount(idx, weights=wu * f, minlength=nb) / wsum
    with np.errstate(divide="ignore"):
        sb = np.where(ws > 0, 1.0 / np.sqrt(ws), np.inf)
    coh = np.bincount(idx, weights=np.nan_to_num(resp.coherence, nan=0.0), minlength=nb) / cnt
    if np.all(np.isnan(resp.coherence)):
        coh = np.full(nb, np.nan)
    navg = np.bincount(idx, weights=resp.n_avg, minlength=nb).astype(int)
    return replace(resp, f_hz=fb, H=Hb, sigma=sb, coherence=coh, n_avg=navg)


@dataclass(frozen=True)
class WelchLevel:
    """One resolution of :func:`welch_h1`: Hann segments of ``nperseg`` samples for bins ``k_lo <= k < k_hi``."""

    nperseg: int
    k_lo: int
    k_hi: int


def welch_plan(n_samples: int, rate_hz: float, band_hz: Sequence[float], *,
               bins_per_octave: int = DEFAULT_BINS_PER_OCTAVE, min_averages: int = 5) -> list[WelchLevel]:
    """The resolutions used by :func:`welch_h1` for a record of ``n_samples``.

    The longest segments give at least ``min_averages`` 50 %-overlapping Hann
    segments and cover the bins from 2 up to ``2 * bins_per_octave``; each next level
    halves the segment and covers the next octave, bins ``bins_per_octave`` to
    ``2 * bins_per_octave``, until the band's top. Records of the same length give
    the same frequencies, so operating points can be compared point by point.

    Parameters
    ----------
    n_samples : int
        Length of the record.
    rate_hz : float
        Sample rate, Hz.
    band_hz : (float, float)
        Band of interest, Hz.
    bins_per_octave : int
        Frequency points per octave.
    min_averages : int
        Segments at the coarsest resolution (>= 2).

    Returns
    -------
    list of WelchLevel
    """
    rate_hz = positive("rate_hz", rate_hz)
    lo, hi = _band(band_hz, rate_hz)
    c = int(bins_per_octave)
    if c < 2 or min_averages < 2:
        raise BadInputError(f"bins_per_octave and min_averages must be >= 2, got {bins_per_octave}, {min_averages}")
    nseg0 = int(2 * n_samples // (min_averages + 1))
    # a segment need not be longer than what resolves the band's low edge at c bins/octave
    if lo > 0:
        nseg0 = min(nseg0, int(np.ceil(c * rate_hz / lo)))
    if nseg0 < 2 * c:
        raise BadInputError(f"the record ({n_samples} samples) is too short for a frequency response "
                            f"at {bins_per_octave} points per octave")
    # halvings needed to reach the band's top: make the longest segment divisible by 2^q
    # so every level has exactly half the segment (octaves meet exactly), 5-smooth for the FFT
    q = max(0, min(int(np.ceil(np.log2(max(hi * nseg0 / ((2 * c - 1) * rate_hz), 1.0)))),
                   int(np.floor(np.log2(max(nseg0 / (4 * c), 1.0))))))
    L = _smooth_len_below(max(nseg0 >> q, 2)) << q if (nseg0 >> q) >= 2 else nseg0
    levels: list[WelchLevel] = []
    k_lo = 2
    while True:
        k_hi = 2 * c
        f_top = (k_hi - 1) * rate_hz / L
        last = f_top >= hi or (L // 2) < 2 * c or L // 2 < 8
        if last:
            k_hi = min(L // 2 + 1, int(np.floor(hi * L / rate_hz)) + 1)
        if k_hi > k_lo:
            levels.append(WelchLevel(nperseg=L, k_lo=k_lo, k_hi=k_hi))
        if last:
            break
        L = L // 2
        k_lo = c
    return levels


def _smooth_len_below(n: int) -> int:
    """Largest even ``2^a 3^b 5^c <= n`` (a fast FFT length whose halvings stay fast while even)."""
    best = 2
    p5 = 1
    while p5 <= n:
        p35 = p5
        while p35 <= n:
            v = p35
            while v * 2 <= n:
                v *= 2
            if v % 2 == 0:
                best = max(best, v)
            p35 *= 3
        p5 *= 5
    return best


def _hann(n: int) -> np.ndarray:
    return 0.5 - 0.5 * np.cos(2.0 * np.pi * np.arange(n) / n)  # periodic Hann


def welch_h1(u: np.ndarray, y: np.ndarray, rate_hz: float, *, band_hz: Sequence[float] | None = None,
             plan: list[WelchLevel] | None = None, bins_per_octave: int = DEFAULT_BINS_PER_OCTAVE,
             min_averages: int = 5) -> FreqResp:
    """H1 frequency response, coherence and standard deviation, at constant relative resolution.

    Parameters
    ----------
    u, y : ndarray, shape (n,)
        Input and output samples at ``rate_hz`` (any units).
    rate_hz : float
        Sample rate, Hz.
    band_hz : (float, float), optional
        Band of interest, Hz (default: everything the record resolves).
    plan : list of WelchLevel, optional
        Resolutions from :func:`welch_plan` (to share one grid between records).
    bins_per_octave, min_averages : int
        Passed to :func:`welch_plan` when ``plan`` is not given.

    Returns
    -------
    FreqResp
        ``method="welch_h1"``, frequencies in Hz, ``sigma`` from the coherence and
        the number of segments (``inf`` where a single segment was averaged).

    Notes
    -----
    Per frequency, with segment spectra ``U_i``, ``Y_i`` (Hann, 50 % overlap, mean
    removed per segment): ``H1 = sum conj(U_i) Y_i / sum |U_i|^2``; the residual
    power ``RSS = sum |Y_i - H1 U_i|^2 = S_yy (1 - gamma^2)``; and

    ``var(H1) = RSS (1 + c) / ((n - 1 - c) S_uu)``,

    where ``c = 2 Re(rho sum conj(U_i) U_{i+1}) / S_uu`` accounts for the noise that
    adjacent overlapping segments share (``rho = (-1)^k / 3`` for a Hann window at
    50 % overlap, bin ``k``). With ``c = 0`` this is Bendat & Piersol's
    ``|H|^2 (1 - gamma^2) / ((n - 1) gamma^2)``.
    """
    u, y = _check_pair(u, y)
    rate_hz = positive("rate_hz", rate_hz)
    if plan is None:
        plan = welch_plan(u.size, rate_hz, band_hz if band_hz is not None else (0.0, rate_hz / 2),
                          bins_per_octave=bins_per_octave, min_averages=min_averages)
    lo, hi = _band(band_hz, rate_hz)
    fs, Hs, sig, coh, navg = [], [], [], [], []
    for lev in plan:
        L, hop = lev.nperseg, lev.nperseg // 2
        if L > u.size:
            raise BadInputError(f"the record ({u.size} samples) is shorter than a Welch segment ({L})")
        fu = sliding_window_view(u, L)[::hop]
        fy = sliding_window_view(y, L)[::hop]
        n = fu.shape[0]
        w = _hann(L)
        k = np.arange(lev.k_lo, lev.k_hi)
        U = sp_fft.rfft((fu - fu.mean(axis=1, keepdims=True)) * w, axis=1)[:, k]
        Y = sp_fft.rfft((fy - fy.mean(axis=1, keepdims=True)) * w, axis=1)[:, k]
        suu = np.sum(np.abs(U) ** 2, axis=0)
        syy = np.sum(np.abs(Y) ** 2, axis=0)
        suy = np.sum(np.conj(U) * Y, axis=0)
        with np.errstate(divide="ignore", invalid="ignore"):
            h1 = suy / suu
            g2 = np.abs(suy) ** 2 / (suu * syy)
            rss = np.maximum(syy - np.abs(suy) ** 2 / suu, 0.0)
            rho = np.where(k % 2 == 0, 1.0, -1.0) / 3.0
            cross = 2.0 * np.real(rho * np.sum(np.conj(U[:-1]) * U[1:], axis=0)) / suu if n > 1 else 0.0 * suu
            dof = n - 1 - cross
            var = np.where(dof > 0.5, rss * (1.0 + cross) / (np.maximum(dof, 0.5) * suu), np.inf)
        fs.append(k * rate_hz / L)
        Hs.append(h1)
        sig.append(np.sqrt(var))
        coh.append(np.clip(np.nan_to_num(g2, nan=0.0), 0.0, 1.0))
        navg.append(np.full(k.size, n, dtype=int))
    f = np.concatenate(fs)
    keep = (f >= lo) & (f <= hi)
    H = np.concatenate(Hs)[keep]
    sigma = np.concatenate(sig)[keep]
    sigma = np.where(np.isfinite(H), sigma, np.inf)
    H = np.where(np.isfinite(H), H, 0.0)
    return FreqResp(f_hz=f[keep], H=H, sigma=sigma, coherence=np.concatenate(coh)[keep],
                    n_avg=np.concatenate(navg)[keep], method="welch_h1", offset=float(np.mean(u)))


def pool(responses: Sequence[FreqResp]) -> FreqResp:
    """Inverse-variance weighted mean of responses on the same frequencies.

    Parameters
    ----------
    responses : sequence of FreqResp
        At least one; all with the same ``f_hz``.

    Returns
    -------
    FreqResp
        ``method="pooled"``: ``H = sum(H_k / s_k^2) / sum(1 / s_k^2)``,
        ``sigma = (sum 1 / s_k^2)^(-1/2)``, coherence the mean of the members',
        ``n_avg`` their sum.
    """
    if not responses:
        raise BadInputError("pool needs at least one frequency response")
    f = responses[0].f_hz
    for r in responses[1:]:
        if r.f_hz.shape != f.shape or not np.allclose(r.f_hz, f, rtol=1e-9, atol=0.0):
            raise BadInputError("pooled responses must share their frequencies (use one welch_plan)")
    S = np.array([r.sigma for r in responses])
    Hk = np.array([r.H for r in responses])
    with np.errstate(divide="ignore", invalid="ignore"):
        w = np.where(np.isfinite(S) & (S > 0), 1.0 / S**2, 0.0)
    wsum = w.sum(axis=0)
    with np.errstate(divide="ignore", invalid="ignore"):
        H = np.where(wsum > 0, (w * Hk).sum(axis=0) / wsum, Hk.mean(axis=0))
        sigma = np.where(wsum > 0, 1.0 / np.sqrt(wsum), np.inf)
    coh = np.nanmean(np.array([r.coherence for r in responses]), axis=0) if any(
        np.any(np.isfinite(r.coherence)) for r in responses) else np.full(f.size, np.nan)
    return FreqResp(f_hz=f.copy(), H=H, sigma=sigma, coherence=coh,
                    n_avg=np.sum([r.n_avg for r in responses], axis=0), method="pooled")
