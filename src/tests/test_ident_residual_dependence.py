"""Calibration and power of the residual offset-dependence test (hasel.ident.dependence.residual_dependence)."""
from __future__ import annotations

import numpy as np
from scipy import signal

from hasel.ident.dependence import residual_dependence


def _case(rng, gain_change=0.0, colour=0.95, model_error=0.02):
    """Six operating points of one chirp through a 2nd-order system; coloured noise; a model error shared by all."""
    fs = 200.0
    t = np.arange(int(20 * fs)) / fs
    u = np.sin(2 * np.pi * (0.2 * t + 0.5 * t * t))
    b, a = signal.bilinear([1.0], [1 / (2 * np.pi * 5) ** 2, 0.6 / (2 * np.pi * 5), 1.0], fs)
    truth = signal.lfilter(b, a, u)
    # the fitted model is off by a frequency-dependent error the same at every operating point
    err = signal.lfilter([model_error, -model_error], [1.0], truth)
    ys, yh, pieces = [], [], []
    n = 0
    for k in range(6):
        g = 1.0 + (gain_change if k == 3 else 0.0)
        noise = signal.lfilter([0.01], [1.0, -colour], rng.standard_normal(t.size))
        ys.append(g * truth + noise)
        yh.append(truth - err)
        pieces.append((n, n + t.size))
        n += t.size
    return np.concatenate(ys), np.concatenate(yh), pieces, fs


def test_false_rejection_rate_on_lti_data_is_at_most_5_percent():
    rng = np.random.default_rng(0)
    p = [residual_dependence(*_case(rng)).p_value for _ in range(60)]
    rate = float(np.mean(np.array(p) < 0.05))
    assert rate <= 0.05 + 0.06   # 60 draws: 5 % nominal, binomial 2-sigma margin
    assert 0.0 < float(np.median(p)) < 1.0


def test_a_gain_change_at_one_operating_point_is_detected():
    rng = np.random.default_rng(1)
    r = residual_dependence(*_case(rng, gain_change=0.05))
    assert r.p_value < 1e-3
    assert abs(r.coefficients[3][0] - np.mean([c[0] for c in r.coefficients])) > 0.03
