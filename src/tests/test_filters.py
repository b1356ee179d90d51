"""hasel.filters: the 40 Hz low-pass against SciPy's Butterworth design."""
from __future__ import annotations

import numpy as np
import pytest
from scipy import signal

from hasel.errors import BadInputError
from hasel.filters import LowPass, butter2_lowpass_biquad


def test_matches_scipy_butter_with_prewarping():
    sos_ref = signal.butter(2, 40.0, fs=200.0, output="sos")
    np.testing.assert_allclose(butter2_lowpass_biquad(40.0, 200.0), sos_ref[0], rtol=1e-12)


def test_minus_3db_exactly_at_cutoff_and_unity_dc():
    sos = butter2_lowpass_biquad(40.0, 200.0).reshape(1, 6)
    _, h = signal.sosfreqz(sos, worN=[0.0, 40.0, 99.999], fs=200.0)
    assert abs(h[0]) == pytest.approx(1.0, rel=1e-12)
    assert 20 * np.log10(abs(h[1])) == pytest.approx(-3.0103, abs=1e-3)
    assert abs(h[2]) < 1e-6  # double zero at Nyquist


def test_lowpass_starts_at_rest_on_first_sample_and_filters():
    lp = LowPass()
    out = [lp(5.0) for _ in range(10)]
    np.testing.assert_allclose(out, 5.0, rtol=1e-12)  # no transient from zero
    lp.reset()
    x = np.sin(2 * np.pi * 90.0 * np.arange(400) / 200.0)
    y = np.array([lp(v) for v in x])
    assert np.max(np.abs(y[200:])) < 0.1  # 90 Hz is strongly attenuated


def test_rejects_cutoff_above_nyquist():
    with pytest.raises(BadInputError, match="Nyquist"):
        butter2_lowpass_biquad(120.0, 200.0)


def test_sample_by_sample_equals_scipy_sosfilt():
    x = np.random.default_rng(2).normal(3.0, 1.0, 500)
    lp = LowPass()
    y = np.array([lp(float(v)) for v in x])
    sos = signal.butter(2, 40.0, fs=200.0, output="sos")
    ref, _ = signal.sosfilt(sos, x, zi=signal.sosfilt_zi(sos) * x[0])
    np.testing.assert_allclose(y, ref, rtol=1e-12, atol=1e-12)
