"""The model checks of hasel.ident.checks: in-band agreement, noise-aware held-out fit, timing offset."""
from __future__ import annotations

import numpy as np
import pytest

from hasel.errors import BadInputError
from hasel.ident.checks import check_model, inband_errors
from hasel.ident.freqresp import FreqResp
from hasel.ident.tffit import TFModel
from hasel.ident.timefit import interleaved, oe_fit, simulate_zoh

TRUE = TFModel(np.array([400.0]), np.array([1.0, 16.0, 400.0]))   # 3.2 Hz, damping 0.4, G(0) = 1


def _measured(model: TFModel, rel_sigma: float = 0.01, f_max: float = 10.0) -> FreqResp:
    f = np.geomspace(0.1, f_max, 60)
    H = model.freqresp(f)
    rng = np.random.default_rng(3)
    noise = rel_sigma * np.abs(H) / np.sqrt(2) * (rng.standard_normal(f.size) + 1j * rng.standard_normal(f.size))
    return FreqResp(f, H + noise, rel_sigma * np.abs(H), np.full(f.size, 0.99), np.full(f.size, 10), "pooled")


def test_inband_check_passes_the_true_model_and_refuses_a_wrong_resonance():
    meas = _measured(TRUE)
    assert check_model(TRUE, band_hz=(0.1, 10.0), measured=meas).usable
    wrong = TFModel(np.array([484.0]), np.array([1.0, 8.0, 484.0]))   # 3.5 Hz, half the damping, same G(0)
    chk = check_model(wrong, band_hz=(0.1, 10.0), measured=meas)
    assert not chk.usable
    assert "disagrees with the measured frequency response" in chk.reasons[0]
    assert chk.details["inband_max_db"] > 3.0


def test_inband_check_ignores_incoherent_points_and_counts_the_timing_offset():
    meas = _measured(TRUE)
    # a response measured with a 2 ms lag: the model with that timing offset agrees, without it not
    lagged = FreqResp(meas.f_hz, meas.H * np.exp(-2j * np.pi * meas.f_hz * 0.02), meas.sigma, meas.coherence,
                      meas.n_avg, "pooled")
    assert check_model(TRUE, band_hz=(0.1, 10.0), measured=lagged, timing_offset_s=0.02).usable
    assert not check_model(TRUE, band_hz=(0.1, 10.0), measured=lagged).usable
    # incoherent points (coherence 0.1) are not judged at all
    noisy = FreqResp(lagged.f_hz, lagged.H, lagged.sigma, np.full(lagged.f_hz.size, 0.1), lagged.n_avg, "pooled")
    assert inband_errors(TRUE, noisy, (0.1, 10.0)) is None


def test_heldout_threshold_takes_the_noise_share_out():
    # NRMSE 0.30 of which noise 0.28: the model's own share is 0.108 (89 %), usable; without the credit 70 %
    assert check_model(TRUE, band_hz=None, heldout_nrmse=0.30, noise_floor=0.28).usable
    chk = check_model(TRUE, band_hz=None, heldout_nrmse=0.30)
    assert not chk.usable and "below 80 %" in chk.reasons[0]
    # the credit is capped: a floor claimed above the error itself does not make a bad fit pass
    assert not check_model(TRUE, band_hz=None, heldout_nrmse=0.60, noise_floor=0.9).usable


def test_output_error_fit_recovers_a_sub_sample_timing_offset():
    rate = 200.0
    rng = np.random.default_rng(5)
    u = np.concatenate([np.zeros(50), np.repeat(rng.uniform(-1, 1, 400), 10)])   # from rest, as the fit starts
    y = simulate_zoh(TRUE, u, rate, shift=0.4) + 1e-4 * rng.standard_normal(u.size)
    pieces = interleaved(u.size, [(0, u.size)], 200, 0.25, 0)
    start = TFModel(np.array([300.0]), np.array([1.0, 20.0, 300.0]))
    fixed = oe_fit(start, u, y, rate, pieces, max_nfev=90)
    free = oe_fit(start, u, y, rate, pieces, max_nfev=90, max_shift=1.0)
    assert free.shift == pytest.approx(0.4, abs=0.02)
    assert free.nrmse_heldout < 0.5 * fixed.nrmse_heldout
    np.testing.assert_allclose(free.model.den, TRUE.den, rtol=0.02)


def test_diagnose_linear_fit_without_training_samples_is_bad_input():
    from hasel.diagnose.linfit import fit_linear
    from hasel.diagnose.prep import prepare

    t = np.arange(4000) / 100.0
    u = np.repeat(np.random.default_rng(1).uniform(-1, 1, 40), 100)
    p = prepare(t, u, simulate_zoh(TRUE, u, 100.0))
    for r in p.records:
        r.train[:] = False
    with pytest.raises(BadInputError, match="no training samples"):
        fit_linear(p)
