"""How well the data pin the identified response: timing offsets, sensor wander, covariance and rival orders.

The logs are the tuning corpus's (``bench/tune_ident/varied.py --seed 1``), rebuilt
here from their drawn conditions; the errors quoted are against the paper's P(s) over
0.1-15 Hz (before: the code as of b66721d).
"""
from __future__ import annotations

import numpy as np
import pytest

import designs
from hasel.ident import identify
from hasel.ident.checks import check_model
from hasel.ident.tffit import TFModel
from hasel.ident.timefit import interleaved, oe_fit, response_uncertainty, simulate_zoh

TRUE = TFModel(np.array([400.0]), np.array([1.0, 16.0, 400.0]))   # 3.2 Hz, damping 0.4, G(0) = 1


def test_a_first_order_hold_at_200_hz_is_a_timing_offset_not_phase():
    """PRBS at 200 Hz, input linearly interpolated and the output 0.39 samples ahead: 0.9 samples of lead.

    Taken into G(s) that lead was 23 deg at 15 Hz (usable, before); estimated as a timing offset it is not.
    """
    log = designs.make_log("prbs", 200.0, seed=729183124, convention="foh", offset_samples=-0.39498054903482505,
                           noise_kind="coloured", noise_mm=0.009691456454564694, noise_fc_hz=10.80229630123136,
                           lsb_mm=10.0 / 4096, amplitude=0.8081124153013544, settle_s=1.4251173530111965,
                           precondition=True)
    r = identify(log.t_s, log.u_kv, log.y_mm, input_name="voltage_kv", output_name="stroke_mm")
    c = r.paper_comparison()
    assert c["max_db"] < 1.0 and c["max_deg"] < 5.0, c
    # the data lead the zero-order-hold model by about 0.9 samples (4.5 ms)
    assert r.timing_offset_s * 200.0 == pytest.approx(-0.9, abs=0.35)
    assert r.usable, r.reasons


def test_a_model_the_data_cannot_single_out_is_refused_with_a_fix():
    """Random level steps at 200 Hz, input linearly interpolated: 2.4 dB / 37 deg off at 15 Hz, usable before.

    A model of another order fits the held-out data as well and differs there by more than twice the
    tolerance: exit 1 with the reason and the experiment that would fix it.
    """
    log = designs.make_log("random_steps", 200.0, seed=947679816, convention="foh",
                           offset_samples=-0.31542334431892805, noise_kind="white", noise_mm=0.01639158298647456,
                           noise_fc_hz=19.577613490929753, lsb_mm=10.0 / 4096, amplitude=0.561256422463365,
                           settle_s=2.7248716695332993, precondition=True)
    r = identify(log.t_s, log.u_kv, log.y_mm, input_name="voltage_kv", output_name="stroke_mm")
    c = r.paper_comparison()
    assert c["max_deg"] > 5.0          # the model is wrong ...
    assert not r.usable                 # ... and says so
    text = " ".join(r.reasons)
    assert "fits the held-out data as well" in text or "the data pin the response only" in text
    assert any("excite more around" in f for f in r.check.fixes)
    assert r.to_model_json()["usable"] is False


def test_response_uncertainty_matches_the_spread_of_repeated_fits():
    """The covariance's standard error of the phase at 5 Hz is within a factor 2 of 12 noise draws' spread."""
    rate = 100.0
    rng0 = np.random.default_rng(11)
    u = np.concatenate([np.zeros(50), np.repeat(rng0.uniform(-1, 1, 300), 10)])
    clean = simulate_zoh(TRUE, u, rate)
    pieces = interleaved(u.size, [(0, u.size)], 200, 1.0 / 3.0, 0)
    f = np.array([1.0, 5.0])
    phases, predicted = [], []
    for k in range(12):
        y = clean + 0.02 * np.random.default_rng(100 + k).standard_normal(u.size)
        oe = oe_fit(TRUE, u, y, rate, pieces, max_nfev=60)
        phases.append(np.degrees(np.angle(oe.model.freqresp(f))))
        sd = response_uncertainty(oe, u, y, rate, pieces, f)
        assert sd is not None
        predicted.append(sd[1])
    spread = np.std(np.array(phases), axis=0, ddof=1)
    pred = np.median(np.array(predicted), axis=0)
    assert np.all(pred > 0.5 * spread) and np.all(pred < 2.0 * spread), (pred, spread)
    assert 0.05 < pred[1] < 2.0    # degrees: a small, nonzero bound


def test_the_slow_baseline_keeps_sensor_wander_out_of_the_static_gain():
    """A 0.3-unit drift over 120 s biases G(0) of a fit with one constant; the 10 s baseline takes it out."""
    rate = 50.0
    rng = np.random.default_rng(4)
    u = np.concatenate([np.zeros(100), np.repeat(rng.uniform(-1, 1, 240), 25)])
    t = np.arange(u.size) / rate
    drift = 0.3 * np.sin(2 * np.pi * t / (2.2 * t[-1])) ** 2
    y = simulate_zoh(TRUE, u, rate) + drift + 0.005 * rng.standard_normal(u.size)
    pieces = interleaved(u.size, [(0, u.size)], 100, 1.0 / 3.0, 0)
    start = TFModel(np.array([300.0]), np.array([1.0, 20.0, 300.0]))
    plain = oe_fit(start, u, y, rate, pieces, max_nfev=90)
    based = oe_fit(start, u, y, rate, pieces, max_nfev=90, drift_s=10.0)
    assert abs(based.model.dc_gain - 1.0) < 0.01
    assert abs(plain.model.dc_gain - 1.0) > 2 * abs(based.model.dc_gain - 1.0)
    assert based.nrmse_heldout < plain.nrmse_heldout


def test_check_7_refuses_a_tied_rival_that_disagrees_and_widens_in_the_roll_off():
    f = np.geomspace(0.1, 10.0, 40)
    rival = TFModel(np.array([484.0]), np.array([1.0, 13.0, 484.0]))   # 3.5 Hz: differs by > 1 dB near 3 Hz
    spread = {"f_hz": f, "sd_db": np.full(f.size, 0.1), "sd_deg": np.full(f.size, 0.5),
              "rivals": [(0, 2, rival, 0.05)], "score": 0.05}
    chk = check_model(TRUE, band_hz=(0.1, 10.0), response_spread=spread)
    assert not chk.usable and "fits the held-out data as well" in chk.reasons[0]
    assert chk.details["rival_max_db"] > 1.0
    # the same rival judged only deep in the roll-off (|G| < 0.03 G(0) above 25 Hz): the tolerances widen
    # by 0.1 G(0) / |G| (4-10 x), it passes
    hi = np.geomspace(25.0, 40.0, 10)
    spread_hi = {**spread, "f_hz": hi, "sd_db": np.full(hi.size, 0.1), "sd_deg": np.full(hi.size, 0.5)}
    assert check_model(TRUE, band_hz=(0.1, 40.0), response_spread=spread_hi).usable
    # a covariance bound beyond the tolerance refuses on its own
    wide = {**spread, "rivals": [], "sd_deg": np.full(f.size, 4.0)}
    chk = check_model(TRUE, band_hz=(0.1, 10.0), response_spread=wide)
    assert not chk.usable and "the data pin the response only" in chk.reasons[0]


def test_check_7_does_not_count_a_difference_within_the_two_models_noise():
    """A tied rival 1.6 dB / 13 deg away near 3 Hz refuses when both are pinned to 0.1 dB / 0.5 deg (1 sd),
    not when the rival's own standard error there is 3 dB / 20 deg (its difference is its own noise)."""
    f = np.geomspace(0.1, 10.0, 40)
    rival = TFModel(np.array([484.0]), np.array([1.0, 13.0, 484.0]))
    pinned = {"f_hz": f, "sd_db": np.full(f.size, 0.1), "sd_deg": np.full(f.size, 0.5),
              "rivals": [(0, 2, rival, 0.05, (np.full(f.size, 0.1), np.full(f.size, 0.5)))], "score": 0.05}
    chk = check_model(TRUE, band_hz=(0.1, 10.0), response_spread=pinned)
    assert not chk.usable and "combined 95 % uncertainty" in chk.reasons[0]
    assert chk.details["rival_u95_db"] == pytest.approx(2.0 * np.hypot(0.1, 0.1))
    loose = {**pinned, "rivals": [(0, 2, rival, 0.05, (np.full(f.size, 3.0), np.full(f.size, 20.0)))]}
    chk = check_model(TRUE, band_hz=(0.1, 10.0), response_spread=loose)
    assert chk.usable, chk.reasons


def _paper_chirp_200():
    """``varied.py --seed 1``'s paper chirp at 200 Hz, k = 0: foh input, wander noise 0.012 mm, amplitude 0.55."""
    return designs.make_log("paper_chirp", 200.0, seed=202260106, convention="foh",
                            offset_samples=-0.15009055250047365, noise_kind="wander", noise_mm=0.012130064070347208,
                            noise_fc_hz=15.398626738552165, lsb_mm=0.0, amplitude=0.5522381515161876,
                            settle_s=0.7034724822382386, precondition=False)


def test_a_right_over_parameterised_model_is_not_refused_for_its_parameterisation():
    """The 4/5 model of a 200 Hz paper chirp is 0.2 dB / 3.1 deg off P(s); refused before (5a1ef5b) with a
    claimed +-6.3 dB / +-90 deg at 0.31 Hz: the derivatives of log G were finite steps 1e8 times a numerator
    coefficient that the model's 45 kHz pole scales to 5e-17. Exact derivatives: a bound of hundredths of a dB.
    The order is given: since h-time the free selection keeps order 2/3 with a -1.8 ms timing offset, which ties
    with 4/5 on the held-out data (0.54 dB / 5.9 deg off, wrong yet usable: bench/tune_ident/RESULT_h-time.md)."""
    log = _paper_chirp_200()
    r = identify(log.t_s, log.u_kv, log.y_mm, input_name="voltage_kv", output_name="stroke_mm", order=(4, 5))
    c = r.paper_comparison()
    assert c["max_db"] < 0.5 and c["max_deg"] < 4.0, c
    assert r.usable, r.reasons
    d = r.check.details
    assert d["response_u95_max_db"] < 0.3 and d["response_u95_max_deg"] < 2.0, d
    # (a wrong model of a tuning log still refused: test_a_model_the_data_cannot_single_out_is_refused_with_a_fix)


def test_a_biased_model_is_refused_against_the_data_with_error_bars():
    """Order (0, 1) forced on the 200 Hz paper chirp: 6.8 dB / 78 deg off P(s) at the band's top yet an 80 %
    held-out fit, usable on the branch before check 8 (no whole periods: check 5 does not run). Its error against
    the data, ``H1(u, y - y_hat) + H1(u, y_hat) - G``, is many standard errors and over 10 % of the response
    over more than an octave: refused. The right order of the same log stays usable (the test above)."""
    log = _paper_chirp_200()
    r = identify(log.t_s, log.u_kv, log.y_mm, input_name="voltage_kv", output_name="stroke_mm", order=(0, 1))
    c = r.paper_comparison()
    assert c["max_db"] > 3.0 and c["max_deg"] > 30.0, c     # the model is wrong ...
    assert not r.usable                                        # ... and says so
    assert any("disagrees with the data" in x for x in r.reasons), r.reasons
    d = r.check.details
    assert d["residual_longest_run_octaves"] > 1.0 or d["residual_disagreeing_share"] > 0.2, d
