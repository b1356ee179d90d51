"""How the identification's simulation reads the output between interval starts (session 14, branch h-ident4).

The truth is the paper's P(s) driven by a held (zero-order-hold) input and simulated on a grid 64 times finer
(hasel.lti's exact ZOH sections), its output read at a fraction of the sample or averaged over blocks of raw
samples; :func:`hasel.ident.timefit.simulate_zoh` must reproduce it from the coarse samples alone.
"""
from __future__ import annotations

import numpy as np
import pytest
from scipy import signal

import designs
from hasel.ident import identify
from hasel.ident.identify import SAMPLE_READ, SAMPLE_READ_EXACT
from hasel.ident.tffit import TFModel
from hasel.ident.timefit import simulate_zoh
from hasel.lti import zoh_sos
from hasel.paper import plant_tf

FINE = 64


def _truth(u: np.ndarray, rate_hz: float, num, den) -> np.ndarray:
    """The continuous output on a grid FINE times finer than ``u``'s (input held), from rest, mm."""
    yf = signal.sosfilt(zoh_sos(num, den, 1.0 / (rate_hz * FINE), output="start"), np.repeat(u, FINE))
    return yf


def _input(n: int) -> np.ndarray:
    rng = np.random.default_rng(0)
    u = np.repeat(rng.uniform(-1.0, 1.0, n // 10), 10)
    u[0] = 0.0
    return u


# the paper's P(s) has a double pole pair (the state-space path); the perturbed one has distinct poles (the
# partial fractions)
_NUM, _DEN = plant_tf()
_PERTURBED = np.real(np.poly(np.roots(_DEN) * np.array([1.0, 1.0, 1.02, 1.02, 1.0, 1.0])))


@pytest.mark.parametrize("den", [_DEN, _PERTURBED], ids=["repeated_poles", "distinct_poles"])
def test_the_exact_read_at_a_fraction_of_the_sample_matches_the_fine_simulation(den):
    """Reads at +0.5, +0.75 samples (on the fine grid exactly): exact to 1e-9 mm; the interpolation is off by 4 um.

    At +-0.3 the fine grid itself is 0.2 % of a sample off (19.2 fine steps rounded): 0.5 um, the interpolation 4 um.
    """
    rate, n = 200.0, 2000
    u = _input(n)
    yf = _truth(u, rate, _NUM, den)
    m = TFModel(num=np.asarray(_NUM, float), den=np.asarray(den, float))
    k = np.arange(n)
    for sh, tol in ((0.5, 1e-9), (0.75, 1e-9), (0.3, 1e-3), (-0.3, 1e-3)):
        truth = yf[np.clip(k * FINE + int(round(sh * FINE)), 0, yf.size - 1)]
        ex = simulate_zoh(m, u, rate, shift=sh, read="exact")
        lin = simulate_zoh(m, u, rate, shift=sh, read="interpolated")
        assert np.max(np.abs(ex - truth)[5:-5]) < tol
        assert np.max(np.abs(lin - truth)[5:-5]) > 3e-3


def test_the_default_read_is_exact_for_block_means_and_interpolated_for_raw_samples():
    """``READ = "blocks"``: raw samples (block 1) read as before (interpolated), means of 8 or more exactly.

    Block means of 8 raw samples of a held input, 2.5 raw samples late: the exact block read matches the block
    means of the fine simulation to 1e-9 mm, the interpolated read at the block's mean time is off by 1.5 um.
    """
    rate, blk, n = 1000.0, 8, 4000
    rng = np.random.default_rng(1)
    ub = np.repeat(rng.uniform(-1.0, 1.0, n // blk // 10), 10)   # held over whole blocks
    ub[0] = 0.0
    u = np.repeat(ub, blk)
    yf = _truth(u, rate, _NUM, _PERTURBED)
    m = TFModel(num=np.asarray(_NUM, float), den=_PERTURBED)
    shift_raw = 2.5
    raw = yf[np.clip(np.arange(n) * FINE + int(round(shift_raw * FINE)), 0, yf.size - 1)]
    means = raw.reshape(-1, blk).mean(axis=1)
    got = simulate_zoh(m, ub, rate / blk, block=blk, shift=shift_raw / blk)
    lin = simulate_zoh(m, ub, rate / blk, block=blk, shift=shift_raw / blk, read="interpolated")
    assert np.max(np.abs(got - means)[3:-3]) < 1e-9
    assert np.max(np.abs(lin - means)[3:-3]) > 1e-3
    # raw samples: the default is the interpolated read (bit for bit)
    y1 = simulate_zoh(m, u, rate, shift=0.3)
    assert np.array_equal(y1, simulate_zoh(m, u, rate, shift=0.3, read="interpolated"))


def test_the_model_json_says_which_read_it_was_fitted_with():
    """A 10 kHz log is fitted on block means of 40 raw samples (exact read), 1 kHz (blocks of 4) and 200 Hz logs
    by interpolation; each model is usable and within 1 dB / 5 deg of P(s)."""
    for rate, want in ((10000.0, SAMPLE_READ_EXACT), (1000.0, SAMPLE_READ), (200.0, SAMPLE_READ)):
        log = designs.make_log("paper_chirp", rate, seed=3)
        r = identify(log.t_s, log.u_kv, log.y_mm, input_name="voltage_kv", output_name="stroke_mm")
        assert r.to_model_json()["sample_read"] == want
        assert r.usable
        cmp_ = r.paper_comparison()
        assert cmp_["max_db"] <= 1.0 and cmp_["max_deg"] <= 5.0


def test_diagnose_reads_a_model_fitted_on_exact_block_means_exactly():
    """A given model JSON with ``sample_read: exact`` is simulated exactly by hasel diagnose (as one without the key);
    ``interpolated`` keeps the interpolating read."""
    from hasel.diagnose.core import DiagnoseOptions, _model_stage, _nominal_model
    from hasel.diagnose.prep import LinearSim, prepare

    rng = np.random.default_rng(7)
    fs = 2000.0
    t = np.arange(16000) / fs
    u = 4.0 + 1.5 * np.sign(np.sin(2 * np.pi * 0.7 * t)) + 0.5 * np.sin(2 * np.pi * 5.0 * t)
    y = LinearSim(_NUM, _DEN, fs, 0.0).run(u) + 0.002 * rng.standard_normal(t.size)
    for read, exact in ((SAMPLE_READ_EXACT, True), (SAMPLE_READ, False)):
        prep = prepare(t, u, y, target_rate_hz=500.0)
        n0, d0, src = _nominal_model({"num": list(_NUM), "den": list(_DEN), "sample_read": read})
        _model_stage(prep, n0, d0, src, DiagnoseOptions(), lambda m: None)
        assert prep.exact_offset is exact
