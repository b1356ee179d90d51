"""hasel.lti: the ZOH discretisation against an independent matrix-exponential reference."""
from __future__ import annotations

import numpy as np
import pytest
from scipy import linalg, signal

from hasel import paper
from hasel.errors import BadInputError
from hasel.lti import SosFilter, butter2_analog, is_stable, tf_freqresp, zoh_sos


def _reference_zoh(num, den, dt, u):
    """ZOH by the matrix exponential of scipy's own realisation, simulated by dlsim."""
    A, B, C, D = signal.tf2ss(num, den)
    n = A.shape[0]
    M = np.zeros((n + 1, n + 1)); M[:n, :n] = A; M[:n, n:] = B
    E = linalg.expm(M * dt)
    _, y, _ = signal.dlsim((E[:n, :n], E[:n, n:], C, D, dt), u)
    return y.ravel()


SYSTEMS = {
    "first order": ([2.0], [1.0, 3.0]),
    "biproper": ([1.0, 2.0, 3.0], [1.0, 5.0, 6.0]),
    "amplifier 500 Hz": butter2_analog(500.0),
    "paper P(s)": paper.plant_tf(),
}


@pytest.mark.parametrize("name", SYSTEMS)
def test_zoh_matches_matrix_exponential(name):
    num, den = SYSTEMS[name]
    dt = 1e-4
    t = np.arange(0.0, 0.5, dt)
    u = np.sin(2 * np.pi * 8.0 * t**2) + 0.3
    y = signal.sosfilt(zoh_sos(num, den, dt), u)
    ref = _reference_zoh(num, den, dt, u)
    assert np.max(np.abs(y - ref)) <= 1e-8 * max(1.0, np.max(np.abs(ref)))


def test_end_output_is_start_output_one_sample_later():
    num, den = paper.plant_tf()
    u = np.random.default_rng(0).standard_normal(2000)
    y0 = signal.sosfilt(zoh_sos(num, den, 1e-4), u)
    y1 = signal.sosfilt(zoh_sos(num, den, 1e-4, output="end"), u)
    np.testing.assert_allclose(y1[:-1], y0[1:], atol=1e-10)


def test_zoh_is_exact_at_sample_instants_for_a_step():
    # a first-order lag k/(s+a) under a held step: y(t) = k/a (1 - exp(-a t))
    k, a, dt = 2.0, 3.0, 0.01
    y = signal.sosfilt(zoh_sos([k], [1.0, a], dt, output="end"), np.ones(100))
    t = dt * np.arange(1, 101)
    np.testing.assert_allclose(y, k / a * (1 - np.exp(-a * t)), rtol=1e-12)


def test_static_gain_of_paper_plant():
    num, den = paper.plant_tf()
    sos = zoh_sos(num, den, 1e-4)
    dc = np.prod(sos[:, :3].sum(axis=1) / sos[:, 3:].sum(axis=1))
    assert dc == pytest.approx(num[-1] / den[-1], rel=1e-9)
    assert num[-1] / den[-1] == pytest.approx(1.3509, abs=1e-4)


def test_sosfilter_keeps_state_across_calls():
    sos = zoh_sos(*paper.plant_tf(), 1e-4)
    u = np.random.default_rng(1).standard_normal(1000)
    whole = signal.sosfilt(sos, u)
    f = SosFilter(sos)
    parts = np.concatenate([f.run(u[:333]), f.run(u[333:777]), f.run(u[777:])])
    np.testing.assert_allclose(parts, whole, atol=1e-12)


def test_sosfilter_reset_is_at_rest():
    f = SosFilter(zoh_sos(*paper.plant_tf(), 1e-4))
    f.reset(3.0)
    np.testing.assert_allclose(f.run(np.full(50, 3.0)), 3.0 * f.dc_gain, rtol=1e-9)


def test_freqresp_and_stability_helpers():
    num, den = paper.plant_tf()
    h = tf_freqresp(num, den, np.array([0.0, 122.2 / (2 * np.pi)]))
    assert abs(h[0]) == pytest.approx(1.3509, abs=1e-4)
    assert abs(h[1]) < 1e-9  # the notch zero of P(s) sits on the imaginary axis
    assert is_stable(den) and not is_stable([1.0, -1.0])


def test_bad_arguments():
    with pytest.raises(BadInputError, match="proper"):
        zoh_sos([1.0, 0.0, 0.0], [1.0, 1.0], 0.1)
    with pytest.raises(BadInputError, match="dt_s must be > 0"):
        zoh_sos([1.0], [1.0, 1.0], 0.0)
    with pytest.raises(BadInputError, match="strictly proper"):
        zoh_sos([1.0, 1.0], [1.0, 2.0], 0.1, output="end")
    with pytest.raises(BadInputError, match="finite"):
        zoh_sos([np.nan], [1.0, 1.0], 0.1)


def test_critical_filter_has_3db_at_cutoff_and_nonnegative_impulse_response():
    from hasel.lti import critical2_analog

    num, den = critical2_analog(500.0)
    assert abs(tf_freqresp(num, den, np.array([500.0]))[0]) == pytest.approx(2**-0.5, rel=1e-12)
    sos = zoh_sos(num, den, 1e-4, output="end")
    h = signal.sosfilt(sos, np.r_[1.0, np.zeros(400)])
    assert h.min() >= -1e-15  # so the output stays within the range of the inputs


def test_constant_block_path_equals_sosfilt():
    sos = zoh_sos(*paper.plant_tf(), 1e-4, output="end")
    a, b = SosFilter(sos), SosFilter(sos)
    rng = np.random.default_rng(4)
    for u in rng.uniform(0, 9, 200):
        np.testing.assert_allclose(a.run_constant(float(u), 50), b.run(np.full(50, u)), rtol=1e-9, atol=1e-12)
    np.testing.assert_allclose(a.zi, b.zi, rtol=1e-9, atol=1e-12)


def test_zero_at_the_origin():
    # a differentiating numerator (zero at s = 0): no DC gain to match the discrete gain on
    num, den = [1.0, 0.0], [1.0, 3.0, 2.0]
    u = np.sin(np.arange(500) * 0.05)
    y = signal.sosfilt(zoh_sos(num, den, 0.01), u)
    np.testing.assert_allclose(y, _reference_zoh(num, den, 0.01, u), atol=1e-10)


def test_held_command_block_of_the_nominal_actuator_equals_sample_by_sample_filtering():
    # the one-matrix path of a held command against scipy's sosfilt of both filters
    from hasel.plant import NominalActuator

    fast, slow = NominalActuator(), NominalActuator()
    rng = np.random.default_rng(5)
    for u in rng.uniform(0, 9, 100):
        a = fast.run_held(float(u), 50)
        b = ActuatorRef(slow, np.full(50, u))
        np.testing.assert_allclose(a.applied_kv, b[0], rtol=1e-9, atol=1e-12)
        np.testing.assert_allclose(a.stroke_mm, b[1], rtol=1e-9, atol=1e-12)
    # and the held value goes to 9 kV and back with the states carried over
    np.testing.assert_allclose(fast.run_held(9.0, 50).stroke_mm, ActuatorRef(slow, np.full(50, 9.0))[1],
                               rtol=1e-9, atol=1e-12)


def ActuatorRef(act, u):  # noqa: N802 - reads like the model it stands for
    """The same actuator's two filters run by scipy.signal.sosfilt, sample by sample."""
    return act._amp.run(u), act._chain.run(u)
