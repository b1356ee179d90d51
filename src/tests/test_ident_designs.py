"""Identification of effect-free logs of several experiment designs (src/tests/designs.py), and honest failure.

Each log is P(s) of the paper behind a zero-order hold with 0.01 mm white noise; the
identified model must be within 1 dB and 5 deg of P(s) over 0.1-15 Hz, with G(0) on
the static map. The heavier sweep over every design, rate and seed is
``bench/tune_ident/run.py``.
"""
from __future__ import annotations

import csv
import json
import subprocess
import sys

import numpy as np
import pytest

import designs
from hasel.ident import identify
from hasel.ident.checks import check_model, check_model_json
from hasel.ident.tffit import TFModel

OFFSETS = (2.0, 4.0, 6.0)


@pytest.mark.parametrize("design, rate", [("paper_chirp", 200.0), ("prbs", 200.0)])
def test_design_recovers_p_within_1_db_and_5_deg(design, rate):
    log = designs.make_log(design, rate, seed=0)
    r = identify(log.t_s, log.u_kv, log.y_mm, input_name="voltage_kv", output_name="stroke_mm")
    c = r.paper_comparison()
    assert c["max_db"] < 1.0 and c["max_deg"] < 5.0, c
    assert r.model.dc_gain == pytest.approx(designs.static_gain(), rel=0.02)
    assert r.usable, r.reasons
    assert np.all(np.real(r.model.poles) < 0)


def test_the_reported_paper_chirp_failure_is_gone():
    """One 20 s paper chirp per offset 2..7 kV after 0.5 s, 1 kHz: was G(0) = -262 with an RHP zero, fit -980 %."""
    log = designs.make_log("paper_chirp", 1000.0, seed=0)
    r = identify(log.t_s, log.u_kv, log.y_mm, input_name="voltage_kv", output_name="stroke_mm")
    assert r.model.dc_gain == pytest.approx(float(r.static_map.slope(4.5)), rel=0.03)
    assert r.validation is not None and r.validation.compare_fit_pct > 90.0
    # no right-half-plane zero beyond the notch pair of P(s) itself (on the imaginary axis at 19.45 Hz)
    assert not np.any(np.real(r.model.zeros) > 0.05 * np.abs(r.model.zeros))
    assert r.usable


def test_checks_flag_a_model_that_contradicts_the_data():
    """The core check used by identify (and offered to diagnose) names each failure with a fix."""
    bad = TFModel(np.array([1.0, -5.0]), np.array([1.0, 0.01, 1.6]))   # RHP zero, near-marginal 0.2 Hz pair (damping 0.004)
    chk = check_model(bad, band_hz=(1.0, 20.0), static_slope=1.35, static_ci=0.01, heldout_nrmse=1.5)
    assert not chk.usable
    text = " ".join(chk.reasons)
    assert "near-marginal" in text and "static gain" in text and "compare fit" in text
    assert len(chk.fixes) == len(chk.reasons) and "model not usable" in chk.one_line()
    ok = check_model(TFModel(np.array([1.35 * 10.0]), np.array([1.0, 10.0])), band_hz=(0.1, 20.0),
                     static_slope=1.35, static_ci=0.01, heldout_nrmse=0.05)
    assert ok.usable and ok.reasons == []
    assert not check_model_json({"num": [1.0], "den": [1.0, 1.0], "usable": False, "reasons": ["x"]}).usable


def test_cli_exits_1_with_usable_false_on_a_log_that_cannot_be_identified(tmp_path):
    """A 2-3 Hz multisine at one offset: nothing pins the low frequencies; exit 1, one line, JSON usable=false."""
    rate = 200.0
    t = np.arange(0, 30.0, 1 / rate)
    rng = np.random.default_rng(4)
    f = np.arange(2.0, 3.01, 0.1)
    u = 4.0 + 0.05 * sum(np.sin(2 * np.pi * fk * t + rng.uniform(0, 6.28)) for fk in f)
    ylog = designs._simulate(u, rate) + 0.01 * rng.standard_normal(u.size)
    path = tmp_path / "narrow.csv"
    with open(path, "w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(["t_s", "voltage_kv", "stroke_mm"])
        w.writerows(zip(t, u, ylog))
    out = tmp_path / "m.json"
    p = subprocess.run([sys.executable, "-m", "hasel.cli", "identify", str(path), "--json", str(out)],
                       capture_output=True, text=True)
    assert p.returncode == 1, p.stderr
    last = p.stderr.strip().splitlines()[-1]
    assert "model not usable" in last and "to fix" in last and "Traceback" not in p.stderr
    m = json.loads(out.read_text())
    assert m["usable"] is False and m["reasons"]


def test_a_log_too_short_for_the_band_asked_is_one_clear_error():
    from hasel.errors import BadInputError

    log = designs.make_log("multisine", 200.0, seed=2, offsets_kv=(3.0,))
    with pytest.raises(BadInputError, match="too short for the band asked"):
        identify(log.t_s, log.u_kv, log.y_mm, band_hz=(0.01, 10.0))
