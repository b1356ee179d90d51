"""A fitted parameter pinned at a limit of its family's form is flagged in the verdict.

The log is P(s) with its double resonance pair made *lighter* than ``load_mass``'s form allows (mass
ratio -0.9, the resonances 3.2 times higher; the family's range stops at -0.8), from the independent
simulator's first-order-hold discretisation at 500 Hz. A load fitted first is reported (a first effect
that raises the resonances is a change of the dynamics to show), its mass ratio pinned at -0.8: the
verdict must say the form may not fit, in the effect's ``at_bound``, in ``notes`` and in the text."""
from __future__ import annotations

import numpy as np
import pytest

from hasel import paper
from hasel.diagnose import diagnose
from hasel.diagnose.report import verdict_lines
from hasel.effects.base import EffectFit
from hasel.effects.load import loaded_den
from hasel.effects.registry import family
from hasel_bench.othersim import FohSystem, excitation

RATE = 500.0


def test_the_families_say_which_parameters_sit_at_a_limit_of_their_form():
    load = family("load_mass")
    assert load.at_bound(None, EffectFit("load_mass", "model", (-0.8, 1.0))) == ["mass_ratio"]
    assert load.at_bound(None, EffectFit("load_mass", "model", (-0.7995, 20.0))) == ["mass_ratio", "gain_factor"]
    assert load.at_bound(None, EffectFit("load_mass", "model", (0.3, 1.0))) == []
    assert load.at_bound(None, EffectFit("load_mass", "model", (-0.78, 1.0))) == []  # 0.02 of a 10.8 range: inside
    # a zero sag is at its bound (one-sided range: only an exact pin)
    assert load.at_bound(None, EffectFit("load_mass", "model:sag", (0.3, 1.0, 0.0))) == ["offset"]
    assert load.at_bound(None, EffectFit("load_mass", "model:sag", (0.3, 1.0, -0.01))) == []
    # a hysteresis weight of zero is an unused play, not a limit of the form
    hyst = family("hysteresis")
    assert hyst.at_bound(None, EffectFit("hysteresis", "input", (0.0, 0.2, 0.0, 0.1, 0.0, 1.0))) == []


@pytest.fixture(scope="module")
def lighter_than_the_form():
    rng = np.random.default_rng(4)
    u, _ = excitation(rng, RATE, short=True)
    num, den = paper.plant_tf()
    z = FohSystem(num, loaded_den(den, -0.9), 1.0 / RATE).run(u)
    y = z + 0.004 * rng.standard_normal(u.size)
    return diagnose(np.arange(u.size) / RATE, u, y, model={"num": num.tolist(), "den": den.tolist()},
                    units=("kV", "mm"))


def test_a_mass_ratio_pinned_at_its_bound_is_flagged(lighter_than_the_form):
    v = lighter_than_the_form
    assert v.names and v.names[0] == "load_mass"
    load = v.effects[0]
    assert load["params"]["mass_ratio"] == pytest.approx(-0.8, abs=0.011)
    assert "mass_ratio" in load["at_bound"]
    js = v.to_json()
    note = next(n for n in js["notes"] if n["name"] == "load_mass")
    assert "mass_ratio" in note["at_bound"] and note["values"]["mass_ratio"] == pytest.approx(-0.8, abs=0.011)
    assert "may not fit" in note["note"] and "another known mass" in note["note"]
    text = "\n".join(verdict_lines(v))
    assert "form may not fit: load_mass: mass_ratio at the bound" in text
    # one note per effect with a pinned parameter, none for the others
    assert [n["name"] for n in js["notes"]] == [e["name"] for e in v.effects if e["at_bound"]]
