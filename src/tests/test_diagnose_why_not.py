"""A verdict says which explanation came closest to a gap it leaves, and which acceptance gate refused it.

``failed_gates`` turns a round's recorded figures into the gates it failed (words and numbers);
``closest_unnamed`` reads the last refused forward round out of a verdict's ``rounds``; the text summary
(``verdict_lines``) prints it when the held-out error left is more than ``LEFT_OVER_FLOOR`` times the floor.
The end-to-end case is a tuning log (``bench/tune_diag/modes.py`` seed 1, case 13: an input power map and an
added mode at 1.7 x the resonance, 200 Hz chirps with sensor wander): the map is named, and 2.2 x the floor is left;
the load that removes 27 % of that is refused as too small a share of the nominal gap, and the summary says so.
"""
from __future__ import annotations

import os
import sys
from types import SimpleNamespace

import numpy as np

from hasel.diagnose import DiagnoseOptions, diagnose
from hasel.diagnose.core import failed_gates
from hasel.diagnose.report import LEFT_OVER_FLOOR, _share, closest_unnamed, verdict_lines

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "..", "bench", "tune_diag"))

OPTS = DiagnoseOptions()
PASS = dict(gain=0.5, need=0.12, gap_share=0.6, gap_need=0.2, big_enough=True, nominal_share=0.5, over_floor=40.0,
            first=False, t_blk=5.0, z_col=8.0, slow_only=False, t_fast=3.0, dbic=-100.0)


def _gates(**kw) -> list[str]:
    return [g["gate"] for g in failed_gates(OPTS, **(PASS | kw))]


def test_each_gate_is_reported_with_its_figures():
    assert _gates() == []
    assert _gates(gain=0.05) == ["gain"]
    assert _gates(gap_share=0.1) == ["gap_share"]
    assert _gates(big_enough=False, nominal_share=0.0008, over_floor=5.0) == ["nominal_share"]
    assert _gates(t_blk=2.8, z_col=2.0) == ["held_out"]
    assert _gates(t_blk=2.8, z_col=14.4) == []           # either held-out figure passes
    assert _gates(t_blk=7.0, z_col=-0.5, slow_only=True, t_fast=-0.2) == ["slow_only"]
    assert _gates(dbic=10.0) == ["bic"]
    assert _gates(first=True, over_floor=1.22) == ["near_floor"]   # a first effect this close to the floor
    assert _gates(first=False, over_floor=1.22) == []              # a later one is judged on its share
    assert _gates(first=True, over_floor=2.0) == []
    assert _gates(first=True, gap_nrmse=0.0008) == ["practical_size"]   # a first effect of a recorder's size
    assert _gates(first=False, gap_nrmse=0.0008) == []                  # a later one: the gap is the nominal's
    assert _gates(first=True, gap_nrmse=0.003) == []
    why = failed_gates(OPTS, **(PASS | dict(first=True, gap_nrmse=0.00084)))[0]["why"]
    assert "0.084 % of the output's spread" in why and "needs 0.3 %" in why
    why = failed_gates(OPTS, **(PASS | dict(big_enough=False, nominal_share=0.0008, over_floor=4.96)))[0]["why"]
    assert "0.08 % of the nominal model's gap (needs 3 %" in why and "here 4.96 x" in why
    why = failed_gates(OPTS, **(PASS | dict(t_blk=2.76, z_col=1.3)))[0]["why"]
    assert "block score 2.8, needs 3.9" in why and "z 1.3, needs 3.5" in why


def _round(n, best, accepted, failed=None, gain=0.3):
    r = {"round": n, "candidates": [{"name": best}], "best": best, "gain": gain, "accepted": accepted}
    return r | ({"failed": [{"gate": "held_out", "why": w} for w in failed]} if failed else {})


def test_closest_unnamed_is_the_newcomer_of_the_last_refused_round():
    rounds = [_round(1, "static_nonlinearity", True, gain=0.99),
              _round(2, "static_nonlinearity + load_mass", False, ["not confirmed"], gain=0.27),
              {"round": 3, "backward_check": True, "best": "static_nonlinearity", "accepted": True}]
    c = closest_unnamed(rounds)
    assert c == {"name": "load_mass", "round": 2, "gain": 0.27, "why": ["not confirmed"], "gates": ["held_out"]}
    assert closest_unnamed(rounds[:1]) is None           # no refused round: stopped at the floor or max_effects
    assert closest_unnamed([_round(1, "hysteresis", False, ["x"])])["name"] == "hysteresis"


def _verdict(nominal, augmented, floor, effects, rounds):
    return SimpleNamespace(heldout={"nrmse_nominal": nominal, "nrmse_augmented": augmented,
                                    "gap_shrink": 1.0 - (augmented / nominal) ** 2},
                           noise_floor_nrmse=floor, model={}, timing_offset={}, effects=effects, notes=[],
                           dropped=[], ambiguous=[], test={}, rounds=rounds)


def test_the_summary_names_the_closest_unnamed_only_when_a_gap_is_left():
    rounds = [_round(1, "static_nonlinearity", True, gain=0.99),
              _round(2, "static_nonlinearity + load_mass", False, ["the held-out test does not confirm it"])]
    eff = [{"name": "static_nonlinearity", "nrmse_after": 0.0185, "evidence": "a map"}]
    lines = verdict_lines(_verdict(0.38, 0.0185, 0.0083, eff, rounds))
    left = [ln for ln in lines if ln.startswith("left unexplained")]
    assert left == ["left unexplained: 2.23 x the noise floor; closest unnamed: load_mass (round 2, removes 30 % of "
                    "the validation error), not named: the held-out test does not confirm it"]
    low = _verdict(0.38, 0.0185, 0.0083, eff, rounds)
    low.noise = {"trust": "low: the noise is coloured", "trust_notes": ["the noise is coloured"]}
    assert any(ln.startswith("left unexplained: 2.23 x the noise floor (a lower bound of the noise here, the noise is "
                             "coloured); closest unnamed: load_mass") for ln in verdict_lines(low))
    near = 0.9 * LEFT_OVER_FLOOR * 0.0083
    assert not any(ln.startswith("left unexplained") for ln in verdict_lines(_verdict(0.38, near, 0.0083, eff, rounds)))


def test_a_first_effect_refused_for_its_size_alone_is_reported_however_close_to_the_floor():
    def refused(*gates):
        return [{"round": 1, "candidates": [{"name": "static_nonlinearity"}], "best": "static_nonlinearity",
                 "gain": 0.67, "accepted": False, "failed": [{"gate": g, "why": f"{g} why"} for g in gates]}]
    seen = [ln for ln in verdict_lines(_verdict(0.0011, 0.0011, 0.0006, [], refused("practical_size")))
            if ln.startswith("seen, too small")]
    assert seen == ["seen, too small to name: static_nonlinearity (removes 67 % of the validation error): "
                    "practical_size why"]
    both = verdict_lines(_verdict(0.0011, 0.0011, 0.0008, [], refused("near_floor", "practical_size")))
    assert any(ln.endswith("near_floor why; practical_size why") for ln in both)
    # refused by a held-out test too: not "seen", and 1.4 x the floor is too close to say what came closest
    other = verdict_lines(_verdict(0.0011, 0.0011, 0.0008, [], refused("practical_size", "held_out")))
    assert not any(ln.startswith(("seen, too small", "left unexplained")) for ln in other)


def test_a_refused_small_load_beside_a_map_is_reported_with_its_gate(tmp_path):
    import modes

    case = modes.make_case(str(tmp_path), 1, 13)
    assert case is not None and case["labels"] == ["load_mass", "static_nonlinearity"]
    d = np.load(case["path"])
    v = diagnose(d["t_s"], d["voltage_kv"], d["stroke_mm"], model={"num": d["num"].tolist(), "den": d["den"].tolist()},
                 units=("kV", "mm"))
    assert v.names == ["static_nonlinearity"]
    left = v.heldout["nrmse_augmented"] / v.noise_floor_nrmse
    assert 2.0 < left < 3.0                              # a little is left above the floor
    c = closest_unnamed(v.rounds)
    assert c is not None and c["name"] == "load_mass" and c["round"] == 2 and 0.2 < c["gain"] < 0.35
    line = next(ln for ln in verdict_lines(v) if ln.startswith("left unexplained"))
    assert f"{left:.3g} x the noise floor" in line and "of the nominal model's gap (needs 3 %" in line


def test_a_share_that_leaves_something_never_reads_100_percent():
    assert _share(0.9975) == "99.7 %" and _share(0.99999) == "99.9 %" and _share(1.0) == "100 %"
    assert _share(0.994) == "99 %" and _share(0.3) == "30 %" and _share(0.001) == "less than 0.5 %"
