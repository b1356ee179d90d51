"""The model's output at a fractional sample offset is exact for a held input, and so is the timing estimate.

References are computed independently of the code under test's fractional path: the exact
zero-order-hold simulation of P(s) on a grid 100 times finer than the log (each log sample's
input held over its 100 fine steps), read at the fine sample ``a`` of the way into each interval.
"""
from __future__ import annotations

import numpy as np
import pytest

from hasel import paper
from hasel.diagnose.setup_stages import timing_stage
from hasel.diagnose.prep import LinearSim, at_offset, estimate_timing, prepare

RATE = 100.0     # Hz: P(s) resonates near 19 Hz, so the output is far from straight between samples
FINE = 100       # fine steps per log sample


def _input(n: int, seed: int) -> np.ndarray:
    """Voltage-like input (kV): a slow random walk plus a 3 Hz sine, sampled at RATE."""
    rng = np.random.default_rng(seed)
    t = np.arange(n) / RATE
    return 4.0 + 0.1 * np.cumsum(rng.standard_normal(n)) / np.sqrt(n) * 10 + np.sin(2 * np.pi * 3.0 * t)


def _exact_at(num, den, u: np.ndarray, a: float) -> np.ndarray:
    """y(t_k + a / RATE), mm, for u held over each interval: fine-grid ZOH simulation (offset 0), read off."""
    fine = np.repeat(u, FINE)
    yf = LinearSim(num, den, RATE * FINE, 0.0).run(fine)
    j = int(round(a * FINE))
    if j >= 0:
        out = yf[j::FINE]
    else:   # before the first sample the output is at rest with u[0]
        out = np.concatenate([np.full(-j, yf[0]), yf])[::FINE]
    return out[:u.size]


@pytest.mark.parametrize("a", [0.5, 0.23, -0.37, 0.9])
def test_output_at_a_fractional_offset_is_exact_at_100hz(a):
    num, den = paper.plant_tf()
    u = _input(1500, 1)
    ref = _exact_at(num, den, u, a)
    got = LinearSim(num, den, RATE, a).run(u)
    # the old linear interpolation between interval starts was about 2 um rms off on this input
    assert float(np.max(np.abs(got - ref))) < 1e-8
    # at_offset on the interval-start outputs (what the timing stage uses) gives the same exact numbers,
    # also after scaling them (a fitted gain)
    ys = LinearSim(num, den, RATE, 0.0).run_start(u)
    np.testing.assert_array_equal(at_offset(ys, a), got)
    assert float(np.max(np.abs(at_offset(ys.scaled(1.7), a) - 1.7 * ref))) < 2e-8
    # a plain array keeps the linear interpolation (the old definition), measurably off
    lin = at_offset(ys.ys, a)
    assert float(np.sqrt(np.mean((lin - ref) ** 2))) > 1e-4


def test_zero_offset_is_the_interval_start_simulation_bit_for_bit():
    num, den = paper.plant_tf()
    u = _input(800, 2)
    ys = LinearSim(num, den, RATE, 0.0).run_start(u)
    np.testing.assert_array_equal(LinearSim(num, den, RATE, 0.0).run(u), ys.ys[:-1])
    np.testing.assert_array_equal(at_offset(ys, 0.0), ys.ys[:-1])


def test_zohat_states_give_every_fraction():
    """ZohAt: the states once, any fraction by its row (mm), against the fine-grid reference."""
    from hasel.lti import ZohAt

    num, den = paper.plant_tf()
    u = _input(1000, 3)
    z = ZohAt(num, den, 1.0 / RATE)
    X = z.states(u)
    for a in (0.0, 0.31, 0.77):
        c, d = z.rows(a)
        assert float(np.max(np.abs(X @ c + d * u - _exact_at(num, den, u, a)))) < 1e-8


@pytest.mark.parametrize("true", [0.5, -0.3])
def test_timing_offset_of_an_effect_free_log_is_estimated_exactly(true):
    """An effect-free 100 Hz log sampled centred (or with a skewed output clock) and 5 um white noise:
    the offset estimated on the interval-start outputs is within 0.002 sample of the truth (the closed
    form on the linear interpolation was 0.008-0.01 sample off on these logs)."""
    num, den = paper.plant_tf()
    n = 3000
    u = _input(n, 4)
    y = _exact_at(num, den, u, true) + 0.005 * np.random.default_rng(5).standard_normal(n)
    mask = np.ones(n, bool)
    mask[:50] = False
    ys = LinearSim(num, den, RATE, 0.0).run_start(u)
    a, sse = estimate_timing(ys, y, mask, -1.0, 1.0)
    assert abs(a - true) < 2e-3
    assert sse / mask.sum() < 1.2 * 0.005 ** 2          # down to the noise
    a2, _ = estimate_timing(ys.scaled(0.8), 0.8 * y, mask, -1.0, 1.0)   # a gain fitted beside it changes nothing
    assert abs(a2 - a) < 1e-6


def test_timing_stage_on_a_centred_log():
    """The pipeline's timing stage (with its nuisance load) on an effect-free centred 100 Hz log of P(s):
    the refined sampling offset is half a sample within 0.003 sample."""
    num, den = paper.plant_tf()
    n = 3000
    u = _input(n, 6)
    y = _exact_at(num, den, u, 0.5) + 0.005 * np.random.default_rng(7).standard_normal(n)
    prep = prepare(np.arange(n) / RATE, u, y, model_den=den, target_rate_hz=RATE)
    assert prep.decimation == 1
    timing_stage(prep, np.asarray(num, float), np.asarray(den, float), 0.0, lambda *_: None)
    assert abs(float(prep.sample_offset) - 0.5) < 3e-3


def test_a_model_identified_from_the_log_is_simulated_as_it_was_fitted():
    """``exact=False`` (a model identified by hasel.ident's interpolating simulation) interpolates linearly
    between interval starts, bit for bit the old path; the exact read differs from it by micrometres."""
    num, den = paper.plant_tf()
    u = _input(600, 3)
    plain = LinearSim(num, den, RATE, 0.4, exact=False)
    run = plain.run_start(u)
    assert run.sim is None                         # no model memory: at_offset / estimate_timing interpolate
    ys = run.ys
    lin = ys[:-1] + 0.4 * (ys[1:] - ys[:-1])
    np.testing.assert_array_equal(plain.run(u), lin)
    exact = LinearSim(num, den, RATE, 0.4).run(u)
    gap = float(np.max(np.abs(exact - lin)))
    assert 1e-4 < gap < 1e-2                       # mm: the interpolation error at 100 Hz, not a different model
    np.testing.assert_allclose(exact, _exact_at(num, den, u, 0.4), atol=1e-8)


def test_the_model_stage_turns_the_exact_read_off_only_for_an_identified_model():
    """Given a model the prepared log keeps ``exact_offset``; identifying one from the log turns it off."""
    from hasel.diagnose.core import DiagnoseOptions
    from hasel.diagnose.setup_stages import _model_stage
    rng = np.random.default_rng(5)
    n = 4000
    t = np.arange(n) / 200.0
    u = 4.0 + 1.5 * np.sign(np.sin(2 * np.pi * 0.7 * t)) + 0.5 * np.sin(2 * np.pi * 5.0 * t)
    num, den = paper.plant_tf()
    y = LinearSim(num, den, 200.0, 0.0).run(u) + 0.002 * rng.standard_normal(n)
    opts = DiagnoseOptions(identify="internal")
    given = prepare(t, u, y)
    _model_stage(given, np.asarray(num, float), np.asarray(den, float), {"source": "given"}, opts, lambda m: None)
    assert given.exact_offset
    ident = prepare(t, u, y)
    _, _, src, _, _ = _model_stage(ident, None, None, {}, opts, lambda m: None)
    assert src["source"] == "identified from the log" and not ident.exact_offset


def test_a_model_fitted_with_the_interpolating_read_keeps_it_and_block_means_are_read_exactly():
    """A given model whose JSON says ``sample_read: interpolated`` (hasel identify's) is simulated that way; the
    exact P(s) on a log reduced by block means (decimation > 1) is read exactly."""
    from hasel.diagnose.core import DiagnoseOptions
    from hasel.diagnose.setup_stages import _model_stage, _nominal_model
    rng = np.random.default_rng(7)
    fs = 2000.0
    n = 16000
    t = np.arange(n) / fs
    u = 4.0 + 1.5 * np.sign(np.sin(2 * np.pi * 0.7 * t)) + 0.5 * np.sin(2 * np.pi * 5.0 * t)
    num, den = paper.plant_tf()
    y = LinearSim(num, den, fs, 0.0).run(u) + 0.002 * rng.standard_normal(n)
    opts = DiagnoseOptions()
    exact = prepare(t, u, y, target_rate_hz=500.0)
    assert exact.decimation > 1
    n0, d0, src = _nominal_model({"num": list(num), "den": list(den)})
    _model_stage(exact, n0, d0, src, opts, lambda m: None)
    assert exact.exact_offset and "sample_read" not in src
    fitted = prepare(t, u, y, target_rate_hz=500.0)
    n1, d1, src1 = _nominal_model({"num": list(num), "den": list(den), "sample_read": "interpolated"})
    assert src1["sample_read"] == "interpolated"
    n2, d2, src2, _, _ = _model_stage(fitted, n1, d1, src1, opts, lambda m: None)
    assert not fitted.exact_offset
    # the given model is kept (not identified again), with its source
    np.testing.assert_array_equal(n2, n1)
    np.testing.assert_array_equal(d2, d1)
    assert src2["source"] == "given" and "nominal_scale" in src2


def test_hasel_identify_says_how_its_fit_read_the_samples():
    """The model JSON of hasel.ident states the interpolating read (so diagnose simulates it the same way)."""
    from hasel.ident import identify as ident_identify
    rng = np.random.default_rng(3)
    fs = 200.0
    t = np.arange(int(60 * fs)) / fs
    u = 4.0 + np.sin(2 * np.pi * (0.1 + 0.2 * t) * t) + 1.0 * (t > 30)
    num, den = paper.plant_tf()
    y = LinearSim(num, den, fs, 0.0).run(u) + 0.002 * rng.standard_normal(t.size)
    mj = ident_identify(t, u, y).to_model_json()
    assert mj["sample_read"] == "interpolated"
