"""Tests of the independent other simulator (hasel_bench.othersim) against closed forms and scipy."""
from __future__ import annotations

import math

import numpy as np
import pytest
from scipy import signal

from hasel_bench import othersim as o
from hasel import paper


def _lsim_nominal(u: np.ndarray, rate_hz: float) -> np.ndarray:
    num, den = paper.plant_tf()
    a, b, c, d = signal.tf2ss(num, den)
    x0 = np.linalg.solve(-a, b[:, 0] * u[0])
    _, y, _ = signal.lsim((a, b, c, d), u, np.arange(u.size) / rate_hz, X0=x0)
    return y


@pytest.mark.parametrize("rate_hz", [500.0, 1000.0])
def test_no_effect_equals_lsim_of_p(rate_hz):
    rng = np.random.default_rng(0)
    u, _ = o.excitation(rng, rate_hz, short=True)
    z = o.simulate(u, rate_hz)
    y = _lsim_nominal(u, rate_hz)
    assert np.ptp(y) > 5.0  # a real excitation: several mm of stroke
    np.testing.assert_allclose(z, y, rtol=0, atol=1e-10)


def test_prandtl_ishlinskii_loop_area_closed_form_and_growth():
    r_max, share = 0.6, 0.5
    radii, w = o._pi_weights(r_max, share)
    areas = []
    for amp in (0.4, 0.8, 1.5):
        t = np.linspace(0.0, 2.0, 4001)  # two periods of a 1 Hz sine, from the minimum
        v = 4.0 - amp * np.cos(2 * np.pi * t)
        ve = o.prandtl_ishlinskii(v, r_max, share)
        x, y = v[2000:], ve[2000:]  # the second (periodic) cycle
        area = 0.5 * abs(np.sum(x * np.roll(y, -1) - np.roll(x, -1) * y))
        expected = sum(wi * 4 * r * (amp - r) for r, wi in zip(radii, w) if r < amp)
        assert area == pytest.approx(expected, rel=2e-3)
        areas.append(area)
    assert areas[0] < areas[1] < areas[2]


def test_duhem_rising_branch_and_rate_independence():
    lag = 0.5
    v = np.linspace(2.0, 5.0, 30001)
    out = o.duhem(v, lag, 1.0)
    closed = v - lag * (1.0 - np.exp(-(v - 2.0) / lag))
    np.testing.assert_allclose(out, closed, atol=2e-4)
    # the same path at two rates gives the same loop
    t1 = np.linspace(0, 2, 4001)  # two periods of a 1 Hz sine around 4 kV
    slow = o.duhem(4 + np.sin(2 * np.pi * t1), lag, 0.6)
    fast = o.duhem(4 + np.sin(2 * np.pi * t1[::4]), lag, 0.6)
    np.testing.assert_allclose(slow[::4], fast, atol=5e-3)
    # a loop: at v = 4 kV the rising branch (t = 1 s) lies below the falling one (t = 1.5 s)
    up, down = slow[2000], slow[3000]
    assert down - up > 0.2


def test_pade_is_an_all_pass_with_the_delay_phase():
    d = 0.02
    num, den = o.pade_tf(d)
    w = np.array([1.0, 10.0, 30.0])
    _, h = signal.freqs(num, den, worN=w)
    np.testing.assert_allclose(abs(h), 1.0, rtol=1e-12)
    np.testing.assert_allclose(np.unwrap(np.angle(h)), -w * d, atol=1e-6 * 30)


def test_shift_delay_is_the_nominal_output_shifted():
    rate = 500.0
    rng = np.random.default_rng(1)
    u, _ = o.excitation(rng, rate, short=True)
    k = 7
    z = o.simulate(u, rate, [o.ForeignEffect("time_delay", "shift", {"delay_s": k / rate})])
    z0 = o.simulate(u, rate)
    np.testing.assert_allclose(z[k:], z0[:-k], atol=1e-9)


def test_slew_limit_equals_a_ramp_command():
    rate = 500.0
    u = np.concatenate([np.zeros(100), np.full(400, 2.0)])
    z = o.simulate(u, rate, [o.ForeignEffect("saturation", "slew", {"slew_kv_s": 40.0})])
    # 2 kV at 40 kV/s: a ramp over 50 ms = 25 samples from the step's start (sample 99)
    ramp = np.clip((np.arange(500) - 99) / 25.0, 0.0, 1.0) * 2.0
    np.testing.assert_allclose(z, o.simulate(ramp, rate), atol=1e-9)


@pytest.mark.parametrize("eff, closed", [
    (o.ForeignEffect("static_nonlinearity", "power", {"exponent": 1.5, "v_ref_kv": 4.0}),
     lambda v, p0: p0 * 4.0 * (v / 4.0) ** 1.5),
    (o.ForeignEffect("static_nonlinearity", "knee", {"v_knee_kv": 3.0, "ratio": 0.5, "v_ref_kv": 4.0}),
     lambda v, p0: p0 * (3.0 + 0.5 * (v - 3.0)) * 4.0 / 3.5),
    (o.ForeignEffect("saturation", "soft_stroke", {"knee_mm": 6.0, "room_mm": 0.5}),
     lambda v, p0: 6.0 + 0.5 * math.tanh((p0 * v - 6.0) / 0.5)),
    (o.ForeignEffect("sensor_nonlinearity", "quadratic", {"curvature_per_mm": 0.03, "center_mm": 4.0}),
     lambda v, p0: p0 * v + 0.03 * (p0 * v - 4.0) ** 2),
    (o.ForeignEffect("sensor_nonlinearity", "exponential", {"scale_mm": -12.0, "center_mm": 4.0}),
     lambda v, p0: 4.0 - 12.0 * math.expm1((p0 * v - 4.0) / -12.0)),
])
def test_static_maps_at_rest(eff, closed):
    p0 = float(np.polyval(paper.plant_tf()[0], 0) / np.polyval(paper.plant_tf()[1], 0))
    v = 6.5
    z = o.simulate(np.full(50, v), 500.0, [eff])
    np.testing.assert_allclose(z, closed(v, p0), rtol=1e-9)


def test_screening_drift_follows_the_leaky_integral_of_v_squared():
    rate, v0, tau, share = 200.0, 5.0, 40.0, 0.2
    u = np.full(int(60 * rate), v0)
    z = o.simulate(u, rate, [o.ForeignEffect("charge_drift", "screening", {"tau_s": tau, "share": share})],
                   oversample=1)
    t = np.arange(u.size) / rate
    num, den = paper.plant_tf()
    p = lambda s: float(np.polyval(num, s) / np.polyval(den, s))  # noqa: E731
    c = share * v0 ** 2 / 25.0
    # the input is v0 (1 - c) + v0 c exp(-t / tau): after the plant's transients (poles
    # >= 18.85 rad/s) the output is P(0) v0 (1 - c) + P(-1 / tau) v0 c exp(-t / tau)
    closed = p(0.0) * v0 * (1 - c) + p(-1.0 / tau) * v0 * c * np.exp(-t / tau)
    np.testing.assert_allclose(z[200:], closed[200:], rtol=1e-6)
    assert z[-1] < 0.9 * z[0]


def test_rate_limit_bounds_the_fall_only():
    rate = 1000.0
    u = np.concatenate([np.zeros(200), np.full(400, 5.0), np.zeros(600)])
    eff = o.ForeignEffect("asymmetric_dynamics", "rate_limit", {"rate_mm_s": 10.0})
    z = o.simulate(u, rate, [eff])
    z0 = o.simulate(u, rate)
    dz = np.diff(z) * rate
    assert dz.min() >= -10.0 - 1e-6
    assert np.diff(z0).min() * rate < -30.0  # the nominal falls much faster
    np.testing.assert_allclose(z[:600], z0[:600], atol=1e-12)  # activation untouched


def test_heavier_mode_keeps_dc_and_lowers_one_pair():
    num, den = paper.plant_tf()
    d2 = o._loaded_den(den, 3.0)
    assert np.polyval(num, 0) / np.polyval(d2, 0) == pytest.approx(np.polyval(num, 0) / np.polyval(den, 0))
    w_old = np.sort(np.abs(np.roots(den)[np.abs(np.roots(den).imag) > 1]))
    w_new = np.sort(np.abs(np.roots(d2)[np.abs(np.roots(d2).imag) > 1]))
    assert w_new[0] == pytest.approx(w_old[0] / 2.0, rel=1e-6)  # sqrt(1 + 3)
    assert w_new[-1] == pytest.approx(w_old[-1], rel=1e-6)


def test_sample_foreign_kinds_and_checks():
    rng = np.random.default_rng(4)
    for name, kinds in o.EFFECT_KINDS.items():
        for kind in kinds:
            e = o.sample_foreign(name, rng, kind)
            assert e.kind == kind and all(math.isfinite(x) for x in e.params.values())
    with pytest.raises(ValueError, match="kind must be one of"):
        o.ForeignEffect("hysteresis", "bouc_wen")


def test_end_to_end_delay_is_diagnosed():
    from hasel.diagnose.core import diagnose

    rng = np.random.default_rng(11)
    rate = 500.0
    eff = o.ForeignEffect("time_delay", "shift", {"delay_s": 0.018})
    u, _ = o.excitation(rng, rate, short=True)
    y = o.simulate(u, rate, [eff]) + 0.005 * rng.standard_normal(u.size)
    num, den = paper.plant_tf()
    v = diagnose(np.arange(u.size) / rate, u, y, model={"num": num.tolist(), "den": den.tolist()})
    assert v.names[:1] == ["time_delay"]
    assert v.effects[0]["params"]["delay_s"] == pytest.approx(0.018, rel=0.1)
    assert v.heldout["nrmse_augmented"] < 0.2 * v.heldout["nrmse_nominal"]


def test_case_mix_covers_every_name_and_kind():
    labels = o._draw_labels(28, np.random.default_rng(1))
    assert sum(not lab for lab in labels) == 6 and sum(len(lab) == 2 for lab in labels) == 6
    singles = {lab[0] for lab in labels if len(lab) == 1}
    assert {(n, k) for n, ks in o.EFFECT_KINDS.items() for k in ks} <= singles


def test_score_reveals_labels_and_counts():
    def case(i, effs):
        return o.ForeignCase(i, i, tuple(o.ForeignEffect(n, o.EFFECT_KINDS[n][0]) for n in effs), 500.0, 0.01,
                             {}, f"p{i}")

    cases = [case(0, []), case(1, []), case(2, ["hysteresis"]), case(3, ["time_delay"]),
             case(4, ["saturation", "load_mass"]), case(5, ["saturation", "charge_drift"])]
    named = [[], ["charge_drift"], ["hysteresis", "load_mass"], ["load_mass"],
             ["load_mass", "time_delay", "saturation"], ["charge_drift", "saturation"]]
    res = [{"path": f"p{i}", "names": n, "nrmse_nominal": 0.1, "nrmse_augmented": 0.1 - 0.02 * i, "floor": 0.0,
            "seconds": 1.0} for i, n in enumerate(named)]
    s = o.score(cases, res)
    assert s["false_alarms"] == 1 and s["n_none"] == 2
    assert s["top1_accuracy"] == pytest.approx(2 / 4)  # cases 0 and 2
    assert s["pair_both_named"] == pytest.approx(1.0) and s["pair_first_two"] == pytest.approx(0.5)
    assert s["confusion"]["time_delay"] == {"load_mass": 1}
    assert s["median_shrink"] == pytest.approx(np.median([0.4, 0.6, 0.8, 1.0]))


def test_effect_free_logs_follow_their_sampling_convention(tmp_path):
    from hasel import paper
    from hasel.diagnose.prep import LinearSim
    from hasel_bench.othersim import make_free_case

    num, den = paper.plant_tf()
    zoh = make_free_case(0, 5, str(tmp_path), design="prbs", rate_hz=500.0, convention="zoh", offset_samples=0.0,
                         noise="white", duration_s=10.0)
    d = np.load(zoh.path)
    y_zoh = LinearSim(num, den, 500.0).run(d["voltage_kv"])  # the diagnosis' own zero-order hold
    assert np.std(d["stroke_mm"] - y_zoh) < 1.5 * zoh.noise_mm + 0.001
    cen = make_free_case(1, 5, str(tmp_path), design="prbs", rate_hz=500.0, convention="centred",
                         offset_samples=0.0, noise="white", duration_s=10.0)
    c = np.load(cen.path)
    assert np.array_equal(c["voltage_kv"], d["voltage_kv"])  # same draw, other convention
    y_mid = LinearSim(num, den, 500.0, offset=0.5).run(c["voltage_kv"])
    assert np.std(c["stroke_mm"] - y_mid) < 1.5 * cen.noise_mm + 0.001
    assert np.std(c["stroke_mm"] - y_zoh) > 1.1 * np.std(c["stroke_mm"] - y_mid)  # half a sample matters on steps
