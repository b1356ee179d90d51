"""The I/O benchmark helpers run and measure what they say (tiny sizes here)."""
from __future__ import annotations

import math

import pytest

from hasel_bench.iospeed import load_speed, writer_overhead


def test_writer_overhead_small():
    r = writer_overhead(n_messages=400, repeats=1)
    assert r["messages"] == 400
    assert r["ratio"] == pytest.approx(r["ours_us"] / r["bare_us"], rel=1e-12) and math.isfinite(r["ratio"])
    assert r["ratio"] > 0


def test_load_speed_small():
    r = load_speed(segments=2, segment_s=0.25, rate_hz=10_000, batch=50, repeats=1)
    assert r["samples"] == 5000
    assert r["samples_per_s"] == pytest.approx(r["samples"] / r["load_cpu_s"], rel=1e-12)
