"""A fitted sub-sample delay is folded into the timing offset only while the total stays within one sample.

``_timing_fold`` turns a time_delay shorter than one original sample into a timing offset (a sampling convention or
a clock offset, not physics). The set-up has already taken part of the lag as timing; the fold must keep the
reported offset within its own bound (``bound_original_samples``), else a physical delay split in two halves, each
under a sample, would be reported as a timing offset of nearly two samples (a tuning log: 0.86 + 0.86 sample at
500 Hz). The stage is called here on its own with the few context fields it reads.
"""
from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest

from hasel import paper
from hasel.diagnose.core import _timing_fold
from hasel.diagnose.prep import prepare
from hasel.diagnose.setup_stages import timing_stage
from hasel.effects.base import EffectFit
from hasel_bench.othersim import FohSystem, excitation

RATE = 500.0  # Hz: one original sample is 2 ms


def _run(setup_samples: float, delay_s: float, bound_reached: str | None = None):
    said: list[str] = []
    ctx = SimpleNamespace(prep=SimpleNamespace(info={"original_rate_hz": RATE}, rate_hz=RATE), say=said.append)
    st = SimpleNamespace(current={"time_delay": EffectFit("time_delay", "input", (delay_s,))})
    timing = {"seconds": setup_samples / RATE, "original_samples": setup_samples, "bound_original_samples": 1.0}
    if bound_reached is not None:  # the set-up's search reached that end and kept the convention (0)
        timing["bound_reached"] = bound_reached
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


def test_a_delay_is_not_folded_when_the_set_up_reached_its_lag_bound():
    # the set-up saw more lag than a convention and left it to the delay (combos.py seed 21 #10: a 6.4 ms shift at
    # 200 Hz, fitted 0.8 sample): folding it back would report a lag the set-up refused as timing
    nuisance, timing, said = _run(0.0, 0.0016, bound_reached="lag")
    assert nuisance == set()
    assert timing["original_samples"] == 0.0 and "delay_fit_within_one_sample_s" not in timing
    assert len(said) == 1 and "reached its lag bound" in said[0] and said[0].endswith("named")
    # at the lead end the set-up saw the output ahead: a delay under a sample is still a timing offset
    assert _run(0.0, 0.0016, bound_reached="lead")[0] == {"time_delay"}


@pytest.mark.parametrize("lag_samples,reached", [(0, None), (2, "lag")])
def test_the_set_up_says_which_end_of_its_search_it_reached(lag_samples, reached):
    # a first-order-hold log is half a sample ahead of the zero-order hold: within the search, no bound; its output
    # two samples late (1.5 samples of lag) reaches the lag end, and the convention is kept (offset 0)
    rng = np.random.default_rng(4)
    u, _ = excitation(rng, RATE, short=True)
    num, den = paper.plant_tf()
    z = FohSystem(num, den, 1.0 / RATE).run(u)
    if lag_samples:
        z = np.concatenate([np.full(lag_samples, z[0]), z[:-lag_samples]])
    t = np.arange(u.size) / RATE
    prep = prepare(t, u, z + 0.004 * rng.standard_normal(u.size), model_den=den)
    out = timing_stage(prep, num, den, 0.0, lambda m: None)
    assert out.get("bound_reached") == reached
    assert out["original_samples"] == (0.0 if reached else pytest.approx(-0.5, abs=0.1))
