"""hasel.timeconv: the one place where float seconds and integer nanoseconds meet."""
from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from hasel.errors import BadInputError
from hasel.timeconv import (NS_PER_S, ns_to_s, ns_to_s_array, ns_to_stamp, s_to_ns, s_to_stamp, stamp_to_ns,
                            stamp_to_s)


@given(st.integers(-(2**62), 2**62))
def test_stamps_round_trip_exactly_and_keep_nanosec_in_range(t_ns):
    sec, nanosec = ns_to_stamp(t_ns)
    assert 0 <= nanosec < NS_PER_S
    assert stamp_to_ns(sec, nanosec) == t_ns


def test_negative_times_follow_the_ros_convention():
    assert ns_to_stamp(-1_700_000_000) == (-2, 300_000_000)
    assert s_to_stamp(-1.7) == (-2, 300_000_000)
    assert s_to_stamp(1.7) == (1, 700_000_000)


@given(st.integers(0, 2**53))
def test_scalar_array_and_stamp_conversions_give_the_same_float(t_ns):
    arr = ns_to_s_array(np.array([t_ns], dtype=np.int64))
    assert ns_to_s(t_ns) == arr[0] == stamp_to_s(*ns_to_stamp(t_ns))
    assert abs(ns_to_s(t_ns) - t_ns / NS_PER_S) <= 2 * math.ulp(t_ns / NS_PER_S)


def test_seconds_round_to_the_nearest_nanosecond():
    assert s_to_ns(0.005) == 5_000_000
    assert s_to_ns(1e-4) == 100_000
    assert s_to_ns(2.0000000004) == 2_000_000_000
    assert s_to_ns(2.0000000006) == 2_000_000_001
    # a loop period built from ticks: integer arithmetic, no drift over a long run
    assert 1_000_000 * s_to_ns(0.005) == s_to_ns(5000.0)


@pytest.mark.parametrize("bad", [math.nan, math.inf, -math.inf])
def test_non_finite_seconds_are_bad_input(bad):
    with pytest.raises(BadInputError, match="finite"):
        s_to_ns(bad)
