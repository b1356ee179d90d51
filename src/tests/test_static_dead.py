"""The input map's dead-band form (``static_nonlinearity``, variant ``input:dead``).

A HASEL does not move below a threshold voltage. Logs here are simulated by this file's own code (scipy's
zero-order-hold P(s), no hasel effect class): a raised-cosine log chirp from 0 kV to 7 kV at 500 Hz for
20 s (a HASEL driven from 0 kV), white noise of 0.005 mm, the exact P(s) as the nominal model.

- a hard dead band of 0.8 kV (``g sign(v) max(|v| - 0.8, 0)``, the gain meeting the nominal line at
  6 kV) is named ``static_nonlinearity`` in the dead-band form, its threshold within 0.05 kV and its gain
  within 2 %, the held-out error under 5 % of the nominal's, and no sensor curve or load beside it (``bench/tune_diag/multi2.py`` seed 21, ``m2_00``:
  before the form, a smooth dead band of 0.38 kV was named ``load_mass`` and ``sensor_nonlinearity``);
- a sensor curve (``L tanh(z / L)``, ``L`` 12 mm) is still named ``sensor_nonlinearity`` alone;
- an effect-free log is named nothing, and the family's fit on it does not take the form;
- a bend whose flat zone the input never reaches (the band's own form, threshold 2.2 kV, corner 0.5 kV,
  driven 1.5-7 kV: a convex curve with an offset there, as the cascaded tanks' pump curve) is fitted by
  the form exactly and preferred by the training BIC, yet the input side takes the polynomial: the data
  see the corner, not a flat zone (``dead_visited``); the hard band's fit passes that rule.
"""
from __future__ import annotations

import numpy as np
import pytest

from hasel import paper
from hasel.effects.base import EffectFit, run_chunked
from hasel.effects.fitkit import bic_prefers
from hasel.effects.registry import family
from hasel.effects.static_map import DEAD, dead_map, dead_visited, dead_zone_shares

from designs import cosine_chirp, diagnose_noisy, zoh_stroke

RATE = 500.0
DUR = 20.0
NOISE_MM = 0.005


def _diagnose(u: np.ndarray, z: np.ndarray, seed: int):
    """The diagnosis of this file's log (RATE, NOISE_MM white noise from ``seed``, exact P(s))."""
    return diagnose_noisy(u, z, seed, RATE, NOISE_MM)


THRESHOLD_KV = 0.8
GAIN = 6.0 / (6.0 - THRESHOLD_KV)


@pytest.fixture(scope="module")
def dead_band():
    u = cosine_chirp(RATE, DUR)
    v = np.sign(u) * np.maximum(np.abs(u) - THRESHOLD_KV, 0.0) * GAIN
    return _diagnose(u, zoh_stroke(v, RATE), 1)


@pytest.fixture(scope="module")
def sensor_curve():
    u = cosine_chirp(RATE, DUR)
    z = zoh_stroke(u, RATE)
    return _diagnose(u, 12.0 * np.tanh(z / 12.0), 2)


@pytest.fixture(scope="module")
def free_log():
    u = cosine_chirp(RATE, DUR)
    return _diagnose(u, zoh_stroke(u, RATE), 3)


def test_a_dead_band_is_named_with_its_threshold(dead_band):
    v = dead_band
    assert v.names == ["static_nonlinearity"]
    m = v.effects[0]["params"]
    assert m["variant"] == DEAD
    assert m["threshold"] == pytest.approx(THRESHOLD_KV, abs=0.05)
    assert m["threshold_unit"] == "kV" and m["width_unit"] == "kV"
    assert m["gain"] == pytest.approx(GAIN, rel=0.02)
    assert 0.0 < m["share_within_threshold"] < 0.5
    assert m["share_flat"] > 0.1  # the chirp dwells near 0 kV: about a fifth of it below 0.73 kV
    # near the noise floor (0.005 mm): nothing left for a load or a sensor curve
    assert v.heldout["gap_shrink"] > 0.95
    assert v.heldout["nrmse_augmented"] < 0.05 * v.heldout["nrmse_nominal"]


def test_a_sensor_curve_stays_a_sensor_curve(sensor_curve):
    assert sensor_curve.names == ["sensor_nonlinearity"]


def test_an_effect_free_log_is_not_given_the_form(free_log):
    from hasel.diagnose.augment import Pipeline
    from hasel.diagnose.prep import prepare

    assert free_log.names == []
    u = cosine_chirp(RATE, DUR)
    y = zoh_stroke(u, RATE) + NOISE_MM * np.random.default_rng(3).standard_normal(u.size)
    num, den = paper.plant_tf()
    pipe = Pipeline(prepare(np.arange(u.size) / RATE, u, y, model_den=den), num, den)
    fit = family("static_nonlinearity").fit(pipe, {})
    assert fit is not None and fit.variant != DEAD


def test_the_dead_band_form_runs_in_chunks_and_is_described_with_units():
    from types import SimpleNamespace

    fam = family("static_nonlinearity")
    fit = EffectFit("static_nonlinearity", DEAD, (0.8, 1.15, 0.03))
    assert fam.param_names(fit) == ("threshold", "gain", "width") and fit.slot == 2
    sc = SimpleNamespace(u_c=3.5, u_s=3.5, y_c=4.0, y_s=3.0)
    x = cosine_chirp(RATE, DUR)
    whole = fam.simulate(fit, x, sc, 1.0 / RATE)
    np.testing.assert_array_equal(run_chunked(fam.stage(fit, sc, 1.0 / RATE), x, 10), whole)
    # nothing below the threshold, the gain beyond it, odd through 0 kV
    assert abs(float(dead_map(fit.theta, np.array([0.5]))[0])) < 1e-4
    assert float(dead_map(fit.theta, np.array([5.0]))[0]) == pytest.approx(1.15 * (5.0 - 0.8), rel=1e-6)
    np.testing.assert_allclose(dead_map(fit.theta, -x), -dead_map(fit.theta, x), atol=1e-12)
    lo, hi = fam.bounds(sc, fit)
    assert np.all(np.asarray(fit.theta) >= lo) and np.all(np.asarray(fit.theta) <= hi)


def test_a_bend_without_a_flat_zone_in_reach_is_the_polynomials():
    from hasel.diagnose.augment import Pipeline
    from hasel.diagnose.prep import prepare
    from hasel.effects import static_map as sm
    from hasel.effects.fitkit import _sse, _with

    # 1.5-7 kV: the band's flat zone (below 2.2 - 2.2 * 0.5 kV) never reached
    u = 1.5 + cosine_chirp(RATE, DUR) * (5.5 / 7.0)
    truth = (2.2, 1.4, 0.5)
    y = zoh_stroke(dead_map(truth, u), RATE) + NOISE_MM * np.random.default_rng(4).standard_normal(u.size)
    num, den = paper.plant_tf()
    pipe = Pipeline(prepare(np.arange(u.size) / RATE, u, y, model_den=den), num, den)
    dead = sm.fit_dead(pipe, {})
    assert dead is not None and dead.theta[0] == pytest.approx(2.2, abs=0.02)
    assert dead.theta[2] == pytest.approx(0.5, abs=0.02)
    poly = sm.fit_variant(pipe, {}, "input")
    x = sm._map_inputs(pipe, {})
    # the form fits the bend better than the polynomial, by the BIC too ...
    assert bic_prefers(x.size, _sse(pipe, _with({}, poly)), _sse(pipe, _with({}, dead)),
                       dead.n_params - poly.n_params)
    # ... but none of the input is flat and over a third lies on the corner: a curve, the polynomial's
    flat, corner = dead_zone_shares(dead.theta, x)
    assert flat == 0.0 and corner > 0.3
    assert not dead_visited(dead.theta, x)
    assert sm.fit_input_side(pipe, {}).variant == "input"


def test_the_flat_zone_and_the_corner_are_counted_where_the_slope_says():
    theta = (0.8, 1.15, 0.03)  # flat below 0.8 - 2.197 * 0.03 = 0.734 kV, corner up to 0.866 kV
    x = np.linspace(0.0, 7.0, 7001)
    flat, corner = dead_zone_shares(theta, x)
    assert flat == pytest.approx(0.734 / 7.0, abs=2e-3)
    assert corner == pytest.approx(0.132 / 7.0, abs=2e-3)
    assert dead_visited(theta, x)
    assert not dead_visited(theta, x[x > 1.0])  # no input below the threshold: not seen as a band
