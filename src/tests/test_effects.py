"""The effects library and the truth actuator, against closed forms and independent simulations."""
from __future__ import annotations

import math
import time

import numpy as np
import pytest
from scipy import signal

from hasel import paper
from hasel.effects import (EFFECT_NAMES, AsymmetricDynamics, ChargeDrift, Hysteresis, LoadMass, Saturation,
                           SensorNonlinearity, StaticNonlinearity, TimeDelay, TruthActuator, from_name, sample_effect)
from hasel.effects.operators import BoucWen, DelayLine, asymmetric_lag, monotone_runs, play, scale_resonances
from hasel.errors import BadInputError
from hasel.plant import NominalActuator

RATE = paper.PLANT_RATE_HZ
P0 = float(paper.plant_tf()[0][-1] / paper.plant_tf()[1][-1])  # static gain of P(s), mm/kV


@pytest.fixture
def rng() -> np.random.Generator:
    return np.random.default_rng(1234)


def _chirp(seconds: float, offset_kv: float = 3.0) -> np.ndarray:
    t = np.arange(int(seconds * RATE)) / RATE
    return offset_kv + signal.chirp(t, 0.2, t[-1], 20.0)


def _settled(act, level_kv: float, seconds: float = 3.0) -> float:
    """Stroke (mm) after holding ``level_kv`` for ``seconds`` from rest at 0 kV."""
    act.reset(0.0)
    return float(act.run(np.full(int(seconds * RATE), level_kv)).stroke_mm[-1])


def test_registry_has_exactly_the_verdict_names():
    assert set(EFFECT_NAMES) == {"static_nonlinearity", "asymmetric_dynamics", "charge_drift", "saturation",
                                 "time_delay", "sensor_nonlinearity", "load_mass", "hysteresis"}
    for name in EFFECT_NAMES:
        assert from_name(name).name == name


def test_from_name_rejects_unknown_names_parameters_and_ranges():
    with pytest.raises(BadInputError, match="unknown effect 'friction'"):
        from_name("friction")
    with pytest.raises(BadInputError, match="time_delay has no parameter lag_s"):
        from_name("time_delay", lag_s=0.1)
    with pytest.raises(BadInputError, match="delay_s must be in"):
        from_name("time_delay", delay_s=-0.1)
    with pytest.raises(BadInputError, match="half_width_kv must be in"):
        from_name("hysteresis", half_width_kv=1.0, h_sat_kv=0.5)


@pytest.mark.parametrize("name", EFFECT_NAMES)
def test_sample_params_draws_valid_and_varied_instances(name):
    a = sample_effect(name, np.random.default_rng(1))
    b = sample_effect(name, np.random.default_rng(2))
    assert a.name == name and type(a)(**a.params()) == a  # round trip through the validator
    assert a != b


def test_no_effect_is_the_nominal_actuator():
    u = _chirp(3.0)
    nom, tru = NominalActuator(), TruthActuator()
    nom.reset(0.0)
    tru.reset(0.0)
    a, b = nom.run(u), tru.run(u)
    np.testing.assert_allclose(b.stroke_mm, a.stroke_mm, rtol=0, atol=1e-12)
    np.testing.assert_allclose(b.applied_kv, a.applied_kv, rtol=0, atol=1e-12)


def test_blocks_equal_one_run_with_every_effect(rng):
    effects = [sample_effect(n, rng) for n in EFFECT_NAMES]
    u = _chirp(2.0)
    act = TruthActuator(effects)
    act.reset(0.5)
    whole = act.run(u).stroke_mm
    act.reset(0.5)
    blocks = np.concatenate([act.run(u[i:i + 50]).stroke_mm for i in range(0, u.size, 50)])
    np.testing.assert_allclose(blocks, whole, rtol=0, atol=1e-9)


def test_time_delay_shifts_the_nominal_response_by_whole_samples():
    u = _chirp(1.0)
    nom = NominalActuator()
    nom.reset(u[0])
    n = 73
    ref = nom.run(np.concatenate([np.full(n, u[0]), u[:-n]])).stroke_mm
    act = TruthActuator([TimeDelay(delay_s=n / RATE)])
    act.reset(u[0])
    np.testing.assert_allclose(act.run(u).stroke_mm, ref, rtol=0, atol=1e-12)


@pytest.mark.parametrize("kind,strength", [("electrostatic", 0.5), ("saturating", 1.5)])
def test_static_map_sets_the_settled_stroke(kind, strength):
    e = StaticNonlinearity(kind=kind, strength=strength, v_ref_kv=5.0)
    act = TruthActuator([e])
    for v in (2.0, 5.0, 7.0):
        if kind == "electrostatic":
            f = (1 - strength) * v + strength * v * v / 5.0
        else:
            f = 5.0 * math.tanh(strength * v / 5.0) / math.tanh(strength)
        assert _settled(act, v) == pytest.approx(P0 * f, rel=1e-6)


def test_amplifier_limit_and_full_stroke():
    amp = TruthActuator([Saturation(kind="amplifier", limit_kv=5.5)])
    assert _settled(amp, 7.0) == pytest.approx(P0 * 5.5, rel=1e-6)
    assert _settled(amp, 4.0) == pytest.approx(P0 * 4.0, rel=1e-6)
    full = TruthActuator([Saturation(kind="stroke", limit_mm=6.0, knee_mm=0.05)])
    z = _settled(full, 7.0)
    assert 6.0 - 0.05 * math.log(2) < z <= 6.0  # softplus knee: at most w ln 2 below the limit at the limit
    assert _settled(full, 2.0) == pytest.approx(P0 * 2.0, abs=1e-9)


def test_load_mass_lowers_resonance_and_damping_keeps_static_gain():
    mu = 25.5 / 39.4
    den = np.asarray(paper.plant_tf()[1])
    loaded = LoadMass(mass_g=25.5).loaded_den(den)
    w = paper.P_NOTCH_RAD_S
    pair = [r for r in np.roots(loaded) if r.imag > 1e-6]
    wn = abs(pair[0])
    zeta = -pair[0].real / wn
    assert wn == pytest.approx(w / math.sqrt(1 + mu), rel=1e-6)
    assert zeta == pytest.approx(230.0 / (2 * w) / math.sqrt(1 + mu), rel=1e-6)
    assert loaded[-1] == pytest.approx(den[-1], rel=1e-12)
    assert _settled(TruthActuator([LoadMass(mass_g=25.5)]), 4.0) == pytest.approx(P0 * 4.0, rel=1e-6)


def test_charge_drift_follows_its_first_order_charge():
    e = ChargeDrift(tau_s=2.0, gain_loss_per_kv=0.01, offset_mm_per_kv=0.03)
    act = TruthActuator([e])
    act.reset(0.0)
    v = 4.0
    z = act.run(np.full(int(6 * RATE), v)).stroke_mm
    for t in (1.0, 3.0, 5.9):
        q = v * (1 - math.exp(-t / 2.0))
        expect = P0 * v * (1 - 0.01 * q) + 0.03 * q
        assert z[int(t * RATE) - 1] == pytest.approx(expect, rel=2e-3)


def test_sensor_curve_acts_on_the_measurement_only():
    e = SensorNonlinearity(bow_mm=0.4, skew_mm=0.1, span_mm=9.0)
    act = TruthActuator([e])
    z = np.array([0.0, 2.25, 4.5, 9.0])
    x = z / 9.0
    expect = z + 0.4 * np.sin(np.pi * x) + 0.1 * (2 * x - 1) ** 3
    np.testing.assert_allclose(act.measure_mm(z), expect, rtol=1e-12)
    np.testing.assert_allclose(act.strain_curve(z), expect, rtol=1e-12)
    assert _settled(act, 3.0) == pytest.approx(P0 * 3.0, rel=1e-6)  # the true stroke is untouched
    assert TruthActuator().strain_curve is None


def test_bouc_wen_matches_a_fine_euler_integration(rng):
    v = np.cumsum(rng.standard_normal(3000)) * 0.05
    beta, gamma = 2.0, 0.6
    bw = BoucWen(beta, gamma)
    bw.reset(v[0])
    h = bw.run(v[1:])
    ref, hh = [], 0.0
    for a, b in zip(v[:-1], v[1:]):
        dv = (b - a) / 400
        for _ in range(400):
            hh += dv - beta * abs(dv) * hh - gamma * dv * abs(hh)
        ref.append(hh)
    np.testing.assert_allclose(h, ref, atol=2e-4)
    assert np.max(np.abs(h)) < 1 / (beta + gamma)


def test_hysteresis_loop_width_is_rate_independent():
    e = Hysteresis(half_width_kv=0.3, h_sat_kv=0.5, shape=0.0)

    def loop_gap(seconds_per_ramp: float, act) -> float:
        n = int(seconds_per_ramp * RATE)
        up = np.linspace(1.0, 7.0, n)
        u = np.concatenate([up, up[::-1]])
        act.reset(1.0)
        z = act.run(u).stroke_mm
        i_up, i_dn = np.argmin(np.abs(up - 4.0)), n + np.argmin(np.abs(up[::-1] - 4.0))
        return float(z[i_dn] - z[i_up])

    # the down-minus-up gap at 4 kV, less that of the (rate-dependent) linear dynamics alone
    gaps = [loop_gap(s, TruthActuator([e])) - loop_gap(s, NominalActuator()) for s in (5.0, 20.0)]
    # saturated branches: the stroke lags by the half-width on the way up and leads on the way down
    assert gaps[0] == pytest.approx(2 * 0.3 * P0, rel=0.01)
    assert gaps[1] == pytest.approx(gaps[0], rel=0.01)


def test_relaxation_slower_than_activation():
    act = TruthActuator([AsymmetricDynamics(tau_relax_s=0.1, tau_activate_s=0.0, stroke_dependence=0.0)])
    nom = NominalActuator()
    u = np.concatenate([np.full(int(RATE), 4.0), np.full(int(RATE), 2.0)])
    act.reset(2.0)
    nom.reset(2.0)
    z, zn = act.run(u).stroke_mm, nom.run(u).stroke_mm
    half = int(RATE)
    np.testing.assert_allclose(z[:half], zn[:half], atol=1e-9)  # activation follows the nominal
    # relaxation: the nominal fall passed through a 0.1 s first-order lag
    a = -math.expm1(-1 / RATE / 0.1)
    ref = signal.lfilter([a], [1, a - 1], zn[half:], zi=[(1 - a) * z[half - 1]])[0]
    np.testing.assert_allclose(z[half:], ref, atol=1e-9)


def test_operators_against_plain_loops(rng):
    x = np.cumsum(rng.standard_normal(5000))
    for r in (0.0, 0.7, 3.0):
        y, ref = 0.5, []
        for xi in x:
            y = min(max(y, xi - r), xi + r)
            ref.append(y)
        np.testing.assert_array_equal(play(x, r, 0.5), ref)
    lag = asymmetric_lag(x, 0.01, 0.02, 0.3, 0.0)
    z, ref = 0.0, []
    for xi in x:
        tau = 0.02 if xi > z else 0.3
        z += (xi - z) * (1 - math.exp(-0.01 / tau))
        ref.append(z)
    np.testing.assert_allclose(lag, ref, rtol=1e-12)
    starts = monotone_runs(np.array([0, 1, 2, 2, 1, 0, 3]))
    np.testing.assert_array_equal(starts, [0, 3, 5])
    d = DelayLine(3)
    d.reset(9.0)
    np.testing.assert_array_equal(np.concatenate([d.run([1, 2]), d.run([3, 4, 5])]), [9, 9, 9, 1, 2])


def test_scale_resonances_closed_form():
    den = np.polymul([1, 3.0], [1, 2.0, 100.0])
    out = scale_resonances(den, 4.0)
    np.testing.assert_allclose(out, np.polymul([1, 3.0], [4.0, 2.0, 100.0]), rtol=1e-12)


def test_a_minute_at_10_khz_with_every_effect_is_fast(rng):
    effects = [sample_effect(n, rng) for n in EFFECT_NAMES]
    u = _chirp(60.0, offset_kv=4.0)
    act = TruthActuator(effects)
    act.reset(0.0)
    t0 = time.perf_counter()
    out = act.run(u)
    elapsed = time.perf_counter() - t0
    assert np.all(np.isfinite(out.stroke_mm))
    assert elapsed < 4.0, f"60 s at 10 kHz took {elapsed:.2f} s"
