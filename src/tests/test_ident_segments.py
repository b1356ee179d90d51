"""Finding operating points in a log (hasel.ident.segments)."""
from __future__ import annotations

import numpy as np
import pytest

from hasel.errors import BadInputError
from hasel.ident.segments import DEFAULT_SETTLE_FRACTION, find_segments, segments_from_markers
from hasel.signals import protocol_schedule


@pytest.fixture(scope="module")
def campaign():
    # the paper's campaign at a low rate, with 2 s holds at -1 kV between the tests
    return protocol_schedule(rate_hz=200.0, precondition_s=2.0)


def test_finds_the_six_operating_points_and_skips_the_holds(campaign):
    found = find_segments(campaign.t_s, campaign.command_kv)
    marks = campaign.markers()
    assert len(found.segments) == len(marks) == 6
    for seg, (t0, t1, off) in zip(found.segments, marks):
        assert seg.offset == pytest.approx(off, abs=0.05)
        assert seg.source == "detected"
        # starts after the settling part, ends within a few blocks of the true end
        assert seg.start_s == pytest.approx(t0 + DEFAULT_SETTLE_FRACTION * (t1 - t0), abs=0.5)
        assert t1 - 0.5 < seg.end_s <= t1
    assert len(found.skipped) == 6
    assert all("no excitation" in s.reason and s.level == pytest.approx(-1.0) for s in found.skipped)


def test_two_close_steps_around_a_short_hold_are_both_found():
    # tests back to back with a hold of exactly one detection window between them
    sch = protocol_schedule(offsets_kv=[6.0, 7.0], duration_s=10.0, rate_hz=200.0, precondition_s=2.0)
    x = np.concatenate([sch.command_kv, sch.command_kv])
    t = np.arange(x.size) / 200.0
    found = find_segments(t, x, window_s=2.0)
    assert [round(s.offset) for s in found.segments] == [6, 7, 6, 7]


def test_markers_override_detection():
    t = np.arange(0, 10, 0.01)
    segs = segments_from_markers(t, [(1.0, 4.0, 2.0), (5.0, 9.0, 3.0)], settle_s=0.5)
    assert [(s.i0, s.i1, s.offset, s.source) for s in segs] == [(150, 400, 2.0, "marker"), (550, 900, 3.0, "marker")]
    with pytest.raises(BadInputError, match="fewer than two samples"):
        segments_from_markers(t, [(20.0, 30.0, 1.0)])
    with pytest.raises(BadInputError, match="t_end_s > t_start_s"):
        segments_from_markers(t, [(3.0, 2.0, 1.0)])
    with pytest.raises(BadInputError, match="must be \\(t_start_s, t_end_s, offset\\)"):
        segments_from_markers(t, [(1.0, 2.0)])


def test_a_constant_log_has_no_operating_point():
    t = np.arange(0, 100, 0.01)
    found = find_segments(t, np.full(t.size, 2.0))
    assert found.segments == [] and len(found.skipped) == 1
