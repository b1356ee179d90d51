"""Rate limits of the diagnosis (hasel.diagnose.ratelimit) against closed forms."""
from __future__ import annotations

import math

import numpy as np
import pytest

from hasel.diagnose.ratelimit import fit_log_scalar, line_share, rate_grid, slew_limit, speed_limit


def _loop_slew(x, rate, dt, x0=None):
    """The definition, one sample at a time (reference)."""
    y = float(x[0]) if x0 is None else float(x0)
    out = []
    for v in x:
        y += min(max(v - y, -rate * dt), rate * dt)
        out.append(y)
    return np.array(out)


def test_slew_limited_step_is_a_ramp():
    dt, rate, h = 1e-3, 30.0, 2.0  # kV/s, kV: a 2 kV step takes 66.7 ms
    t = np.arange(400) * dt
    k0 = 50
    x = np.where(np.arange(t.size) >= k0, h, 0.0)
    y = slew_limit(x, rate, dt)
    expect = np.clip(rate * (t - t[k0] + dt), 0.0, h)  # the first limited sample has moved one step
    np.testing.assert_allclose(y, expect, atol=1e-12)
    # down again: the mirror ramp
    y2 = slew_limit(h - x, rate, dt)
    np.testing.assert_allclose(y2, h - expect, atol=1e-12)


def test_slew_passes_slow_signals_and_limits_fast_ramps():
    dt = 1e-3
    t = np.arange(2000) * dt
    a, w = 1.0, 2 * np.pi * 3.0  # peak speed a w = 18.8 kV/s
    x = 4.0 + a * np.sin(w * t)
    np.testing.assert_allclose(slew_limit(x, 1.05 * a * w, dt), x, atol=1e-12)
    # a ramp faster than the limit is followed at the limit, from the start
    ramp = 50.0 * t
    np.testing.assert_allclose(slew_limit(ramp, 20.0, dt), 20.0 * t, atol=1e-9)
    # the output never moves faster than the limit, and a too-slow limit turns the sine into a
    # triangle whose slope is the limit
    y = slew_limit(x, 0.5 * a * w, dt)
    v = np.diff(y) / dt
    assert np.max(np.abs(v)) <= 0.5 * a * w * (1 + 1e-9)
    assert np.mean(np.isclose(np.abs(v), 0.5 * a * w)) > 0.5


def test_slew_matches_its_definition_on_random_signals():
    rng = np.random.default_rng(4)
    for _ in range(30):
        n = int(rng.integers(2, 400))
        x = np.repeat(rng.normal(0, 2, n // 8 + 1), 8)[:n] + 0.05 * np.cumsum(rng.normal(size=n))
        rate, dt = float(rng.uniform(0.5, 80)), 1e-2
        x0 = None if rng.random() < 0.5 else float(rng.normal(0, 3))
        np.testing.assert_allclose(slew_limit(x, rate, dt, x0), _loop_slew(x, rate, dt, x0), atol=1e-12)
    with pytest.raises(ValueError):
        slew_limit(np.ones(3), -1.0, 1e-3)
    np.testing.assert_array_equal(slew_limit(np.arange(5.0), math.inf, 1e-3), np.arange(5.0))


def test_speed_limit_falling_step_is_a_ramp_and_rising_passes():
    dt, rate, h = 2e-3, 12.0, 5.0  # mm/s, mm
    n, k0 = 600, 100
    t = np.arange(n) * dt
    up = np.where(np.arange(n) >= k0, h, 0.0)
    # rising: followed at once
    np.testing.assert_array_equal(speed_limit(up, rate, dt, "falling"), up)
    down = h - up
    y = speed_limit(down, rate, dt, "falling")
    np.testing.assert_allclose(y, np.clip(h - rate * (t - t[k0] + dt), 0.0, h) * (t >= t[k0]) + h * (t < t[k0]),
                               atol=1e-12)
    # the mirror: a rising limit ramps the rise and passes the fall
    yr = speed_limit(up, rate, dt, "rising")
    np.testing.assert_allclose(yr, np.clip(rate * (t - t[k0] + dt), 0.0, h), atol=1e-12)
    np.testing.assert_array_equal(speed_limit(down, rate, dt, "rising"), down)
    with pytest.raises(ValueError):
        speed_limit(up, rate, dt, "sideways")


def test_speed_limit_on_a_sine_rises_with_it_and_falls_at_the_limit():
    dt = 1e-3
    t = np.arange(3000) * dt
    z = 3.0 + 2.0 * np.sin(2 * np.pi * 2.0 * t)  # falls at up to 25.1 mm/s
    y = speed_limit(z, 10.0, dt)
    v = np.diff(y) / dt
    assert v.min() >= -10.0 * (1 + 1e-9)
    assert np.all(y >= z - 1e-12)  # a limited fall can only lag above
    # wherever the output differs from the input it falls at exactly the limit
    free = np.isclose(y, z, atol=1e-12)
    assert (~free).mean() > 0.1
    np.testing.assert_allclose(v[~free[1:]], -10.0, rtol=1e-9)
    # and a limit above the fastest fall does nothing
    np.testing.assert_array_equal(speed_limit(z, 26.0, dt), z)


def test_rate_grid_spans_the_signal_speeds():
    dt = 1e-3
    t = np.arange(5000) * dt
    x = np.sin(2 * np.pi * 1.0 * t)  # speeds up to 2 pi
    g = rate_grid(x, dt, n=8)
    assert g.size == 8 and np.all(np.diff(g) > 0)
    assert g[-1] < 2 * np.pi and g[-1] > 0.9 * 2 * np.pi
    # from the median speed (of a sine: 2 pi cos(pi/4), half the time above it), but at most half
    # the fastest, so that the grid spans a range
    assert g[0] == pytest.approx(min(2 * np.pi * math.cos(math.pi / 4), 0.5 * g[-1]), rel=0.01)
    # a chirp-like signal that is slow most of the time starts at its median speed
    xs = np.concatenate([np.sin(2 * np.pi * 0.2 * t), np.sin(2 * np.pi * 5.0 * t[:500])])
    gs = rate_grid(xs, dt, n=8)
    sp = np.abs(np.diff(xs)) / dt
    assert gs[0] == pytest.approx(np.median(sp[sp > 0]), rel=1e-9)
    gf = rate_grid(x + 0.0 * t, dt, n=5, direction="falling")
    assert gf.size == 5 and gf[-1] < 2 * np.pi
    assert rate_grid(np.ones(100), dt).size == 0


def test_fit_log_scalar_finds_the_minimum_between_grid_points():
    grid = np.geomspace(1.0, 100.0, 6)
    v, c = fit_log_scalar(lambda s: (math.log(s) - math.log(7.3)) ** 2, grid)
    assert v == pytest.approx(7.3, rel=1e-3)
    assert c < 1e-6
    assert math.isnan(fit_log_scalar(lambda s: s, np.zeros(0))[0])
    # a minimum below the grid: the grid is extended downwards by its ratio (here 2, 4 times at most)
    v, _ = fit_log_scalar(lambda s: (math.log(s) - math.log(3.0)) ** 2, np.geomspace(10.0, 80.0, 4))
    assert v == pytest.approx(3.0, rel=1e-3)
    v, _ = fit_log_scalar(lambda s: (math.log(s) - math.log(0.01)) ** 2, np.geomspace(10.0, 80.0, 4))
    assert v == pytest.approx(10.0 / 2 ** 4, rel=1e-3)  # no further than that


def test_line_share_closed_forms():
    z = np.linspace(-1.0, 1.0, 20001)
    assert line_share(0.3 + 2.0 * z, z) == pytest.approx(0.0, abs=1e-12)
    assert line_share(np.full(z.size, 4.0), z) == 0.0
    # z^2 on a symmetric uniform range is uncorrelated with z: none of it is a line
    assert line_share(z ** 2, z) == pytest.approx(1.0, abs=1e-9)
    # z + e z^2: var(z) = 1/3, var(z^2) = 4/45 (uniform on [-1, 1])
    e = 0.5
    expect = math.sqrt(e * e * 4 / 45 / (1 / 3 + e * e * 4 / 45))
    assert line_share(z + e * z ** 2, z) == pytest.approx(expect, rel=1e-3)


# -- the families that use them (hasel.diagnose.augment), on short synthetic logs -------------------

def _log(rng, rate_hz=500.0):
    """Steps and a fast sine burst (kV) at ``rate_hz``: 8 s."""
    def hold(v, s):
        return np.full(int(round(s * rate_hz)), float(v))

    tb = np.arange(int(2.0 * rate_hz)) / rate_hz
    u = np.concatenate([hold(0.0, 0.5), hold(2.0, 1.0), hold(5.0, 1.0), hold(3.0, 1.0), hold(1.0, 1.0),
                        4.0 + 1.0 * np.sin(2 * np.pi * (1.0 * tb + 3.0 * tb * tb)), hold(2.0, 1.5)])
    return np.arange(u.size) / rate_hz, u


def _pipe(t, u, y, num, den):
    from hasel.diagnose.augment import Pipeline
    from hasel.diagnose.prep import prepare

    prep = prepare(t, u, y, model_den=den)
    # lsim interpolates the input linearly (a first-order hold), which leads a held input by half a
    # sample: these tests of the effect families give the pipeline that known convention
    prep.sample_offset = 0.5
    return Pipeline(prep, num, den)


def _lsim(num, den, t, u):
    from scipy import signal

    return signal.lsim((num, den), u, t)[1]


def test_saturation_family_finds_a_slew_limit_and_the_asymmetric_family_a_speed_limit():
    from hasel import paper
    from hasel.diagnose.augment import _sse, describe_params, fit_family

    rng = np.random.default_rng(7)
    num, den = paper.plant_tf()
    t, u = _log(rng)
    dt = t[1] - t[0]
    # slew: the plant driven by the slew-limited command (scipy's simulation of P(s))
    y = _lsim(num, den, t, slew_limit(u, 25.0, dt)) + 0.003 * rng.standard_normal(t.size)
    pipe = _pipe(t, u, y, num, den)
    f = fit_family(pipe, {}, "saturation")
    assert f.variant == "slew"
    assert f.theta[0] == pytest.approx(25.0, rel=0.03)
    assert _sse(pipe, {"saturation": f}) < 0.05 * _sse(pipe, {})
    p = describe_params(pipe, f, ("kV", "mm"))
    assert p["slew_rate_limit"] == f.theta[0] and p["unit"] == "kV/s"
    # speed limit of the relaxation: the stroke falls at most 6 mm/s
    z = _lsim(num, den, t, u)
    y2 = speed_limit(z, 6.0, dt) + 0.003 * rng.standard_normal(t.size)
    pipe2 = _pipe(t, u, y2, num, den)
    f2 = fit_family(pipe2, {}, "asymmetric_dynamics")
    assert f2.variant == "rate_limit:falling"
    assert f2.theta[0] == pytest.approx(6.0, rel=0.03)
    assert describe_params(pipe2, f2, ("kV", "mm"))["direction"] == "falling"
    # warm start from the fit keeps the variant and the value
    f3 = fit_family(pipe2, {}, "asymmetric_dynamics", init=f2)
    assert f3.variant == f2.variant and f3.theta[0] == pytest.approx(6.0, rel=0.03)


def test_static_map_that_is_nearly_a_line_keeps_only_its_offset():
    from hasel import paper
    from hasel.diagnose.augment import _sse, fit_family

    rng = np.random.default_rng(8)
    num, den = paper.plant_tf()
    t, u = _log(rng)
    # a gain 1.25 times the nominal's: a line of the input, no curve
    y = 1.25 * _lsim(num, den, t, u) + 0.003 * rng.standard_normal(t.size)
    pipe = _pipe(t, u, y, num, den)
    f = fit_family(pipe, {}, "static_nonlinearity")
    assert len(f.theta) == 1  # only its offset: a gain is no static nonlinearity
    load = fit_family(pipe, {}, "load_mass")  # but the load family's gain factor
    assert load.theta[1] == pytest.approx(1.25, rel=0.02) and len(load.theta) == 2
    assert _sse(pipe, {"load_mass": load}) < 0.02 * _sse(pipe, {})
    # a true curve (an electrostatic-like square law of the input) keeps its curvature
    y2 = _lsim(num, den, t, u * u / 4.0) + 0.003 * rng.standard_normal(t.size)
    pipe2 = _pipe(t, u, y2, num, den)
    f2 = fit_family(pipe2, {}, "static_nonlinearity")
    assert len(f2.theta) > 2
    assert _sse(pipe2, {"static_nonlinearity": f2}) < 0.02 * _sse(pipe2, {})


def test_load_with_twice_the_inertia_and_a_sag():
    from hasel import paper
    from hasel.diagnose.augment import _sse, describe_params, fit_family

    rng = np.random.default_rng(9)
    num, den = paper.plant_tf()
    t, u = _log(rng)
    # P(s) (17) with its two mechanical pole pairs' inertia doubled, and 0.2 mm of sag
    w2 = paper.P_NOTCH_RAD_S ** 2
    quad = np.array([2.0, 230.0, w2])
    den2 = np.polymul(np.polymul([1, 18.85], [1, 56.55]), np.polymul(quad, quad))
    den2 = den2 * den[-1] / den2[-1]
    y = _lsim(num, den2, t, u) - 0.2 + 0.003 * rng.standard_normal(t.size)
    pipe = _pipe(t, u, y, num, den)
    load = fit_family(pipe, {}, "load_mass")
    assert load.variant == "model:sag"
    assert load.theta[0] == pytest.approx(1.0, rel=0.05)
    assert load.theta[2] == pytest.approx(-0.2, abs=0.01)
    assert _sse(pipe, {"load_mass": load}) < 0.02 * _sse(pipe, {})
    assert describe_params(pipe, load, ("kV", "mm"))["offset"] == load.theta[2]


def test_diagnose_names_a_slew_limit_saturation_and_says_why():
    from hasel import paper
    from hasel.diagnose import diagnose

    rng = np.random.default_rng(10)
    num, den = paper.plant_tf()
    t, u = _log(rng)
    y = _lsim(num, den, t, slew_limit(u, 20.0, t[1] - t[0])) + 0.005 * rng.standard_normal(t.size)
    v = diagnose(t, u, y, model={"num": num.tolist(), "den": den.tolist()}, units=("kV", "mm"))
    assert v.names == ["saturation"]
    e = v.effects[0]
    assert e["params"]["variant"] == "slew" and e["params"]["slew_rate_limit"] == pytest.approx(20.0, rel=0.05)
    assert "slew-rate limit" in e["evidence"]
    assert v.heldout["nrmse_augmented"] < 2.0 * v.noise_floor_nrmse
