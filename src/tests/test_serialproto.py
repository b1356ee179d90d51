"""hasel.serialproto: framing, checksums, and the firmware model's clamp and watchdog."""
from __future__ import annotations

import math

import pytest
from hypothesis import given
from hypothesis import strategies as st

from hasel.serialproto import LineBuffer, McuModel, ProtocolError, decode, encode


@given(st.integers(0, 2**32 - 1), st.integers(0, 2**40), st.floats(-1e6, 1e6, allow_nan=False))
def test_round_trip(seq, t, x):
    f = decode(encode("T", seq, t, x))
    assert f.kind == "T" and f.seq == seq and f.fields[1] == t and f.fields[2] == pytest.approx(x, rel=1e-15)


def test_corruption_is_detected():
    good = encode("V", 7, 4.5)
    with pytest.raises(ProtocolError, match="checksum"):
        decode(good.replace(b"4.5", b"8.5"))
    with pytest.raises(ProtocolError):
        decode(b"V,1*00")
    lb = LineBuffer(max_line=64)
    frames = lb.feed(good + b"junk\n" + b"x" * 100 + encode("Z", 1))
    assert [f.kind for f in frames] == ["V"] and lb.bad >= 2


def test_firmware_clamps_and_times_out():
    m = McuModel(period_s=0.005)
    m.handle(decode(encode("V", 1, 12.0)), 0.0)
    assert m.tick(0.0) == 9.0
    m.handle(decode(encode("V", 2, -3.0)), 0.001)
    assert m.tick(0.001) == 0.0
    m.handle(decode(encode("V", 3, 5.0)), 0.002)
    assert m.tick(0.016) == 5.0
    assert m.tick(0.0171) == 0.0  # three periods without a host frame
    m.handle(decode(encode("V", 4, math.inf)), 0.02)
    assert m.tick(0.02) == 0.0
