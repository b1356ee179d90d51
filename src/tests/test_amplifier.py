"""hasel.amplifier: the hard 9 kV ceiling, non-finite handling, watchdog, pre-conditioning."""
from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from hasel.amplifier import HARD_CEILING_KV, AmplifierCore, HeldOutput, HvLimits, Reason, TripMark, Watchdog
from hasel.errors import BadInputError, UnsafeParameterError
from hasel.faults import ERROR, WARN


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


@settings(max_examples=300, deadline=None)
@given(st.lists(st.floats(allow_nan=True, allow_infinity=True), max_size=60), st.floats(0.0, 4.0),
       st.floats(4.5, 9.0))
def test_a_waveform_is_limited_sample_by_sample_by_the_same_rule(req, lo, hi):
    lim = HvLimits(lo, hi)
    applied, reasons = lim.apply_many(req)
    assert applied.tolist() == [lim.apply(x).applied_kv for x in req]
    assert reasons.tolist() == [lim.apply(x).reason for x in req]


def test_amplifier_core_reasons_and_diagnostics():
    amp = AmplifierCore()
    (ok, note), = amp.command(0.0, 4.0)
    assert ok.applied_kv == 4.0 and note is None
    (high, note), = amp.command(0.005, 12.0)
    assert high.applied_kv == 9.0 and high.reason == Reason.CLAMP_HIGH and note.level == WARN
    assert amp.command(0.010, 13.0)[0][1] is None  # reported when the reason changes, not every tick
    (bad, note), = amp.command(0.015, math.nan)
    assert bad.applied_kv == 0.0 and bad.reason == Reason.NONFINITE and note.level == ERROR
    (pre, note), = [amp.precondition(0.02, -7.0)]
    assert pre.applied_kv == -2.0 and pre.reason == Reason.PRECONDITION and note is None
    down, note = amp.shutdown(0.025)
    assert down.applied_kv == 0.0 and down.reason == Reason.SHUTDOWN and amp.output_kv == 0.0


def test_amplifier_watchdog_zero_kv_once_commands_stop_and_the_first_command_of_the_instant():
    amp = AmplifierCore(watchdog=Watchdog(0.005, 3))
    assert amp.poll(0.0) is None  # never fed: nothing to guard yet
    amp.command(1.000, 5.0)
    assert amp.poll(1.015) is None  # three periods: still fresh
    out, note = amp.poll(1.020)
    assert out.applied_kv == 0.0 and out.reason == Reason.WATCHDOG and note.level == ERROR and amp.tripped
    assert note.values["command_age_s"] == pytest.approx(0.020)  # how late, from the last arrival
    assert amp.poll(1.020) is None  # once per instant
    assert amp.poll(1.025)[0].reason == Reason.WATCHDOG  # then every period
    # a request at an instant whose 0 kV was not sent yet: the watchdog's output comes first
    results = amp.command(1.030, 5.0)
    assert [r[0].reason for r in results] == [Reason.WATCHDOG, Reason.NONE] and not amp.tripped


def test_batches_are_limited_with_one_warning():
    amp = AmplifierCore(HvLimits(0.0, 8.0))
    applied, note = amp.batch(0.0, [1.0, 9.5, math.nan, -1.0, 7.9])
    assert applied.tolist() == [1.0, 8.0, 0.0, 0.0, 7.9]
    assert note.level == WARN and note.values["samples"] == 3 and note.values["max_requested_kv"] == 9.5
    assert amp.output_kv == 7.9 and amp.batch(0.005, [2.0])[1] is None


def test_held_output_holds_three_periods_then_zero():
    dac = HeldOutput(3)
    assert dac.fresh(6.0) == 6.0
    assert [dac.missing() for _ in range(5)] == [6.0, 6.0, 6.0, 0.0, 0.0]
    assert dac.fresh(math.inf) == 0.0
    assert dac.fresh(np.array([1.0, math.nan])).tolist() == [1.0, 0.0]


def test_a_request_measured_before_a_trip_gives_zero_kv_and_does_not_feed_the_watchdog():
    amp, mark = AmplifierCore(watchdog=Watchdog(0.005, 3)), TripMark(window_s=1.0)
    amp.command(1.000, 5.0)
    mark.fed(1.000, 100.998)  # its stamp is on a clock 100 s ahead, and it arrived 2 ms after its measurement
    assert amp.poll(1.020)[0].reason == Reason.WATCHDOG
    mark.trip(1.020, mono_ns=10_000)
    mark.trip(1.025, mono_ns=11_000)  # a repeat of the 0 kV keeps the first mark
    assert mark.trip_stamp_s == pytest.approx(101.018)  # the trip on the stamps' clock
    # measured before the trip, handled 1 ms later: queued; measured after it: fresh
    assert mark.queued(101.017, 10_000 + 1_000_000) and not mark.queued(101.019, 10_000 + 1_000_000)
    assert not mark.queued(0.0, 10_001)  # an unset stamp: counted fresh
    assert not mark.queued(101.017, 10_000 + 1_000_000_001)  # beyond the window (clocks of other rates)
    (out, note), = [amp.queued_request(1.021, 6.0)]
    assert out.applied_kv == 0.0 and out.reason == Reason.WATCHDOG and out.requested_kv == 6.0
    assert note.level == WARN and "measured before the watchdog tripped" in note.message
    assert amp.tripped and amp.output_kv == 0.0 and amp.watchdog.last_s == 1.000  # not fed
    assert amp.queued_request(1.022, math.nan)[1] is None  # one notice per trip
    assert amp.poll(1.025)[0].reason == Reason.WATCHDOG  # still stale
    (out, _), = amp.command(1.025, 6.0)  # a request measured after the trip resumes
    assert out.applied_kv == 6.0 and not amp.tripped
    mark.fed(1.025, 101.023)
    assert not mark.queued(101.017, 10_001)
    assert amp.poll(1.045)[0].reason == Reason.WATCHDOG
    assert amp.queued_request(1.046, 7.0)[1] is not None  # a new trip: a new notice
    assert not TripMark().queued(1.0, 0)  # never fed, never tripped


def test_one_late_request_before_a_trip_does_not_let_older_queued_requests_through():
    """The CI failure of session 38's landing: the last request before the trip came 39 ms after its
    measurement (a loaded machine); requests measured 23-39 ms before the trip, handled after it, were
    applied (2.7 kV) because the mark took the last latency. The smallest recent latency puts the mark
    at the trip minus the transport floor."""
    mark = TripMark(window_s=1.0)
    for k in range(50):  # 200 Hz, 1-3 ms through the chain; stamps on a clock 100 s behind
        mark.fed(900.0 + 0.005 * k, 800.0 + 0.005 * k - 0.001 - 0.002 * (k % 2))
    mark.fed(900.270, 800.270 - 0.039)  # the late one
    mark.trip(900.2889, mono_ns=5_000)
    assert mark.trip_stamp_s == pytest.approx(800.2879)
    # measured 25-41 ms after the late one's stamp, all before the trip: queued (the last-latency mark was 800.2499)
    assert all(mark.queued(800.231 + d, 5_000 + 400_000) for d in (0.019, 0.027, 0.035))
    assert not mark.queued(800.2889, 5_000 + 400_000)  # measured at the trip itself: fresh
    with pytest.raises(BadInputError):
        TripMark(history=0)
