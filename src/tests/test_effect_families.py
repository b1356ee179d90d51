"""hasel.effects families: the registry, chunked == whole, fits recovering known parameters, bounds."""
from __future__ import annotations

import importlib
import math
from types import SimpleNamespace

import numpy as np
import pytest
from scipy import signal

from hasel import paper
from hasel.effects import EFFECT_NAMES, TruthActuator, from_name, sample_effect
from hasel.effects.base import SLOTS, EffectFamily, EffectFit, run_chunked
from hasel.effects.registry import FAMILIES, NAMES, family
from hasel.errors import BadInputError

DT = 1e-4  # the plant's 10 kHz
CHUNK = 50  # 5 ms


def _signal(n: int = 20000, seed: int = 3) -> np.ndarray:
    """A wandering voltage-like signal (kV) with reversals, steps and fast parts."""
    rng = np.random.default_rng(seed)
    t = np.arange(n) * DT
    x = 3.0 + 2.0 * np.sin(2 * np.pi * (1.0 + 4.0 * t) * t) + 0.5 * np.sign(np.sin(2 * np.pi * 3.1 * t))
    return x + 0.05 * np.cumsum(rng.standard_normal(n)) * math.sqrt(DT)


_SCALES = SimpleNamespace(u_c=3.0, u_s=2.5, y_c=4.0, y_s=3.0, thresholds=(0.05, 0.15, 0.35, 0.75, 1.5),
                          num=np.asarray(paper.plant_tf()[0]), den=np.asarray(paper.plant_tf()[1]),
                          tau_smooth_s=0.05)

#: One generic fit of each variant (the forms the diagnosis fits and a plant file will carry).
GENERIC = [
    EffectFit("time_delay", "input", (7.3 * DT,)),
    EffectFit("time_delay", "input", (12 * DT,)),
    EffectFit("saturation", "input:upper", (4.5,)),
    EffectFit("saturation", "output:lower", (1.0,)),
    EffectFit("saturation", "measured:both", (1.0, 5.0)),
    EffectFit("saturation", "slew", (40.0,)),
    EffectFit("static_nonlinearity", "input", (0.02, 0.1, 0.05, -0.03)),
    EffectFit("static_nonlinearity", "internal", (0.0, 0.05, 0.1)),
    EffectFit("hysteresis", "input", (0.1, 0.2, 0.0, 0.3, 0.05, -0.5)),
    EffectFit("load_mass", "model:sag", (0.5, 1.1, -0.1)),
    EffectFit("asymmetric_dynamics", "output", (0.002, 0.03, 0.0)),
    EffectFit("asymmetric_dynamics", "output", (0.0, 0.03, 0.7)),
    EffectFit("asymmetric_dynamics", "rate_limit:falling", (20.0,)),
    EffectFit("charge_drift", "output", (0.4, 0.05, 0.02)),
    EffectFit("sensor_nonlinearity", "output", (0.01, 0.02, -0.04)),
    EffectFit("charge_drift", "output:travel", (0.4, -0.02, 0.01)),
    EffectFit("saturation", "output:slew", (15.0,)),
]


def test_registry_lists_the_eight_families_once_each_in_their_own_modules():
    assert NAMES == EFFECT_NAMES and len(NAMES) == 8 and len(set(NAMES)) == 8
    mods = set()
    for name, fam in FAMILIES.items():
        assert isinstance(fam, EffectFamily) and fam.name == name and fam.slot in SLOTS
        mods.add(type(fam).__module__)
        assert importlib.import_module(type(fam).__module__).FAMILY is fam
        assert fam.truth_class.name == name
    assert len(mods) == 8
    assert {FAMILIES[n].slot for n in NAMES} == set(SLOTS)
    with pytest.raises(BadInputError):
        family("backlash")


@pytest.mark.parametrize("fit", GENERIC, ids=lambda f: f"{f.name}-{f.variant}")
def test_generic_form_in_5ms_chunks_equals_one_call(fit):
    fam = FAMILIES[fit.name]
    x = _signal()
    u = x if fit.name != "charge_drift" else x - 1.0  # the drift reads the input beside the output
    whole_stage = fam.stage(fit, _SCALES, DT)
    whole_stage.reset(float(x[0]))
    whole = whole_stage.run(x, u)
    chunked = run_chunked(fam.stage(fit, _SCALES, DT), x, CHUNK, u)
    assert np.all(np.isfinite(whole))
    np.testing.assert_allclose(chunked, whole, rtol=0, atol=1e-12 * float(np.max(np.abs(whole))))
    assert not np.array_equal(whole, x)  # the effect does something on this signal
    if fit.name != "charge_drift":
        np.testing.assert_array_equal(fam.simulate(fit, x, _SCALES, DT), whole)


def test_chunked_stages_without_arithmetic_state_are_bit_for_bit():
    x = _signal()
    for fit in (GENERIC[1], GENERIC[5], GENERIC[8], GENERIC[10], GENERIC[12], GENERIC[-1]):
        fam = FAMILIES[fit.name]
        assert np.array_equal(run_chunked(fam.stage(fit, _SCALES, DT), x, CHUNK),
                              fam.simulate(fit, x, _SCALES, DT)), fit


@pytest.mark.parametrize("name", EFFECT_NAMES)
def test_truth_form_in_chunks_equals_one_call(name):
    fam = FAMILIES[name]
    x = _signal()
    for seed in range(3):
        e = sample_effect(name, np.random.default_rng(seed))
        if name == "load_mass":
            e = from_name("load_mass", mass_g=e.mass_g, sag_mm=0.2)
        a, b = fam.truth_stage(e, DT), fam.truth_stage(e, DT)
        a.reset(float(x[0]))
        whole = a.run(x, x)
        chunked = run_chunked(b, x, CHUNK, x)
        np.testing.assert_allclose(chunked, whole, rtol=0, atol=1e-12 * float(np.max(np.abs(whole))))


def test_truth_actuator_in_5ms_blocks_equals_one_long_call_with_every_effect():
    rng = np.random.default_rng(11)
    effs = [sample_effect(n, rng) for n in EFFECT_NAMES]
    x = np.clip(_signal(30000), -1.0, 9.0)
    a = TruthActuator(effs)
    a.reset(float(x[0]))
    whole = a.run(x).stroke_mm
    a.reset(float(x[0]))
    chunked = np.concatenate([a.run(x[i:i + CHUNK]).stroke_mm for i in range(0, x.size, CHUNK)])
    # a Bouc-Wen run split at a block boundary restarts its closed form there: rounding only
    np.testing.assert_allclose(chunked, whole, rtol=0, atol=1e-11)


def test_fractional_delay_matches_linear_interpolation_in_time():
    from hasel.effects.delay import shift
    from hasel.effects.operators import DelayStage

    x = _signal(5000)
    t = np.arange(x.size) * DT + 12.5
    for d in (0.0, 3 * DT, 7.3 * DT, 0.5 * DT, 101.77 * DT):
        ref = np.interp(t - d, t, x, left=x[0], right=x[-1])
        # np.interp works on the rounded times (t = 12.5 s + k dt: ~1e-14 s off): a relative timing error
        # of ~1e-10 of a sample, times the largest jump between samples
        np.testing.assert_allclose(shift(t, x, d), ref, rtol=0, atol=1e-9 * np.max(np.abs(np.diff(x))))
    # an integer delay is a pure shift, bit for bit
    st = DelayStage(12)
    st.reset(float(x[0]))
    y = st.run(x)
    assert np.array_equal(y[12:], x[:-12]) and np.all(y[:12] == x[0])


def test_drift_charge_is_the_three_low_passes_from_zero():
    from hasel.effects.drift import charge

    x = _signal(8000)
    dt, ts, tau = 1e-3, 0.2, 3.0
    ref = x
    for tc in (ts, ts, tau):
        a = -math.expm1(-dt / tc)
        ref = signal.lfilter([a], [1.0, a - 1.0], ref)
    np.testing.assert_array_equal(charge(x, tau, dt, ts, 2.0), ref / 2.0)


def test_load_transform_lowers_the_resonance_and_keeps_the_static_gain():
    from hasel.effects.load import loaded_den

    num, den = paper.plant_tf()
    fam = FAMILIES["load_mass"]
    n2, d2 = fam.transform(num, den, EffectFit("load_mass", "model", (0.69, 1.0)))
    assert np.polyval(n2, 0) / np.polyval(d2, 0) == pytest.approx(np.polyval(num, 0) / np.polyval(den, 0), rel=1e-12)
    w0 = np.sort(np.abs(np.roots(den)[np.abs(np.roots(den).imag) > 1]))
    w1 = np.sort(np.abs(np.roots(d2)[np.abs(np.roots(d2).imag) > 1]))
    np.testing.assert_allclose(w1, w0 / math.sqrt(1.69), rtol=1e-6)  # double poles: roots to sqrt(eps)
    assert np.array_equal(loaded_den(den, 0.0), np.asarray(den, float))


# -- fits on noiseless logs simulated by the same forms ---------------------------------------

def _steps_and_chirp(rate_hz: float = 500.0) -> tuple[np.ndarray, np.ndarray]:
    def hold(v, s):
        return np.full(int(round(s * rate_hz)), float(v))

    tb = np.arange(int(4.0 * rate_hz)) / rate_hz
    u = np.concatenate([hold(0.0, 0.5), hold(2.0, 1.0), hold(5.0, 1.0), hold(3.0, 1.0), hold(1.0, 1.0),
                        3.5 + 2.5 * np.sin(2 * np.pi * (0.5 + 1.0 * tb) * tb), hold(2.0, 1.0),
                        3.0 + 2.0 * np.sin(2 * np.pi * 0.7 * tb), hold(0.0, 0.5)])
    return np.arange(u.size) / rate_hz, u


def _pipe_with(true: EffectFit):
    """A pipeline on a noiseless log made by the pipeline's own chain with ``true``."""
    from hasel.diagnose.augment import Pipeline
    from hasel.diagnose.prep import prepare

    num, den = paper.plant_tf()
    t, u = _steps_and_chirp()
    probe = Pipeline(prepare(t, u, signal.lsim((num, den), u, t)[1], model_den=den), num, den)
    y = probe.stages({true.name: true}, 0)["y"]
    rec = probe.prep.records[0]
    return Pipeline(prepare(rec.t_s, rec.u, y, model_den=den), num, den)


RECOVER = [
    (EffectFit("time_delay", "input", (0.0123,)), 0.02),
    (EffectFit("load_mass", "model", (0.6, 1.1)), 0.02),
    (EffectFit("asymmetric_dynamics", "output", (0.0, 0.06, 0.0)), 0.05),
    (EffectFit("asymmetric_dynamics", "rate_limit:falling", (8.0,)), 0.02),
    (EffectFit("saturation", "slew", (30.0,)), 0.02),
    (EffectFit("saturation", "output:slew", (12.0,)), 0.02),
]


@pytest.mark.parametrize("true,rel", RECOVER, ids=lambda v: getattr(v, "name", ""))
def test_fit_recovers_known_parameters_within_its_bounds(true, rel):
    from hasel.diagnose.augment import _sse

    pipe = _pipe_with(true)
    fam = FAMILIES[true.name]
    fit = fam.fit(pipe, {})
    assert fit is not None and fit.variant.split(":")[0] == true.variant.split(":")[0]
    for got, want in zip(fit.theta, true.theta):
        assert got == pytest.approx(want, rel=rel, abs=1e-2 * rel), (fit.theta, true.theta)
    assert all(abs(v) < 1e-6 for v in fit.theta[len(true.theta):])  # no sag where there is none
    lo, hi = fam.bounds(pipe, fit)
    assert np.all(np.asarray(fit.theta) >= lo) and np.all(np.asarray(fit.theta) <= hi)
    assert _sse(pipe, {true.name: fit}) < 1e-4 * _sse(pipe, {})
    d = fam.describe(pipe, fit, ("kV", "mm"), {})
    assert d["variant"] == fit.variant and set(fam.param_names(fit)) and fit.named()


def test_polynomial_maps_and_hysteresis_reproduce_their_logs():
    from hasel.diagnose.augment import _sse

    for true in (EffectFit("static_nonlinearity", "input", (0.0, 0.0, 0.08)),
                 EffectFit("sensor_nonlinearity", "output", (0.0, 0.0, -0.05, 0.02)),
                 EffectFit("hysteresis", "input", (0.0, 0.3, 0.0, 0.2, 0.0, 0.0))):
        pipe = _pipe_with(true)
        fam = FAMILIES[true.name]
        fit = fam.fit(pipe, {})
        lo, hi = fam.bounds(pipe, fit)
        assert np.all(np.asarray(fit.theta) >= lo) and np.all(np.asarray(fit.theta) <= hi)
        assert _sse(pipe, {true.name: fit}) < 1e-3 * _sse(pipe, {}), true


def test_frequency_signature_tells_a_load_from_a_delay():
    from hasel.effects.evidence import load_or_delay

    den = paper.plant_tf()[1]
    delay = load_or_delay(_pipe_with(EffectFit("time_delay", "input", (0.012,))), {}, den)
    assert delay["favours"] == "time_delay"
    assert delay["delay"]["delay_s"] == pytest.approx(0.012, rel=0.05)
    assert delay["delay"]["magnitude_rms_db"] < 0.1
    load = load_or_delay(_pipe_with(EffectFit("load_mass", "model", (0.6, 1.0))), {}, den)
    assert load["favours"] == "load_mass"
    assert load["load"]["magnitude_near_resonance_rms_db"] > 1.0
    none = load_or_delay(_pipe_with(EffectFit("time_delay", "input", (0.0,))), {}, den)
    assert none["favours"] == "none"


def test_pile_up_sees_a_clip_and_not_a_curve():
    from hasel.effects.saturation import pile_up

    t = np.arange(20000) * DT
    x = 3.0 + 2.0 * np.sin(2 * np.pi * (1.0 + 4.0 * t) * t)
    clipped = pile_up(np.minimum(x, 4.5))
    curved = pile_up(x + 0.05 * (x - 3.0) ** 2)
    # a sine dwells near its peaks (under 1 % within 1e-4 of the range); the clip holds a quarter there
    assert clipped["upper"] > 0.05 and curved["upper"] < 0.01 and curved["lower"] < 0.01


def test_bend_profile_tells_a_one_sided_flattening_from_a_curve():
    from hasel.effects.sensor import bend_profile

    w = np.linspace(-1, 1, 401)
    soft = 0.1 * np.logaddexp(0.0, (w - 0.7) / 0.1)  # a stroke bending over into a limit near the top
    th_soft = np.polynomial.polynomial.polyfit(w, -soft, 5)
    th_quad = np.polynomial.polynomial.polyfit(w, 0.05 * w ** 2, 5)
    b_soft, b_quad = bend_profile(th_soft), bend_profile(th_quad)
    assert b_soft["one_sided"] and b_soft["upper_quarter_share"] > 0.6
    assert not b_quad["one_sided"]
    assert b_quad["upper_quarter_share"] == pytest.approx(0.25, abs=0.01)
    assert b_quad["lower_quarter_share"] == pytest.approx(0.25, abs=0.01)


def test_map_sides_names_the_side_of_the_dynamics_a_map_acts_on():
    from hasel.effects.static_map import map_sides

    inp = map_sides(_pipe_with(EffectFit("static_nonlinearity", "input", (0.0, 0.0, 0.08))), {})
    out = map_sides(_pipe_with(EffectFit("sensor_nonlinearity", "output", (0.0, 0.0, -0.05, 0.02))), {})
    assert inp["best"] == "input" and inp["separable"] and inp["remaining_share"]["input"] < 1e-3
    assert out["best"] == "sensor" and out["separable"] and out["remaining_share"]["sensor"] < 1e-3


def test_play_support_counts_the_reversals_each_play_needs():
    from hasel.effects.hysteresis import play_support

    t = np.arange(20000) * 1e-3
    u = 3.0 + 1.0 * np.sin(2 * np.pi * 0.5 * t)  # reversals of 2 kV
    s = play_support(u, (0.1, 0.5, 1.5), (0.2, 0.3, 0.5))
    assert s["reversals_over_2r"][0] >= 18 and s["reversals_over_2r"][1] >= 18 and s["reversals_over_2r"][2] == 0
    assert s["unsupported_weight_share"] == pytest.approx(0.5)
    assert s["largest_reversal"] == pytest.approx(2.0, rel=0.06)
