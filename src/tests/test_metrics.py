"""hasel.metrics: step metrics against closed forms."""
from __future__ import annotations

import math

import numpy as np
import pytest

from hasel.metrics import step_metrics


def test_first_order_rise_and_settling_closed_form():
    tau = 0.05
    t = np.arange(0, 2, 1e-4)
    y = 2.0 + 2.0 * (1 - np.exp(-(t - 0.5) / tau)) * (t >= 0.5)
    m = step_metrics(t, y, 0.5, 2.0, 2.0, 4.0)
    assert m.mode == "activation"
    assert m.rise_s == pytest.approx(tau * math.log(9), rel=1e-3)  # 10-90 % of a lag
    assert m.settling_s == pytest.approx(tau * math.log(20), abs=2e-4)  # 5 % band
    assert m.overshoot_pct == 0.0


def test_relaxation_with_overshoot():
    t = np.arange(0, 1, 1e-4)
    wn, zeta = 40.0, 0.3
    wd = wn * math.sqrt(1 - zeta**2)
    s = 1 - np.exp(-zeta * wn * t) * (np.cos(wd * t) + zeta / math.sqrt(1 - zeta**2) * np.sin(wd * t))
    y = 6.0 - 2.0 * s
    m = step_metrics(t, y, 0.0, 1.0, 6.0, 4.0)
    assert m.mode == "relaxation"
    assert m.overshoot_pct == pytest.approx(100 * math.exp(-zeta * math.pi / math.sqrt(1 - zeta**2)), rel=1e-3)


def test_never_reached_gives_nan():
    t = np.arange(0, 1, 1e-3)
    m = step_metrics(t, np.full(t.size, 2.0), 0.0, 1.0, 2.0, 12.0)
    assert math.isnan(m.rise_s) and math.isnan(m.settling_s)
    assert m.to_json()["rise_s"] is None
