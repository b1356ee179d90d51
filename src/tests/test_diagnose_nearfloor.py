"""A first effect is not named on a gap within ``first_over_floor_min`` times the noise floor's energy.

The log is an effect-free tuning log (``bench/tune_diag/free_indep.py`` seed 15, log 14: a 200 Hz multisine
through the exact P(s), the stroke quantised to 14 bits over 20 mm with white noise of a fraction of a step).
The quantisation error is a deterministic function of the stroke, so a load fitted to it passed the held-out
test (block score 4.5, coloured z 5.9) on a nominal gap 1.22 times the floor's energy and was named before
session 29. Now the round is refused by the ``near_floor`` gate, and the verdict names nothing.
"""
from __future__ import annotations

import os
import sys

import numpy as np

from hasel.diagnose import DiagnoseOptions, diagnose

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "..", "bench", "tune_diag"))


def test_a_quantised_effect_free_log_names_nothing_near_the_floor():
    import free_indep

    arrays, desc = free_indep.make_one(15, 14)
    assert desc["form"] == "quant"
    v = diagnose(arrays["t_s"], arrays["voltage_kv"], arrays["stroke_mm"],
                 model={"num": np.asarray(arrays["num"]).tolist(), "den": np.asarray(arrays["den"]).tolist()},
                 units=("kV", "mm"), options=DiagnoseOptions())
    assert v.names == []
    first = v.rounds[0]
    assert first["over_floor"] < DiagnoseOptions().first_over_floor_min
    # its gap is also below session 30's practical size (0.3 % of the stroke's spread), which refuses it too
    small = first["nominal_gap_nrmse"] < DiagnoseOptions().min_gap_nrmse
    assert [g["gate"] for g in first["failed"]] == ["near_floor"] + ["practical_size"] * small
