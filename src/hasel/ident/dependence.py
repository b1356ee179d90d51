"""Does the dynamic response depend on the operating point? A test of the paper's claim.

The paper found the dynamic response ``h_d`` of the actuator independent of the DC
offset over 2-7 kV (Fig. 3), by eye. Here the claim is tested against the data's
own uncertainty: the H1 estimates of the operating points (on one frequency grid)
are compared with their inverse-variance weighted mean. Under the hypothesis of one
common response and Gaussian errors of standard deviation ``sigma_k / sqrt(2)`` in
the real and imaginary parts,

``chi2 = sum_k sum_f |H_k(f) - H_mean(f)|^2 / (sigma_k(f)^2 / 2)``

follows a chi-square law with ``2 (K - 1) N_f`` degrees of freedom. Only points
where every operating point is coherent (``coherence >= coherence_min``) enter, and
only every ``thin``-th of them, because neighbouring Hann bins are correlated.

Statistical significance is not the whole story: with long, clean records even a
tiny, harmless difference is significant. So the verdict also weighs the size of
the differences, the spread between the operating points' curves (largest minus
smallest at each frequency, 95th percentile over the tested band, in dB and
degrees), against tolerances (default 1 dB and 5 degrees, the accuracy a model is
asked for):

- ``"independent"``: the differences are within the noise (``p >= alpha``);
- ``"weakly_dependent"``: significant, but within the tolerances;
- ``"dependent"``: beyond the tolerances;
- ``"untestable"``: fewer than two operating points or no coherent point.
"""
from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np
from scipy import stats

from hasel.errors import BadInputError
from hasel.ident.freqresp import FreqResp

__all__ = ["DependenceTest", "offset_dependence", "VERDICTS", "ResidualDependence", "residual_dependence",
           "RESIDUAL_TEST_ASSUMPTIONS"]

#: Possible values of :attr:`DependenceTest.verdict`.
VERDICTS = ("independent", "weakly_dependent", "dependent", "untestable")


@dataclass(frozen=True)
class DependenceTest:
    """Result of :func:`offset_dependence`.

    Attributes
    ----------
    verdict : str
        One of :data:`VERDICTS`.
    summary : str
        One sentence with the numbers behind the verdict.
    chi2, dof, p_value, reduced_chi2 : float, int, float, float
        The statistic, its degrees of freedom, the probability of a value at least as
        large under independence, and ``chi2 / dof``.
    max_dev_db, max_dev_deg : float
        Largest deviation of any operating point from the pooled mean over the tested
        points, dB and degrees.
    spread_db, spread_deg : float
        95th percentile over the tested frequencies of the spread between the
        operating points (largest minus smallest magnitude in dB, phase in degrees),
        over the frequencies where every estimate's relative error is below a quarter
        of ``tol_db`` (all tested frequencies if fewer than three are).
    band_hz : (float, float)
        Lowest and highest tested frequency, Hz.
    n_points : int
        Frequencies tested.
    offsets : list of float
        The operating points compared (input unit).
    per_offset : list of dict
        For each operating point: ``offset``, ``reduced_chi2``, ``mean_dev_db``,
        ``mean_dev_deg`` (its average deviation from the pooled mean).
    alpha, tol_db, tol_deg, coherence_min : float
        The settings used.
    """

    verdict: str
    summary: str
    chi2: float
    dof: int
    p_value: float
    reduced_chi2: float
    max_dev_db: float
    max_dev_deg: float
    spread_db: float
    spread_deg: float
    band_hz: tuple[float, float]
    n_points: int
    offsets: list[float]
    per_offset: list[dict] = field(default_factory=list)
    alpha: float = 0.01
    tol_db: float = 1.0
    tol_deg: float = 5.0
    coherence_min: float = 0.9
    method: str = "frequency_response"
    assumptions: str = ("chi-square of the operating points' responses against their weighted mean, "
                        "with the estimates' own standard deviations; every thin-th coherent bin")

    def to_json(self) -> dict:
        """JSON-ready dict (non-finite numbers become None)."""
        def clean(v):
            if isinstance(v, float):
                return v if np.isfinite(v) else None
            if isinstance(v, (list, tuple)):
                return [clean(x) for x in v]
            if isinstance(v, dict):
                return {k: clean(x) for k, x in v.items()}
            return v
        return clean({k: getattr(self, k) for k in self.__dataclass_fields__})


def _untestable(reason: str, offsets: list[float], alpha: float, tol_db: float, tol_deg: float,
                coherence_min: float) -> DependenceTest:
    nan = float("nan")
    return DependenceTest("untestable", reason, nan, 0, nan, nan, nan, nan, nan, nan, (nan, nan), 0, offsets,
                          [], alpha, tol_db, tol_deg, coherence_min)


def offset_dependence(responses: Sequence[FreqResp], *, coherence_min: float = 0.9, alpha: float = 0.01,
                      tol_db: float = 1.0, tol_deg: float = 5.0, thin: int = 2,
                      band_hz: Sequence[float] | None = None, unit: str = "") -> DependenceTest:
    """Test whether frequency responses at several operating points share one response.

    Parameters
    ----------
    responses : sequence of FreqResp
        H1 estimates with ``sigma`` and ``coherence``, all on the same frequencies
        (:func:`~hasel.ident.freqresp.welch_h1` with one shared plan), each with its
        ``offset``.
    coherence_min : float
        Points where any response has a lower coherence are left out.
    alpha : float
        Significance level.
    tol_db, tol_deg : float
        Spreads (95th percentile) below which a significant dependence is called weak.
    thin : int
        Use every ``thin``-th coherent frequency.
    band_hz : (float, float), optional
        Restrict the test to this band, Hz.
    unit : str
        Unit of the offsets, for the summary.

    Returns
    -------
    DependenceTest
    """
    offsets = [float(r.offset) for r in responses]
    if len(responses) < 2:
        return _untestable("untestable: fewer than two operating points", offsets, alpha, tol_db, tol_deg,
                           coherence_min)
    f = responses[0].f_hz
    for r in responses[1:]:
        if r.f_hz.shape != f.shape or not np.allclose(r.f_hz, f, rtol=1e-9, atol=0.0):
            raise BadInputError("the responses must share their frequencies (use one welch_plan)")
    if thin < 1:
        raise BadInputError(f"thin must be >= 1, got {thin}")
    Hk = np.array([r.H for r in responses])
    Sk = np.array([r.sigma for r in responses])
    Ck = np.array([r.coherence for r in responses])
    ok = np.all(np.isfinite(Sk) & (Sk > 0) & np.isfinite(Hk), axis=0)
    ok &= np.all(np.nan_to_num(Ck, nan=1.0) >= coherence_min, axis=0)
    if band_hz is not None:
        ok &= (f >= band_hz[0]) & (f <= band_hz[1])
    idx = np.flatnonzero(ok)[::thin]
    if idx.size == 0:
        return _untestable(f"untestable: no frequency where every operating point has coherence >= {coherence_min}",
                           offsets, alpha, tol_db, tol_deg, coherence_min)
    H, S = Hk[:, idx], Sk[:, idx]
    w = 1.0 / S**2
    Hm = (w * H).sum(axis=0) / w.sum(axis=0)
    z2 = np.abs(H - Hm) ** 2 / (S**2 / 2.0)
    chi2 = float(z2.sum())
    K, N = H.shape
    dof = 2 * (K - 1) * N
    p = float(stats.chi2.sf(chi2, dof))
    ratio = H / Hm
    dev_db = 20.0 * np.log10(np.abs(ratio))
    dev_deg = np.degrees(np.angle(ratio))
    max_db, max_deg = float(np.max(np.abs(dev_db))), float(np.max(np.abs(dev_deg)))
    # the spread is judged where the estimates are precise enough to show a spread of the
    # tolerance (relative error below a quarter of it), so noise does not pass for dependence
    precise = np.all(S / np.abs(H) < 0.25 * (10 ** (tol_db / 20.0) - 1.0), axis=0)
    cols = precise if np.count_nonzero(precise) >= 3 else np.ones(N, bool)
    spread_db = float(np.percentile(np.ptp(dev_db[:, cols], axis=0), 95))
    spread_deg = float(np.percentile(np.ptp(dev_deg[:, cols], axis=0), 95))
    per = [{"offset": offsets[k], "reduced_chi2": float(z2[k].sum() / (2 * N * (K - 1) / K)),
            "mean_dev_db": float(np.mean(dev_db[k])), "mean_dev_deg": float(np.mean(dev_deg[k]))}
           for k in range(K)]
    f_lo, f_hi = float(f[idx[0]]), float(f[idx[-1]])
    span = f"{min(offsets):.3g}-{max(offsets):.3g}{(' ' + unit) if unit else ''}"
    nums = (f"chi2/dof = {chi2 / dof:.3g}, p = {p:.3g}; the curves differ by {spread_db:.2g} dB and "
            f"{spread_deg:.2g} deg (95th percentile over {f_lo:.3g}-{f_hi:.3g} Hz)")
    if p >= alpha:
        verdict = "independent"
        summary = (f"independent: the {K} responses over {span} agree within their uncertainty ({nums})")
    elif spread_db <= tol_db and spread_deg <= tol_deg:
        verdict = "weakly_dependent"
        summary = (f"weakly dependent: the {K} responses over {span} differ significantly but by less than "
                   f"{tol_db:g} dB / {tol_deg:g} deg ({nums})")
    else:
        verdict = "dependent"
        summary = (f"dependent: the dynamics change with the operating point over {span} ({nums})")
    return DependenceTest(verdict, summary, chi2, dof, p, chi2 / dof, max_db, max_deg, spread_db, spread_deg,
                          (f_lo, f_hi), int(N), offsets, per, alpha, tol_db, tol_deg, coherence_min)


@dataclass(frozen=True)
class ResidualDependence:
    """Result of :func:`residual_dependence`: do the operating points leave different model errors?

    Attributes
    ----------
    chi2, dof, p_value : float, int, float
        Friedman's ``Q`` (see :func:`residual_dependence`), its degrees of freedom
        ``K - 1``, and the Bonferroni p-value.
    coefficients : list of (float, float)
        Per operating point: relative gain correction and lag correction (s) of the
        common model that fits its residual best.
    std_errors : list of (float, float)
        Their standard errors from the sub-blocks' spread.
    ar_order : int
        0 (no noise model: the error estimate is the observed sub-block variability).
    assumptions : str
        What the p-value relies on.
    """

    chi2: float
    dof: int
    p_value: float
    coefficients: list[tuple[float, float]]
    std_errors: list[tuple[float, float]]
    ar_order: int
    assumptions: str


#: What :func:`residual_dependence` assumes (reported in the JSON and the summary).
RESIDUAL_TEST_ASSUMPTIONS = (
    "one linear model fitted to the whole log (its simulation runs through every transient, so start-up "
    "transients are not in the residual); each operating point is cut into 16 equal sub-blocks and the "
    "residual of each is regressed on the model's response and its derivative (a local gain and lag "
    "correction); Friedman's rank test (operating point x sub-block) asks whether some operating points rank "
    "consistently higher within the sub-blocks, so the error estimate is the observed block-to-block "
    "variability (it holds for coloured noise, correlated samples and leakage alike), model error shared by "
    "the points at the same position in their excitation cancels within each sub-block, and sub-blocks of "
    "very different precision (a sweep's slow start against its fast end) weigh alike; assumes that within "
    "a sub-block the operating points' estimates are exchangeable under independence (the same excitation at "
    "the same position, independent noise), which fails when the detected operating points are not aligned "
    "on the excitation (they are aligned on the model's response, to within 5 % of their length, before the "
    "cut; beyond that give markers); gain and lag p-values combined by Bonferroni")


def _aligned(y_hat: np.ndarray, pieces: Sequence[tuple[int, int]], slack: float = 0.05) -> list[tuple[int, int]]:
    """Windows of one length, one per piece, on the same position of their excitation.

    Detected operating points start and end a little apart from the excitation (a
    sweep's slow start looks like a level change), and then their sub-blocks hold
    different parts of it, which breaks the test's exchangeability. Each window is
    ``min length - 2 slack`` long; the first piece's sits in its middle, every other
    piece's is shifted by up to ``slack`` of the length to the lag that best matches
    the model's response of the first (cross-correlation of the centred ``y_hat``).
    """
    n_c = min(i1 - i0 for i0, i1 in pieces)
    L = int(slack * n_c)
    n_w = n_c - 2 * L
    if L < 1 or n_w < 8:
        return [(i0, i0 + n_c) for i0, _ in pieces]
    r0 = y_hat[pieces[0][0] + L: pieces[0][0] + L + n_w]
    r0 = r0 - r0.mean()
    out = [(pieces[0][0] + L, pieces[0][0] + L + n_w)]
    nfft = 1 << int(np.ceil(np.log2(n_w + n_c)))
    F0 = np.fft.rfft(r0, nfft)
    for i0, _ in pieces[1:]:
        x = y_hat[i0: i0 + n_c]
        x = x - x.mean()
        # corr[m] = sum_t x[t + m] r0[t], m = 0 .. 2L (window start i0 + m)
        corr = np.fft.irfft(np.fft.rfft(x, nfft) * np.conj(F0), nfft)[: 2 * L + 1]
        m = int(np.argmax(corr))
        out.append((i0 + m, i0 + m + n_w))
    return out


def _friedman_rows(C: np.ndarray) -> tuple[float, int, float]:
    """Friedman's test of a row effect in ``C[k, b]`` (rows ranked within each column): Q, its dof, p-value.

    ``Q = 12 / (B K (K + 1)) sum_k R_k^2 - 3 B (K + 1)`` with ``R_k`` the rank sum of row
    ``k``, compared with chi-square of ``K - 1`` degrees of freedom. Ranks make columns of
    any scale weigh alike.
    """
    K, B = C.shape
    R = stats.rankdata(C, axis=0).sum(axis=1)
    Q = 12.0 / (B * K * (K + 1)) * float(np.sum(R * R)) - 3.0 * B * (K + 1)
    return Q, K - 1, float(stats.chi2.sf(Q, K - 1))


def residual_dependence(y: np.ndarray, y_hat: np.ndarray, pieces: Sequence[tuple[int, int]], rate_hz: float, *,
                        sub_blocks: int = 16) -> ResidualDependence | None:
    """A calibrated test of offset dependence from the time-domain residual of one common model.

    Parameters
    ----------
    y, y_hat : ndarray, shape (n,)
        Measured output and the common model's simulation over the whole log.
    pieces : sequence of (int, int)
        Sample ranges of the operating points.
    rate_hz : float
        Sample rate of ``y``, Hz.
    sub_blocks : int
        Sub-blocks per operating point.

    Returns
    -------
    ResidualDependence or None
        None with fewer than two usable operating points.

    Notes
    -----
    In sub-block ``b`` of operating point ``k``, with ``x1`` the model response about
    its mean and ``x2 = dx1/dt``: ``y - y_hat = c1 x1 - c2 x2 + const + e`` (``c1`` a
    relative gain change, ``c2`` a lag, s). For ``c1`` and ``c2`` separately, the
    operating-point effect of ``c[k, b]`` is tested by Friedman's rank test (operating
    points ranked within each sub-block; chi-square of ``K - 1`` degrees of freedom).
    ``chi2`` reports ``Q`` of the smaller p-value. See :data:`RESIDUAL_TEST_ASSUMPTIONS`.
    """
    # only operating points of one length compare like with like (same excitation at the same sub-block)
    n_med = float(np.median([i1 - i0 for i0, i1 in pieces])) if len(pieces) else 0.0
    use = [(i0, i1) for i0, i1 in pieces if abs((i1 - i0) - n_med) <= 0.1 * n_med and i1 - i0 >= 40 * sub_blocks]
    K, B = len(use), sub_blocks
    if K < 2:
        return None
    use = _aligned(y_hat, use)
    C = np.zeros((2, K, B))
    for k, (i0, i1) in enumerate(use):
        edges = np.linspace(i0, i1, B + 1).astype(int)
        for b in range(B):
            a0, a1 = edges[b], edges[b + 1]
            x1 = y_hat[a0:a1] - np.mean(y_hat[a0:a1])
            x2 = -np.gradient(x1) * rate_hz
            r = y[a0:a1] - y_hat[a0:a1]
            X = np.column_stack([x1, x2, np.ones(x1.size)])
            c = np.linalg.lstsq(X, r, rcond=None)[0]
            C[:, k, b] = c[:2]
    res = [_friedman_rows(C[j]) for j in range(2)]
    p = min(1.0, 2.0 * min(r[2] for r in res))
    j = int(np.argmin([r[2] for r in res]))
    Q, d1, _ = res[j]
    coefs = [(float(C[0, k].mean()), float(C[1, k].mean())) for k in range(K)]
    ses = [(float(C[0, k].std(ddof=1) / np.sqrt(B)), float(C[1, k].std(ddof=1) / np.sqrt(B))) for k in range(K)]
    return ResidualDependence(float(Q), int(d1), p, coefs, ses, 0, RESIDUAL_TEST_ASSUMPTIONS)
