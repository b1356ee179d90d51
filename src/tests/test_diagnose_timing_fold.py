"""A fitted sub-sample delay is folded into the timing offset only while the total stays within one sample.

``_timing_fold`` turns a time_delay shorter than one original sample into a timing offset (a sampling convention or
a clock offset, not physics). The set-up has already taken part of the lag as timing; the fold must keep the
reported offset within its own bound (``bound_original_samples``), else a physical delay split in two halves, each
under a sample, would be reported as a timing offset of nearly two samples (a tuning log: 0.86 + 0.86 sample at
500 Hz). The stage is called here on its own with the few context fields it reads.
"""
from __future__ import annotations

from types import SimpleNamespace

import pytest

from hasel.diagnose.core import _timing_fold
from hasel.effects.base import EffectFit

RATE = 500.0  # Hz: one original sample is 2 ms


def _run(setup_samples: float, delay_s: float):
    said: list[str] = []
    ctx = SimpleNamespace(prep=SimpleNamespace(info={"original_rate_hz": RATE}, rate_hz=RATE), say=said.append)
    st = SimpleNamespace(current={"time_delay": EffectFit("time_delay", "input", (delay_s,))})
    timing = {"seconds": setup_samples / RATE, "original_samples": setup_samples, "bound_original_samples": 1.0}
    return _timing_fold(ctx, st, timing), timing, said


def test_a_delay_within_the_timing_bound_is_folded():
    nuisance, timing, said = _run(0.10, 0.0017)   # 0.10 + 0.85 sample: within one sample
    assert nuisance == {"time_delay"}
    assert timing["original_samples"] == pytest.approx(0.95)
    assert timing["seconds"] == pytest.approx(0.0019)
    assert timing["delay_fit_within_one_sample_s"] == pytest.approx(0.0017)
    assert "timing offset, not named" in said[0]


@pytest.mark.parametrize("setup", [0.86, 0.20])
def test_a_delay_that_carries_the_total_beyond_one_sample_is_named(setup):
    delay = 0.00173 if setup > 0.5 else 0.0019    # 0.86 + 0.865 and 0.20 + 0.95 sample: beyond one
    nuisance, timing, said = _run(setup, delay)
    assert nuisance == set()
    assert timing["original_samples"] == setup and "delay_fit_within_one_sample_s" not in timing
    assert len(said) == 1 and "beyond a timing offset's bound (1): named" in said[0]
    assert f"reaches {setup + delay * RATE:.2f} samples" in said[0]


def test_an_output_lead_at_set_up_leaves_room_for_the_delay():
    # the set-up found the output ahead of the zero-order hold (-0.6 sample): 0.9 sample of delay gives +0.3
    nuisance, timing, _ = _run(-0.6, 0.0018)
    assert nuisance == {"time_delay"}
    assert timing["original_samples"] == pytest.approx(0.3)
