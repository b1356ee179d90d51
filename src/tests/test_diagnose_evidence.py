"""Diagnosis selection with frequency-domain evidence: a changed resonance is not read as timing or delay.

Logs come from the independent simulator's first-order-hold discretisation (hasel_bench.othersim.FohSystem) of
P(s) with its double resonance pair made heavier (frequency and damping ratio lowered together, static gain
kept), the way a load changes it."""
from __future__ import annotations

import numpy as np
import pytest

from hasel import paper
from hasel.diagnose import DiagnoseOptions, diagnose
from hasel.diagnose.setup_stages import timing_stage
from hasel.diagnose.prep import prepare
from hasel.effects.load import loaded_den
from hasel_bench.othersim import FohSystem, excitation

RATE = 500.0


def _log(drop: float, seed: int = 3, noise_mm: float = 0.004):
    """A 500 Hz log of P(s) with its resonances' frequency lowered by ``drop`` (0: the nominal plant)."""
    rng = np.random.default_rng(seed)
    u, _ = excitation(rng, RATE, short=True)
    num, den = paper.plant_tf()
    mu = 1.0 / (1.0 - drop) ** 2 - 1.0
    den2 = loaded_den(den, mu)
    z = FohSystem(num, den2, 1.0 / RATE).run(u)
    return np.arange(u.size) / RATE, u, z + noise_mm * rng.standard_normal(u.size), mu


@pytest.mark.parametrize("drop", [0.0, 0.2])
def test_timing_is_the_sampling_convention_whether_or_not_the_resonance_moved(drop):
    t, u, y, mu = _log(drop)
    num, den = paper.plant_tf()
    prep = prepare(t, u, y, model_den=den)
    out = timing_stage(prep, num, den, 0.0, lambda m: None)
    # linear interpolation of the input (first-order hold) is half a sample ahead of the zero-order hold
    assert out["original_samples"] == pytest.approx(-0.5, abs=0.1)
    fitted = out["fitted_beside"]["load_mass_ratio"]
    if drop == 0.0:
        assert fitted == 0.0  # the nuisance load does not pay for itself on the nominal plant
    else:
        assert fitted == pytest.approx(mu, rel=0.15)


def test_a_lower_double_resonance_is_named_load_mass_and_the_gap_closes():
    t, u, y, mu = _log(0.22, seed=5)
    num, den = paper.plant_tf()
    v = diagnose(t, u, y, model={"num": num.tolist(), "den": den.tolist()}, units=("kV", "mm"),
                 options=DiagnoseOptions(max_effects=2))
    assert v.names == ["load_mass"]
    assert v.effects[0]["params"]["mass_ratio"] == pytest.approx(mu, rel=0.2)
    assert v.heldout["gap_shrink"] > 0.8
