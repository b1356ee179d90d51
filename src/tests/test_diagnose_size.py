"""A first effect is not named where the nominal model's systematic error is below ``min_gap_nrmse``.

The log is an effect-free tuning log (``bench/tune_diag/free_indep.py`` seed 27, log 23: 5 kHz voltage steps of
whole kV through the exact P(s), the *recorded* voltage quantised to 10 bits over 10 kV while the plant saw the
command). Each level's recording is off by a fixed 0-4.9 V, a static map of the input the log really shows, so a
static map passed the held-out test (block score 4.0, coloured z 14.6) on a gap 3.2 times the floor's energy and
was named in session 29. That gap is 0.08 % of the stroke's spread: the size of a recorder's own calibration.
Now the round is refused by the ``practical_size`` gate, and the verdict names nothing; its text summary says
what was seen and why it is not named.
"""
from __future__ import annotations

import os
import sys

import numpy as np

from hasel.diagnose import DiagnoseOptions, diagnose
from hasel.diagnose.report import verdict_lines

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "..", "bench", "tune_diag"))


def test_a_recorded_voltage_quantised_to_10_bits_names_nothing():
    import free_indep

    arrays, desc = free_indep.make_one(27, 23)
    assert (desc["form"], desc["design"]) == ("vquant", "steps")
    v = diagnose(arrays["t_s"], arrays["voltage_kv"], arrays["stroke_mm"],
                 model={"num": np.asarray(arrays["num"]).tolist(), "den": np.asarray(arrays["den"]).tolist()},
                 units=("kV", "mm"), options=DiagnoseOptions())
    assert v.names == []
    first = v.rounds[0]
    assert first["over_floor"] > DiagnoseOptions().first_over_floor_min   # not the near-floor gate's case
    assert [g["gate"] for g in first["failed"]] == ["practical_size"]
    assert first["nominal_gap_nrmse"] < DiagnoseOptions().min_gap_nrmse
    assert "% of the output's spread" in first["failed"][0]["why"]
    # the text summary says what was seen and why it is not named, though the gap is within 2 x the floor
    assert any(ln.startswith("seen, too small to name: static_nonlinearity") for ln in verdict_lines(v))
