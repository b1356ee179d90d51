"""The ``static_nonlinearity`` variant acting on the hysteresis output (between the hysteresis and the dynamics):
its place in the diagnosis's pipeline and in a fitted plant's chunked chain, and its fit."""
from __future__ import annotations

import json

import numpy as np
import pytest
from scipy import signal

from hasel import paper
from hasel.diagnose.augment import Pipeline, _sse
from hasel.diagnose.prep import prepare
from hasel.effects.base import SLOT_ORDER, EffectFit
from hasel.effects.static_map import (AFTER_HYST, AFTER_HYST_KNEE, fit_after_hysteresis, fit_variant, input_map,
                                      knee_map, linear_static)
from hasel.plantchain import FileActuator
from hasel.plantfile import parse_plant

NUM, DEN = (list(map(float, c)) for c in paper.plant_tf())
HYST = EffectFit("hysteresis", "input", (0.1, 0.25, 0.0, 0.3, 0.05, -0.5))
#: a strongly curved map (normalised coefficients; ``x + u_s (a_1 z + a_2 z^2)``)
MAP = (0.0, 0.1, 0.15)
SCALES = {"u_c": 3.0, "u_s": 2.5, "y_c": 4.0, "y_s": 3.0, "thresholds": [0.05, 0.15, 0.35, 0.75, 1.5],
          "tau_smooth_s": 0.5}


def _plant(variant: str) -> dict:
    """A fitted plant file: hysteresis and a map before it (``input``) or after it (:data:`AFTER_HYST`)."""
    hyst = {"name": "hysteresis", "form": "fitted", "variant": "input",
            "params": {"w_1": 0.1, "w_2": 0.25, "w_3": 0.0, "w_4": 0.3, "w_5": 0.05, "branch": -0.5}}
    smap = {"name": "static_nonlinearity", "form": "fitted", "variant": variant,
            "params": {f"z^{j}": v for j, v in enumerate(MAP)}}
    eff = [smap, hyst] if variant == "input" else [hyst, smap]
    return {"format": "hasel-plant", "version": 1, "num": NUM, "den": DEN, "units": {"input": "kV", "output": "mm"},
            "effects": eff, "scales": SCALES}


def _command(n: int = 20000) -> np.ndarray:
    """Steps with a chirp on top, kV, at 10 kHz (reversals for the hysteresis, levels for the map)."""
    t = np.arange(n) * 1e-4
    return np.clip(3.0 + 2.0 * np.sign(np.sin(2 * np.pi * 1.5 * t)) + 0.8 * np.sin(2 * np.pi * (1 + 5 * t) * t), 0, 9)


def test_slot_lies_between_the_hysteresis_and_the_dynamics():
    f = EffectFit("static_nonlinearity", AFTER_HYST, MAP)
    assert SLOT_ORDER["hysteresis"] < f.slot < SLOT_ORDER["load_mass"]
    assert f.slot == 3.5 and EffectFit("static_nonlinearity", "input", MAP).slot == 2


def test_fitted_chain_with_the_map_after_the_hysteresis_in_5ms_blocks_equals_one_call():
    u = _command()
    a, b = FileActuator(parse_plant(_plant(AFTER_HYST))), FileActuator(parse_plant(_plant(AFTER_HYST)))
    whole = a.run(u).stroke_mm
    blocks = np.concatenate([b.run(u[i:i + 50]).stroke_mm for i in range(0, u.size, 50)])
    np.testing.assert_allclose(blocks, whole, rtol=0, atol=1e-12)
    # the same map before the hysteresis is another chain: the plays see the bent voltage, not the straight one
    before = FileActuator(parse_plant(_plant("input"))).run(u).stroke_mm
    gap = float(np.max(np.abs(whole - before)))
    assert gap > 0.1, gap  # mm: 0.13 mm here (on a 7.9 mm range), far above the 1e-12 mm of the chunking check
    # and without the map the stroke differs by the map's bend (0.76 mm of a 7.9 mm range here)
    no_map = _plant(AFTER_HYST)
    no_map["effects"] = no_map["effects"][:1]
    plain = FileActuator(parse_plant(no_map)).run(u).stroke_mm
    assert float(np.max(np.abs(whole - plain))) > 0.05 * float(np.ptp(whole))


def test_plant_file_keeps_the_chain_order_with_the_map_after_the_hysteresis():
    obj = _plant(AFTER_HYST)
    assert [e.name for e in parse_plant(obj).effects] == ["hysteresis", "static_nonlinearity"]
    wrong = json.loads(json.dumps(obj))
    wrong["effects"] = wrong["effects"][::-1]
    with pytest.raises(Exception, match="chain order"):
        parse_plant(wrong)


def _log_pipe(effects: dict[str, EffectFit]) -> Pipeline:
    """A pipeline on a noiseless log made by the pipeline's own chain with ``effects``."""
    num, den = paper.plant_tf()
    rate = 500.0
    tb = np.arange(int(4.0 * rate)) / rate
    u = np.concatenate([np.full(250, 0.5), np.full(500, 2.0), np.full(500, 5.0), np.full(500, 3.0),
                        3.5 + 2.5 * np.sin(2 * np.pi * (0.5 + 1.0 * tb) * tb), np.full(500, 2.0),
                        3.0 + 2.0 * np.sin(2 * np.pi * 0.7 * tb), np.full(250, 0.5)])
    t = np.arange(u.size) / rate
    probe = Pipeline(prepare(t, u, signal.lsim((num, den), u, t)[1], model_den=den), num, den)
    y = probe.stages(effects, 0)["y"]
    rec = probe.prep.records[0]
    return Pipeline(prepare(rec.t_s, rec.u, y, model_den=den), num, den)


def test_pipeline_applies_the_map_to_the_hysteresis_output_and_the_fit_recovers_it():
    true = EffectFit("static_nonlinearity", AFTER_HYST, MAP)
    pipe = _log_pipe({"hysteresis": HYST, "static_nonlinearity": true})
    st = pipe.stages({"hysteresis": HYST, "static_nonlinearity": true}, 0)
    np.testing.assert_allclose(st["x_eff"], input_map(MAP, st["x_hyst"], pipe.u_c, pipe.u_s), rtol=0, atol=1e-12)
    assert not np.allclose(st["x_hyst"], st["x_map"])  # the hysteresis acts before the map
    # offered only beside a hysteresis
    assert fit_after_hysteresis(pipe, {}) is None
    fit = fit_after_hysteresis(pipe, {"hysteresis": HYST})
    assert fit is not None and fit.variant == AFTER_HYST
    s0 = _sse(pipe, {"hysteresis": HYST})
    s_after = _sse(pipe, {"hysteresis": HYST, "static_nonlinearity": fit})
    assert s_after < 1e-6 * s0, (s_after, s0)
    np.testing.assert_allclose(fit.theta[:3], MAP, atol=1e-4)
    # the map before the hysteresis, fitted (and refined) beside the same hysteresis, cannot reproduce the log
    before = fit_variant(pipe, {"hysteresis": HYST}, "input")
    s_before = _sse(pipe, {"hysteresis": HYST, "static_nonlinearity": before})
    assert s_before > 100.0 * s_after, (s_before, s_after)


#: a knee after the hysteresis (as the tuning simulator draws them: a line whose slope drops by 40 % above
#: 4 kV; ``x + u_s (a_0 + a_1 z) + dead_map((d, g, w), x)``, a nearly hard corner of 0.02 kV)
KNEE = (0.02, 0.05, 4.0, -0.4, 0.02)


def test_knee_after_the_hysteresis_is_chosen_over_the_polynomial_and_recovered():
    true = EffectFit("static_nonlinearity", AFTER_HYST_KNEE, KNEE)
    pipe = _log_pipe({"hysteresis": HYST, "static_nonlinearity": true})
    st = pipe.stages({"hysteresis": HYST, "static_nonlinearity": true}, 0)
    np.testing.assert_allclose(st["x_eff"], knee_map(KNEE, st["x_hyst"], pipe.u_c, pipe.u_s), rtol=0, atol=1e-12)
    s0 = _sse(pipe, {"hysteresis": HYST})
    poly = fit_after_hysteresis(pipe, {"hysteresis": HYST}, AFTER_HYST)
    s_poly = _sse(pipe, {"hysteresis": HYST, "static_nonlinearity": poly})
    fit = fit_after_hysteresis(pipe, {"hysteresis": HYST})  # both forms, the lower validation error kept
    assert fit is not None and fit.variant == AFTER_HYST_KNEE
    s_knee = _sse(pipe, {"hysteresis": HYST, "static_nonlinearity": fit})
    # sums of squares (mm^2): none 86.4, the degree-5 polynomial 0.68, the knee 3e-12 (noiseless log)
    assert s_poly < 0.01 * s0 and s_knee < 1e-6 * s_poly, (s_knee, s_poly, s0)
    np.testing.assert_allclose(fit.theta, KNEE, atol=1e-4)  # threshold to 0.1 V, the corner's width too
    # not a gain and an offset
    assert not linear_static(pipe, {"hysteresis": HYST, "static_nonlinearity": fit})


def test_fitted_chain_with_the_knee_after_the_hysteresis_in_5ms_blocks_equals_one_call():
    obj = _plant(AFTER_HYST)
    obj["effects"][1] = {"name": "static_nonlinearity", "form": "fitted", "variant": AFTER_HYST_KNEE,
                         "params": dict(zip(("z^0", "z^1", "threshold", "gain", "width"), KNEE))}
    u = _command()
    whole = FileActuator(parse_plant(obj)).run(u).stroke_mm
    b = FileActuator(parse_plant(obj))
    blocks = np.concatenate([b.run(u[i:i + 50]).stroke_mm for i in range(0, u.size, 50)])
    np.testing.assert_allclose(blocks, whole, rtol=0, atol=1e-12)
    poly = FileActuator(parse_plant(_plant(AFTER_HYST))).run(u).stroke_mm
    assert float(np.max(np.abs(whole - poly))) > 0.05, "the knee is another map than the polynomial"
