"""Readers of the real datasets, and the diagnosis naming their documented effects.

The data are public measurements of other real systems (``shared/datasets/README.md``);
the tests are skipped where that directory is not present.
"""
from __future__ import annotations

import numpy as np
import pytest

import realdata as D
from hasel.diagnose import DiagnoseOptions, diagnose
from hasel.errors import DataFileError

HAVE = (D.datasets_dir() / "README.md").is_file()
needs_data = pytest.mark.skipif(not HAVE, reason=D.MISSING)


def test_missing_directory_is_a_data_file_error(tmp_path):
    with pytest.raises(DataFileError, match="dataset file not found"):
        D.load_piezo(tmp_path)


@needs_data
def test_readers_give_the_documented_shapes_rates_and_units():
    p = D.load_piezo()
    assert p.t_s.size == 50_001 and p.rate_hz == pytest.approx(5000.0, rel=1e-3)
    assert (p.input_unit, p.output_unit) == ("V", "um")
    assert np.ptp(p.u) == pytest.approx(300.0, rel=0.01) and np.ptp(p.y) == pytest.approx(39.4, rel=0.02)
    est, val = D.load_cascaded_tanks()
    assert est.u.size == val.u.size == 1024 and est.rate_hz == pytest.approx(0.25)
    assert np.sum(est.y >= 10.0) == 47 and np.sum(val.y >= 10.0) == 37  # the overflow clips
    s = D.load_silverbox("all")
    assert s.u.size == 131_072 and s.rate_hz == pytest.approx(D.SILVERBOX_RATE_HZ)
    assert D.load_silverbox().u.size == 131_072 - 40_000
    m, b = D.load_dc_motor(), D.load_dc_motor(brake=True)
    assert (m.u.size, b.u.size) == (1221, 1101) and m.rate_hz == pytest.approx(100.0)
    assert set(np.unique(m.u)) == {5.0, 15.0} and m.output_unit == "rpm"


@needs_data
def test_piezo_with_a_quasi_static_nominal_shows_hysteresis():
    # far below its resonance a piezo stack is a gain: that is the nominal a simulator uses
    d = D.load_piezo()
    k = float(d.u @ d.y / (d.u @ d.u))
    v = diagnose(d.t_s, d.u, d.y, model={"num": [k], "den": [1.0]}, units=("V", "um"))
    assert v.names[0] == "hysteresis"
    assert v.heldout["nrmse_augmented"] < 0.5 * v.heldout["nrmse_nominal"]


@needs_data
def test_dc_motor_affine_map_and_dead_time_without_a_model():
    d = D.load_dc_motor()
    v = diagnose(d.t_s, d.u, d.y, units=("V", "rpm"))
    assert v.names[0] == "static_nonlinearity"
    # the dead time (README: about 0.09 s) is the best second effect and removes about half of what is
    # left on validation, but it shows only at the steps of this 12 s log (10 validation blocks), and
    # the held-out test calibrated on effect-free logs does not pass it: it is reported, not named
    if "time_delay" in v.names:
        delay = next(e for e in v.effects if e["name"] == "time_delay")["params"]["delay_s"]
        assert 0.03 < delay < 0.15
    m = v.model.get("reidentified", v.model)
    zeros = np.roots(m["num"])
    rhp = zeros[zeros.real > 0]
    if "time_delay" not in v.names and rhp.size:
        # identify kept the dead time in the nominal as right-half-plane zeros (the step data show the
        # lag): the all-pass part's delay at low frequency, sum of 2 Re(z)/|z|^2, is that dead time
        assert 0.03 < float(np.sum(2 * rhp.real / np.abs(rhp) ** 2)) < 0.15
    elif "time_delay" not in v.names:
        r2 = next(r for r in v.rounds if r.get("round") == 2)
        assert "time_delay" in r2["best"] and not r2["accepted"] and r2["gain"] > 0.3
    # the affine map: an incremental gain about 245 rpm/V and an intercept about -160 rpm
    st = next(e for e in v.effects if e["name"] == "static_nonlinearity")["params"]
    assert 220 < m["num"][-1] / m["den"][-1] < 270
    assert -200 < st["output_offset_at_centre"] < -120


@needs_data
def test_dc_motor_brake_is_a_changed_load():
    free, brake = D.load_dc_motor(), D.load_dc_motor(brake=True)
    # the motor without brake, identified (its first effect is enough to get the model)
    model = diagnose(free.t_s, free.u, free.y, options=DiagnoseOptions(max_effects=1)).model
    v = diagnose(brake.t_s, brake.u, brake.y, model=model, options=DiagnoseOptions(max_effects=1))
    assert v.names[0] == "load_mass"
    assert 0.45 < v.effects[0]["params"]["gain_factor"] < 0.75  # README: 245 -> 151 rpm/V


@needs_data
def test_silverbox_cubic_stiffness_is_a_static_nonlinearity():
    d = D.load_silverbox()
    d = d.crop(d.t_s[0] + 10.0, d.t_s[0] + 30.0)
    v = diagnose(d.t_s, d.u, d.y, options=DiagnoseOptions(max_effects=1))
    assert v.names[0] == "static_nonlinearity"
    assert v.heldout["nrmse_augmented"] < 0.5 * v.heldout["nrmse_nominal"]


@needs_data
def test_cascaded_tanks_overflow_is_named_saturation_beside_the_static_map():
    # the overflow clips the level at 10 V: the measured output piles up on that value while the
    # linear model goes beyond it; the Torricelli outflow makes the gains and time constants depend
    # on the level, which the static map covers in part (and the offset the identified model leaves out)
    est, val = D.load_cascaded_tanks()
    v = diagnose(est.t_s, est.u, est.y, heldout=(val.t_s, val.u, val.y), units=("V", "V"),
                 options=DiagnoseOptions(max_effects=1))  # the clip check comes on top of the rounds
    h = v.heldout
    assert h["split"] == "separate held-out log" and h["nrmse_nominal"] > 1.0
    assert h["nrmse_augmented"] < 0.4 * h["nrmse_nominal"]
    assert "saturation" in v.names
    # the static map removes nearly all of the validation error (levels of the estimation log) but
    # makes the separate held-out log worse (its levels differ; a degree-5 map extrapolates badly):
    # it is dropped as "seen in training, did not generalise", with both figures
    if "static_nonlinearity" not in v.names:
        d = next(x for x in v.dropped if x["name"] == "static_nonlinearity")
        assert d["final_nrmse_with"] > d["final_nrmse_without"] and d["validation_gap_removed"] > 0.5
    sat = next(e for e in v.effects if e["name"] == "saturation")["params"]
    assert sat["acts_on"] == "output" and sat["upper"] == pytest.approx(10.0)
    assert v.where["level"]["clipped_output"]["upper"]["samples"] == 47


@needs_data
def test_piezo_without_a_model_shows_hysteresis():
    # identified first, a linear model takes the loop's first harmonic as a phase lag; what it cannot
    # take (the loop's odd harmonics, the rest level below the loop's centre) is a rate-independent memory
    d = D.load_piezo()
    # at the default working rate: reduced to 100 Hz (to keep the test short) the validation part is 177
    # samples in 32 blocks, and the block score of a 97 % removal sat at 3.7-4.0 against 3.9 depending on
    # how the working-rate model averages blocks (session 12): a coin toss, not a check
    v = diagnose(d.t_s, d.u, d.y, units=("V", "um"), options=DiagnoseOptions(max_effects=1))
    assert v.names == ["hysteresis"]
    assert v.heldout["nrmse_augmented"] < 0.5 * v.heldout["nrmse_nominal"]
    hy = v.effects[0]["params"]
    assert hy["initial_branch"] < 0.0  # it rests below the loop's centre: it came there rising
    # README: the loop is about 15 % of the 39 um peak-to-peak wide; the play operators' share of it
    # (through the linear part's gain) is about half that here, the linear part keeping some phase lag
    m = v.model.get("reidentified", v.model)
    width = 2.0 * hy["loop_half_width"] * m["num"][-1] / m["den"][-1] / np.ptp(d.y)
    assert 0.05 < width < 0.2
