"""The operating-point dependence test (hasel.ident.dependence)."""
from __future__ import annotations

import numpy as np
import pytest

from hasel import paper
from hasel.errors import BadInputError
from hasel.ident.dependence import offset_dependence
from hasel.ident.freqresp import FreqResp
from hasel.lti import tf_freqresp

F = np.geomspace(0.2, 15.0, 120)
NUM, DEN = paper.plant_tf()
P = tf_freqresp(NUM, DEN, F)


def _resp(rng, H, rel, offset):
    """A response with complex Gaussian errors of standard deviation rel |H| (sigma as welch_h1 reports)."""
    sigma = rel * np.abs(H)
    noise = sigma / np.sqrt(2) * (rng.standard_normal(H.size) + 1j * rng.standard_normal(H.size))
    return FreqResp(F, H + noise, sigma, np.full(F.size, 0.99), np.full(F.size, 10), "welch_h1", offset)


def test_same_dynamics_are_independent_and_p_values_are_calibrated():
    rng = np.random.default_rng(0)
    ps = []
    for _ in range(200):
        res = [_resp(rng, P, 0.02, v) for v in (2.0, 3.0, 4.0)]
        ps.append(offset_dependence(res, thin=1).p_value)
    ps = np.array(ps)
    # uniform under the hypothesis: about 5 % below 0.05, median near 0.5
    assert 0.01 <= np.mean(ps < 0.05) <= 0.10
    assert 0.4 < np.median(ps) < 0.6
    t = offset_dependence([_resp(rng, P, 0.02, v) for v in (2.0, 3.0, 4.0)], thin=1, unit="kV")
    assert t.dof == 2 * 2 * F.size
    assert t.verdict == "independent" or t.p_value < 0.01
    assert "kV" in t.summary and t.band_hz == (pytest.approx(F[0]), pytest.approx(F[-1]))


def test_a_gain_change_with_the_offset_is_dependent():
    rng = np.random.default_rng(1)
    res = [_resp(rng, P * (1 + 0.05 * k), 0.01, 2.0 + k) for k in range(4)]  # +5 % per kV: 1.3 dB spread
    t = offset_dependence(res, thin=1)
    assert t.verdict == "dependent" and t.p_value < 1e-10
    assert t.spread_db == pytest.approx(20 * np.log10(1.15), abs=0.15)
    devs = [q["mean_dev_db"] for q in t.per_offset]
    assert devs == sorted(devs)  # the deviation grows with the offset


def test_a_tiny_but_significant_change_is_weak():
    rng = np.random.default_rng(2)
    res = [_resp(rng, P * (1 + 0.01 * k), 0.001, 2.0 + k) for k in range(3)]  # 1 % change, 0.1 % noise
    t = offset_dependence(res, thin=1)
    assert t.verdict == "weakly_dependent" and t.p_value < 1e-6
    assert t.spread_db == pytest.approx(20 * np.log10(1.02), abs=0.02)


def test_untestable_and_bad_grids():
    rng = np.random.default_rng(3)
    one = _resp(rng, P, 0.01, 2.0)
    assert offset_dependence([one]).verdict == "untestable"
    incoherent = FreqResp(F, P, np.full(F.size, 0.1), np.full(F.size, 0.2), np.ones(F.size, int), "welch_h1", 3.0)
    assert offset_dependence([one, incoherent]).verdict == "untestable"
    other = FreqResp(F * 1.1, P, one.sigma, one.coherence, one.n_avg, "welch_h1", 3.0)
    with pytest.raises(BadInputError, match="share their frequencies"):
        offset_dependence([one, other])
