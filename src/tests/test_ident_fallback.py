"""An order the held-out data chose but whose response they do not pin yields to a lower one (session 38, h-fallback).

:func:`hasel.ident.identify` chooses the order on held-out data; check 6 then refuses a model whose response the
fit's covariance does not pin to the tolerance (a parameter the data cannot support). When that is the only reason,
the search runs again below that order, and the lower model is kept if it passes every check and fits the held-out
data within 10 % of the refused one.
"""
from __future__ import annotations

import numpy as np

import designs
from hasel.ident import identify


def _closed_loop_with_feed_forward(seed: int, fs: float = 1000.0, dur_s: float = 60.0, noise_mm: float = 0.01):
    """P(s) at ``fs`` Hz under a PI-D with static feed-forward at 200 Hz (kp 0.5, ki 18, kd 0.002; command held,
    clamped to 0-9 kV, conditional integration), reading the stroke's last sample before each update; reference
    2-4-6-4-2 mm for 2 s each, then random levels 1.5-7 mm held 0.3-2 s; white noise ``noise_mm`` mm.
    Returns (t s, applied kV, measured mm)."""
    rng = np.random.default_rng(seed)
    Ad, Bd, Cd, _ = designs.plant_discrete(fs)
    g0 = designs.static_gain()
    parts = [np.full(int(2 * fs), v) for v in (2.0, 4.0, 6.0, 4.0, 2.0)]
    n = int(dur_s * fs)
    while sum(p.size for p in parts) < n:
        parts.append(np.full(int(rng.uniform(0.3, 2.0) * fs), rng.uniform(1.5, 7.0)))
    ref = np.concatenate(parts)[:n]
    per, tc = int(round(fs / 200.0)), 1.0 / 200.0
    x = np.zeros(Ad.shape[0])
    u, y = np.zeros(n), np.zeros(n)
    integ = e_prev = ym = v = 0.0
    for i in range(n):
        if i % per == 0:
            e = ref[i] - ym
            unclamped = ref[i] / g0 + 0.5 * e + 18.0 * (integ + e * tc) + 0.002 * (e - e_prev) / tc
            v = min(9.0, max(0.0, unclamped))
            if v == unclamped:
                integ += e * tc
            e_prev = e
        y[i] = float(Cd[0] @ x) + noise_mm * rng.standard_normal()
        u[i] = v
        x = Ad @ x + Bd[:, 0] * v
        if (i + 1) % per == 0:
            ym = y[i]
    return np.arange(n) / fs, u, y


def test_an_unpinned_order_yields_to_a_lower_one_the_data_support():
    """Closed-loop steps at 1 kHz (seed 0): 4/5 wins on held-out data but check 6 finds its response pinned only
    to +-2.3 dB / +-15 deg at 12.6 Hz (it was 5.2 deg off P(s), refused at exit 1 before this change); 2/3,
    searched below it, passes every check within 10 % of its held-out error and is 2.5 deg off."""
    t, u, y = _closed_loop_with_feed_forward(0)
    r = identify(t, u, y, input_name="voltage_kv", output_name="stroke_mm")
    assert r.usable, r.reasons
    assert (r.model.num.size - 1, r.model.den.size - 1) == (2, 3)
    assert "order 4/5 (chosen on held-out data) was refused: the data pin the response only to" in r.notes[0]
    c = r.paper_comparison()
    assert c["max_db"] < 0.5 and c["max_deg"] < 3.5, c


def test_a_fixed_order_is_not_replaced():
    """With the order fixed by the user the refusal stands: nothing is searched."""
    t, u, y = _closed_loop_with_feed_forward(0)
    r = identify(t, u, y, input_name="voltage_kv", output_name="stroke_mm", order=(4, 5))
    assert not r.usable
    assert any(x.startswith("the data pin the response only to") for x in r.reasons), r.reasons
    assert not any("searched below it" in n for n in r.notes)
