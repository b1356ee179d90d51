"""The blind withheld check, CI size: labels stay in this process, diagnoses run in spawned ones."""
from __future__ import annotations

import numpy as np
import pytest

from hasel_bench.blind import format_report, make_case, run_blind, score


def test_case_files_hold_no_label(tmp_path):
    case = make_case(0, 12345, str(tmp_path), quick=True)
    with np.load(case.path) as d:
        assert set(d.files) == {"t_s", "voltage_kv", "stroke_mm", "num", "den"}
        assert d["t_s"].size == d["voltage_kv"].size == d["stroke_mm"].size > 100_000
    assert case.path.startswith(str(tmp_path))


def test_scoring_reveals_labels_and_counts():
    cases = [type("C", (), {"index": i, "seed": i, "labels": lab, "params": {}, "noise_mm": 0.0, "path": f"p{i}"})()
             for i, lab in enumerate([(), ("time_delay",), ("hysteresis", "charge_drift"), (), ("saturation",)])]
    res = {"p0": [], "p1": ["time_delay"], "p2": ["charge_drift", "hysteresis", "load_mass"], "p3": ["load_mass"],
           "p4": []}
    results = {k: {"names": v, "nrmse_nominal": 0.2, "nrmse_augmented": 0.05, "floor": 0.0, "seconds": 1.0}
               for k, v in res.items()}
    s = score(cases, results)
    assert s["top1_accuracy"] == 2 / 4  # p0 right, p1 right, p3 false alarm, p4 miss
    assert s["pair_accuracy"] == 1.0 and s["false_alarms"] == 1 and s["misses"] == 1
    assert s["median_shrink"] == pytest.approx(0.75) and s["confusion"]["none"] == {"none": 1, "load_mass": 1}
    assert "false alarms: 1 of 2" in format_report(s)


def test_blind_check_small():
    s = run_blind(n_cases=9, seed=3, workers=2, quick=True)
    assert s["n_cases"] == 9
    assert s["false_alarms"] == 0 and s["misses"] == 0
    assert s["top1_accuracy"] >= 0.8
    assert s["median_shrink"] >= 0.7
