"""Non-parametric frequency responses (hasel.ident.freqresp) against known systems."""
from __future__ import annotations

import numpy as np
import pytest
from scipy import signal

from hasel import paper
from hasel.errors import BadInputError
from hasel.ident.freqresp import (FreqResp, detect_period, excited_band, fft_ratio, log_bin, pool, welch_h1,
                                  welch_plan)
from hasel.lti import tf_freqresp, zoh_sos
from hasel.signals import odd_multisine

RATE = 500.0
# a lightly damped 2nd-order system, 8 Hz, zeta 0.2, gain 2
WN = 2 * np.pi * 8.0
NUM2, DEN2 = [2 * WN**2], [1.0, 2 * 0.2 * WN, WN**2]


def _zoh_truth(num, den, f_hz, rate):
    """Response of the ZOH-discretised system (what the simulated samples follow)."""
    sos = zoh_sos(num, den, 1.0 / rate)
    _, h = signal.sosfreqz(sos, worN=f_hz, fs=rate)
    return h


def _noise_input(rng, n, rate, f_hi):
    sos = signal.butter(4, f_hi, fs=rate, output="sos")
    return signal.sosfilt(sos, rng.standard_normal(n))


def test_h1_coherence_is_one_without_noise_and_matches_a_known_system():
    rng = np.random.default_rng(0)
    u = _noise_input(rng, 60_000, RATE, 60.0)
    y = signal.sosfilt(zoh_sos(NUM2, DEN2, 1 / RATE), u)
    fr = welch_h1(u, y, RATE, band_hz=(0.5, 40.0))
    assert fr.method == "welch_h1" and np.all(np.diff(fr.f_hz) > 0)
    assert fr.f_hz[0] >= 0.5 and fr.f_hz[-1] <= 40.0
    truth = _zoh_truth(NUM2, DEN2, fr.f_hz, RATE)
    away = np.abs(fr.f_hz - 8.0) > 1.5  # leakage bias is largest on the resonance
    np.testing.assert_allclose(fr.H[away], truth[away], rtol=0.02)
    # leakage of the finite segments keeps it a little below 1 at the coarsest resolutions
    assert np.median(fr.coherence[away]) > 0.999 and np.min(fr.coherence[away]) > 0.98


def test_h1_uncertainty_is_calibrated_and_coherence_drops_with_noise():
    """Output noise of known level: errors match sigma (z ~ 1) and coherence follows S/(S+N)."""
    rng = np.random.default_rng(1)
    n = 120_000
    u = _noise_input(rng, n, RATE, 60.0)
    y0 = signal.sosfilt(zoh_sos(NUM2, DEN2, 1 / RATE), u)
    noise = 0.5 * np.std(y0) * rng.standard_normal(n)
    fr = welch_h1(u, y0 + noise, RATE, band_hz=(1.0, 40.0))
    truth = _zoh_truth(NUM2, DEN2, fr.f_hz, RATE)
    z = np.abs(fr.H - truth) / fr.sigma
    assert 0.7 < np.sqrt(np.mean(z**2)) < 1.3
    # coherence from the true spectra: |H|^2 Suu / (|H|^2 Suu + Snn)
    f, suu = signal.welch(u, RATE, nperseg=4096)
    snn = np.var(noise) * 2 / RATE
    gamma2 = np.interp(fr.f_hz, f, np.abs(_zoh_truth(NUM2, DEN2, f, RATE)) ** 2 * suu)
    gamma2 = gamma2 / (gamma2 + snn)
    assert np.median(np.abs(fr.coherence - gamma2)) < 0.05
    assert np.min(fr.coherence) < 0.9  # noise shows


def test_fft_ratio_is_exact_for_a_periodic_input_and_its_sigma_is_calibrated():
    num, den = paper.plant_tf()
    rate = 1000.0
    ms = odd_multisine(rate, 10.0, 0.1, 40.0, rng=np.random.default_rng(2))
    u = np.tile(ms.signal, 6)
    y = signal.sosfilt(zoh_sos(num, den, 1 / rate), u)[10_000:]   # drop the first period (transient)
    u = u[10_000:]
    fr = fft_ratio(u, y, rate, period_s=10.0, band_hz=(0.05, 45.0))
    np.testing.assert_array_equal(np.round(fr.f_hz * 10).astype(int), ms.excited)
    np.testing.assert_allclose(fr.H, _zoh_truth(num, den, fr.f_hz, rate), rtol=1e-7)
    assert np.all(fr.n_avg == 5)
    # with noise: five periods, sigma from their spread; and one period, sigma from neighbouring lines
    rng = np.random.default_rng(3)
    yn = y + 0.02 * rng.standard_normal(y.size)
    truth = _zoh_truth(num, den, fr.f_hz, rate)
    for data_u, data_y in ((u, yn), (u[-10_000:], yn[-10_000:])):
        frn = fft_ratio(data_u, data_y, rate, period_s=10.0, band_hz=(0.05, 45.0))
        z = np.abs(frn.H - truth) / frn.sigma
        assert 0.75 < np.sqrt(np.mean(z**2)) < 1.3, frn.n_avg[0]


def test_fft_ratio_without_period_is_the_plain_ratio():
    rng = np.random.default_rng(4)
    u = rng.standard_normal(1000)
    y = np.convolve(u, [0.5, 0.25], mode="full")[:1000]
    fr = fft_ratio(u, y, 100.0, rel_level=0.0)
    U, Y = np.fft.rfft(u - u.mean()), np.fft.rfft(y - y.mean())
    np.testing.assert_allclose(fr.H, (Y / U)[1:], rtol=1e-10)
    assert fr.f_hz[0] == pytest.approx(0.1)


def test_detect_period_and_excited_band():
    rate = 200.0
    ms = odd_multisine(rate, 5.0, 1.0, 30.0, rng=np.random.default_rng(5))
    x = np.tile(ms.signal, 3)
    assert detect_period(x, rate) == pytest.approx(5.0, abs=1 / rate)
    assert detect_period(np.random.default_rng(6).standard_normal(3000), rate) is None
    lo, hi = excited_band(x, rate)
    assert 0.5 < lo < 1.5 and 25.0 < hi < 35.0
    with pytest.raises(BadInputError, match="no excitation"):
        excited_band(np.full(100, 3.0), rate)


def test_welch_plan_levels_are_contiguous_octaves():
    plan = welch_plan(40_000, 1000.0, (0.1, 40.0), bins_per_octave=16)
    f_edges = [(lv.k_lo * 1000.0 / lv.nperseg, lv.k_hi * 1000.0 / lv.nperseg) for lv in plan]
    for (_, hi), (lo, _) in zip(f_edges, f_edges[1:]):
        assert lo == pytest.approx(hi, rel=1e-9)
    assert f_edges[-1][1] > 39.0
    assert plan[0].nperseg <= 2 * 40_000 // 6
    with pytest.raises(BadInputError, match="too short"):
        welch_plan(40, 1000.0, (0.1, 40.0))


def test_pool_is_the_inverse_variance_mean():
    f = np.array([1.0, 2.0])
    a = FreqResp(f, np.array([1 + 1j, 2.0]), np.array([1.0, 2.0]), np.ones(2), np.ones(2, int), "welch_h1", 1.0)
    b = FreqResp(f, np.array([3 + 1j, 4.0]), np.array([2.0, 2.0]), np.ones(2), np.ones(2, int), "welch_h1", 2.0)
    p = pool([a, b])
    np.testing.assert_allclose(p.H, [(1 + 1j) * 0.8 + (3 + 1j) * 0.2, 3.0])
    np.testing.assert_allclose(p.sigma, [1 / np.sqrt(1.25), np.sqrt(2.0)])
    with pytest.raises(BadInputError, match="share their frequencies"):
        pool([a, FreqResp(f * 2, a.H, a.sigma, a.coherence, a.n_avg, "welch_h1")])


def test_log_bin_keeps_a_smooth_response_and_combines_sigma():
    f = np.arange(1, 2001) * 0.05
    H = tf_freqresp([10.0], [1.0, 10.0], f)
    fr = FreqResp(f, H, np.full(f.size, 0.01), np.ones(f.size), np.ones(f.size, int), "fft_ratio")
    b = log_bin(fr, per_octave=32)
    assert 150 < b.f_hz.size < 400
    np.testing.assert_allclose(b.H, tf_freqresp([10.0], [1.0, 10.0], b.f_hz), rtol=2e-3)
    np.testing.assert_allclose(b.sigma, 0.01 / np.sqrt(b.n_avg), rtol=1e-9)
