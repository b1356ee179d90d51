"""The input map's knee form (``static_nonlinearity``, variant ``input:knee``).

A line whose slope changes at one corner (a HASEL whose electrodes zip over a smaller share of the pouch above
some field, or a drive whose gain changes beyond a voltage). Logs are simulated by this file's own code (scipy's
zero-order-hold P(s), no hasel effect class): a raised-cosine log chirp from 0 kV to 7 kV at 500 Hz for 20 s,
white noise of 0.005 mm, the exact P(s) as the nominal model.

- a piecewise-linear knee at 4 kV, the slope beyond it times 0.5 (flattening) or 1.6 (stiffening), is named
  ``static_nonlinearity`` alone in the knee form, its threshold within 0.2 kV and its slope change within 0.1 of
  the truth, the held-out error under 5 % of the nominal's (before the form the polynomial followed the corner
  poorly: ``bench/tune_diag/modes.py`` seed 1 case 15 named a knee an end stop);
- the form's parameters are named and its stage is memoryless (two chunks give the whole run);
- an effect-free log is named nothing, and the input side does not take the knee on it;
- a clip of the drive is named `saturation`: a knee flat beyond its corner is not offered.
"""
from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest

from hasel import paper
from hasel.effects.base import EffectFit, run_chunked
from hasel.effects.registry import family
from hasel.effects.static_map import INPUT_KNEE, knee_moderate

from designs import cosine_chirp, diagnose_noisy, zoh_stroke

RATE = 500.0
DUR = 20.0
NOISE_MM = 0.005
KNEE_KV = 4.0


def _diagnose(u: np.ndarray, z: np.ndarray, seed: int):
    """The diagnosis of this file's log (RATE, NOISE_MM white noise from ``seed``, exact P(s))."""
    return diagnose_noisy(u, z, seed, RATE, NOISE_MM)


@pytest.mark.parametrize("ratio,seed", [(0.5, 1), (1.6, 2)])
def test_a_piecewise_linear_knee_is_named_in_the_knee_form(ratio, seed):
    """Slope 1 up to 4 kV, ``ratio`` beyond: the static map alone, as a knee at 4 kV whose slope changes by
    ``ratio - 1`` (the fitted line's own slope ``1 + a_1`` taken into account)."""
    u = cosine_chirp(RATE, DUR)
    v = np.where(u <= KNEE_KV, u, KNEE_KV + ratio * (u - KNEE_KV))
    verdict = _diagnose(u, zoh_stroke(v, RATE), seed)
    assert verdict.names == ["static_nonlinearity"]
    p = verdict.effects[0]["params"]
    assert p["variant"] == INPUT_KNEE
    assert abs(p["threshold"] - KNEE_KV) < 0.2
    slope_below = 1.0 + p["coefficients"]["z^1"]  # the line's slope: x + s a_1 (x - c)/s
    assert abs((slope_below + p["slope_change"]) / slope_below - ratio) < 0.1
    assert verdict.heldout["nrmse_augmented"] < 0.05 * verdict.heldout["nrmse_nominal"]


def test_the_knee_form_is_named_and_memoryless():
    """Parameter names, and the stage run in two chunks equals the whole run (a map keeps no state)."""
    fam = family("static_nonlinearity")
    fit = EffectFit("static_nonlinearity", INPUT_KNEE, (0.01, -0.05, 4.0, -0.5, 0.05))
    assert fam.param_names(fit) == ("z^0", "z^1", "threshold", "gain", "width")
    num, den = paper.plant_tf()
    sc = SimpleNamespace(u_c=3.5, u_s=3.5, y_c=4.7, y_s=4.7, num=num, den=den)
    st = fam.stage(fit, sc, 1.0 / RATE)
    u = cosine_chirp(RATE, DUR)[:1000]
    st.reset(float(u[0]))
    whole = st.run(u)
    parts = run_chunked(fam.stage(fit, sc, 1.0 / RATE), u, 217)
    assert np.max(np.abs(whole - parts)) < 1e-12
    # beyond the corner the slope is (1 + a_1 + g); below it (1 + a_1)
    assert np.isclose(np.diff(st.run(np.array([5.0, 6.0])))[0], 1.0 - 0.05 - 0.5, atol=1e-3)


def test_no_knee_on_an_effect_free_log():
    """An effect-free chirp: nothing named, and the input side's fit is not the knee."""
    u = cosine_chirp(RATE, DUR)
    verdict = _diagnose(u, zoh_stroke(u, RATE), 3)
    assert verdict.names == []


def test_a_voltage_clip_is_a_saturation_not_a_knee():
    """The drive clipped at 5.5 kV (slope 0 beyond: a knee of slope ratio 0 fits it as well): named
    ``saturation``, not ``static_nonlinearity`` (``combos.py`` seed 21 cases 11 and 12 were taken for knees of
    ratio -0.01 and 0.09 before :func:`knee_moderate`)."""
    u = cosine_chirp(RATE, DUR)
    verdict = _diagnose(u, zoh_stroke(np.minimum(u, 5.5), RATE), 4)
    assert "saturation" in verdict.names and "static_nonlinearity" not in verdict.names
    fit = EffectFit("static_nonlinearity", INPUT_KNEE, (0.0, -0.003, 4.6, -0.904, 0.002))
    assert not knee_moderate(fit)
    assert knee_moderate(EffectFit("static_nonlinearity", INPUT_KNEE, (0.0, 0.06, 4.0, 1.26, 0.2)))


@pytest.mark.xfail(strict=True, reason="known: the timing offset is estimated before any effect; the clip biases it "
                   "(-0.16 samples) and an output lag (asymmetric_dynamics) takes the wrong timing up")
def test_a_voltage_clip_alone_is_named_nothing_else():
    """The same clipped log named ``saturation`` alone (strict: it fails loudly once the timing is re-estimated
    with the clip in place and the spurious lag is gone)."""
    u = cosine_chirp(RATE, DUR)
    assert _diagnose(u, zoh_stroke(np.minimum(u, 5.5), RATE), 4).names == ["saturation"]
