"""The working-rate model of block means (diagnosis of logs above the working rate).

A log above the ~400 Hz working rate is brought down by block means of ``q`` samples. The
working-rate simulation must reproduce those block means, not hold each block's mean input and
interpolate the output: that differs by a fixed gain error of relative size about
(2 pi f T)^2 / 6 (0.8 % at 15 Hz for T = 2.5 ms), a few micrometres, which a quiet sensor
resolves and which ``load_mass`` absorbs (bench/tune_diag/RESULT-e-free.md, RESULT-h-efree2.md).
"""
from __future__ import annotations

import numpy as np

from hasel import paper
from hasel.diagnose import diagnose
from hasel.diagnose.prep import LinearSim, prepare
from hasel_bench import othersim as o


def _block_means(x: np.ndarray, q: int) -> np.ndarray:
    n = (x.size // q) * q
    return x[:n].reshape(-1, q).mean(axis=1)


def _multisine(rate_hz: float, dur_s: float) -> np.ndarray:
    """A 0.5-15 Hz multisine around 4 kV (kV), sampled at ``rate_hz``."""
    t = np.arange(int(round(rate_hz * dur_s))) / rate_hz
    rng = np.random.default_rng(11)
    f = np.arange(0.5, 15.01, 0.5)
    return 4.0 + 0.25 * np.sum(np.sin(2 * np.pi * f[:, None] * t + rng.uniform(0, 2 * np.pi, f.size)[:, None]),
                               axis=0) / np.sqrt(f.size / 2)


def test_working_model_matches_exact_block_means_of_a_fine_simulation():
    num, den = paper.plant_tf()
    fs = 5000.0
    u = _multisine(fs, 8.0)
    y = LinearSim(num, den, fs, 0.0).run(u)   # the exact ZOH output at the original rate, mm
    prep = prepare(np.arange(u.size) / fs, u, y, model_den=den, target_rate_hz=400.0)
    q = prep.decimation
    assert q == 12
    exact = _block_means(y, q)
    r = prep.records[0]
    model = LinearSim(num, den, prep.rate_hz, prep.sample_offset).run(r.u)
    err = (exact - model)[400:]   # past the first second (both start at rest with their first input)
    held = LinearSim(num, den, prep.rate_hz, float(prep.sample_offset))
    old = (exact - at_mean_hold(held, r.u))[400:]
    rms = float(np.sqrt(np.mean(err ** 2)))
    rms_old = float(np.sqrt(np.mean(old ** 2)))
    sig = float(np.std(exact))
    # the hold-and-interpolate model is off by ~0.05 % of the signal (0.17 um here)
    assert rms_old > 3e-4 * sig
    # the block-mean model: under a hundredth of that, under 0.01 um
    assert rms < 0.01 * rms_old
    assert rms < 1e-5
    assert np.max(np.abs(err)) < 0.1 * np.max(np.abs(old))


def at_mean_hold(sim: LinearSim, u: np.ndarray) -> np.ndarray:
    """The hold-and-interpolate simulation (each block's mean input held, output read at the offset)."""
    from hasel.diagnose.prep import at_offset
    return at_offset(sim.run_start(u), sim.offset)


def test_no_change_at_the_original_rate():
    """q = 1 (a log at or below the working rate): the simulation is exactly the held-input one."""
    num, den = paper.plant_tf()
    fs = 400.0
    u = _multisine(fs, 10.0)
    y = LinearSim(num, den, fs, 0.0).run(u)
    prep = prepare(np.arange(u.size) / fs, u, y, model_den=den)
    assert prep.decimation == 1
    a = prep.sample_offset
    assert a == 0.0
    ru = prep.records[0].u
    assert type(a) is float
    got = LinearSim(num, den, prep.rate_hz, a).run(ru)
    np.testing.assert_array_equal(got, at_mean_hold(LinearSim(num, den, prep.rate_hz, 0.0), ru))
    assert float(np.max(np.abs(got - y))) < 1e-9   # and it is the log's own output
    prep.sample_offset = 0.3   # a timing offset estimated later stays a plain offset
    assert type(prep.sample_offset) is float
    got = LinearSim(num, den, prep.rate_hz, prep.sample_offset).run(ru)
    np.testing.assert_array_equal(got, at_mean_hold(LinearSim(num, den, prep.rate_hz, 0.3), ru))


def test_refined_offset_keeps_the_block_mean_model():
    """The timing stage sets a refined offset on the prepared log; the block-mean model must stay."""
    num, den = paper.plant_tf()
    fs = 5000.0
    u = _multisine(fs, 6.0)
    y = LinearSim(num, den, fs, 0.0).run(u)
    prep = prepare(np.arange(u.size) / fs, u, y, model_den=den, target_rate_hz=400.0)
    q = prep.decimation
    prep.sample_offset = float(prep.sample_offset) + 0.5 / q   # the output half an original sample later
    exact = _block_means(LinearSim(num, den, fs, 0.5).run(u), q)
    model = LinearSim(num, den, prep.rate_hz, prep.sample_offset).run(prep.records[0].u)
    assert float(np.sqrt(np.mean((exact - model)[400:] ** 2))) < 1e-5


def test_quiet_5khz_effect_free_log_names_nothing():
    """free_noise.py --quiet seed 3 log quiet_20: P(s) under the paper's short excitation at 5 kHz, ZOH, white
    0.5 um; the hold-and-interpolate model named ``load_mass`` here (its error ~0.3 um rms against a block-mean
    floor of 0.14 um)."""
    num, den = paper.plant_tf()
    rate, sd = 5000.0, 0.0005
    rng = np.random.default_rng([3, 1020])
    rng.uniform(-0.45, 0.45)                     # the skew draw of the grid (unused for ZOH)
    rng.standard_normal(int(round(15.0 * rate)))  # the closed-loop noise draw of the grid (unused)
    u = o.excitation(rng, rate, short=True)[0]
    y = LinearSim(num, den, rate, 0.0).run(u) + sd * rng.standard_normal(u.size)
    v = diagnose(np.arange(u.size) / rate, u, y, model={"num": num.tolist(), "den": den.tolist()},
                 units=("kV", "mm"))
    assert v.names == []
