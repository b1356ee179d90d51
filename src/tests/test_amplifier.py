"""hasel.amplifier: the hard 9 kV ceiling, non-finite handling, watchdog, pre-conditioning."""
from __future__ import annotations

import math

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from hasel.amplifier import HARD_CEILING_KV, HvLimits, Reason, Watchdog
from hasel.errors import UnsafeParameterError


@settings(max_examples=2000, deadline=None)
@given(st.one_of(st.floats(allow_nan=True, allow_infinity=True), st.integers(-10**30, 10**30)),
       st.floats(0.0, 8.9), st.floats(0.1, 9.0))
def test_applied_is_always_within_limits(req, lo, hi):
    if hi <= lo:
        return
    lim = HvLimits(lo, hi)
    out = lim.apply(req)
    assert lo <= out.applied_kv <= hi or out.applied_kv == 0.0
    assert out.applied_kv <= HARD_CEILING_KV
    if not math.isfinite(float(req)):
        assert out.applied_kv == 0.0 and out.reason == Reason.NONFINITE


def test_reasons():
    lim = HvLimits()
    assert lim.apply(4.0).reason == Reason.NONE and not lim.apply(4.0).clamped
    assert lim.apply(12.0).applied_kv == 9.0 and lim.apply(12.0).reason == Reason.CLAMP_HIGH
    assert lim.apply(-3.0).applied_kv == 0.0 and lim.apply(-3.0).reason == Reason.CLAMP_LOW
    assert lim.apply("junk").applied_kv == 0.0


def test_ceiling_cannot_be_raised_and_negative_floor_rejected():
    with pytest.raises(UnsafeParameterError, match="hard 9.0 kV ceiling"):
        HvLimits(v_max_kv=9.5)
    with pytest.raises(UnsafeParameterError, match="pre-conditioning"):
        HvLimits(v_min_kv=-1.0)


def test_precondition_is_bounded():
    assert HvLimits.precondition(-1.0).applied_kv == -1.0
    assert HvLimits.precondition(-50.0).applied_kv == -2.0
    assert HvLimits.precondition(5.0).applied_kv == 0.0
    assert HvLimits.precondition(math.nan).applied_kv == 0.0


def test_watchdog_three_periods():
    wd = Watchdog(0.005, 3)
    assert wd.expired(0.0)  # nothing received yet
    wd.feed(1.0)
    assert not wd.expired(1.015)
    assert wd.expired(1.0151)
    assert wd.expired(0.9)  # clock jumped backwards: stale
