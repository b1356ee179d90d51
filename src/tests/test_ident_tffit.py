"""Transfer-function fit to frequency-response data (hasel.ident.tffit)."""
from __future__ import annotations

import numpy as np
import pytest

from hasel import paper
from hasel.errors import BadInputError
from hasel.ident.tffit import default_orders, fit_tf, fit_tf_order
from hasel.lti import tf_freqresp

F = np.geomspace(0.1, 40.0, 160)


def _noisy(H, rel, rng):
    return H * (1 + rel / np.sqrt(2) * (rng.standard_normal(H.size) + 1j * rng.standard_normal(H.size)))


def _sorted(r):
    r = np.asarray(r, complex)
    return r[np.lexsort((np.imag(r), np.real(r)))]


def test_fixed_order_recovers_a_known_tf_exactly_from_clean_data():
    # zero at -30 rad/s, poles -5 and a 12 Hz pair, zeta 0.3
    wn = 2 * np.pi * 12
    num = 40.0 * np.array([1.0, 30.0])
    den = np.polymul([1.0, 5.0], [1.0, 2 * 0.3 * wn, wn**2])
    fit = fit_tf_order(F, tf_freqresp(num, den, F), 1, 3)
    np.testing.assert_allclose(_sorted(fit.model.poles), _sorted(np.roots(den)), rtol=1e-6)
    np.testing.assert_allclose(fit.model.zeros, [-30.0], rtol=1e-6)
    np.testing.assert_allclose(fit.model.num, num / den[0], rtol=1e-6)
    np.testing.assert_allclose(fit.model.den, den, rtol=1e-6)
    assert fit.model.dc_gain == pytest.approx(num[-1] / den[-1], rel=1e-9)
    assert fit.max_db < 1e-6 and fit.fit_percent > 99.9999


def test_order_selection_picks_the_true_order_of_a_second_order_system():
    rng = np.random.default_rng(0)
    wn = 2 * np.pi * 5.0
    H = tf_freqresp([2 * wn**2], [1.0, 2 * 0.25 * wn, wn**2], F)
    fit = fit_tf(F, _noisy(H, 0.01, rng), sigma=0.01 * np.abs(H))
    assert (fit.nz, fit.np) == (0, 2)
    np.testing.assert_allclose(fit.model.den, [1.0, 2 * 0.25 * wn, wn**2], rtol=0.01)
    assert fit.model.dc_gain == pytest.approx(2.0, rel=0.005)
    assert 0.7 < fit.cost < 1.3  # fits to the noise, not beyond
    assert {(s.nz, s.np) for s in fit.scores} >= {(0, 1), (0, 2), (1, 2)}


def test_fit_of_the_papers_plant_from_noisy_data():
    rng = np.random.default_rng(1)
    num, den = paper.plant_tf()
    H = tf_freqresp(num, den, F)
    fit = fit_tf(F, _noisy(H, 0.005, rng), sigma=0.005 * np.abs(H))
    f = np.geomspace(0.1, 15.0, 300)
    r = fit.model.freqresp(f) / tf_freqresp(num, den, f)
    assert np.max(np.abs(20 * np.log10(np.abs(r)))) < 0.1
    assert np.max(np.abs(np.degrees(np.angle(r)))) < 1.0
    assert fit.model.dc_gain == pytest.approx(num[-1] / den[-1], rel=0.005)
    # the notch of P(s): a zero pair near +-122.2j rad/s
    z = fit.model.zeros
    assert np.min(np.abs(z - 122.2j)) < 1.0
    assert np.all(np.real(fit.model.poles) < 0)


def test_stable_poles_are_enforced():
    # data of unstable systems: whatever the fit makes of them, its poles are stable
    for den in ([1.0, -10.0], [1.0, -3.0, 400.0], np.polymul([1.0, 2.0], [1.0, -1.0, 900.0])):
        H = tf_freqresp([10.0], den, F)
        for n_p in (1, 2, 3):
            fit = fit_tf_order(F, H, 0, n_p)
            assert np.all(np.real(fit.model.poles) < 0)
            assert np.isfinite(fit.cost)


def test_input_delay_is_fitted():
    H = tf_freqresp([20.0], [1.0, 20.0], F) * np.exp(-2j * np.pi * F * 0.005)
    fit = fit_tf_order(F, H, 0, 1, delay=True)
    assert fit.model.delay_s == pytest.approx(0.005, rel=0.01)
    assert fit.model.poles[0].real == pytest.approx(-20.0, rel=0.01)


def test_bad_fit_inputs_raise():
    with pytest.raises(BadInputError, match="proper"):
        fit_tf_order(F, np.ones(F.size), 3, 2)
    with pytest.raises(BadInputError, match="at least 4 usable"):
        fit_tf(F[:3], np.ones(3))
    with pytest.raises(BadInputError, match="same length"):
        fit_tf(F, np.ones(5))
    assert default_orders(2) == [(0, 1), (1, 1), (0, 2), (1, 2), (2, 2)]
