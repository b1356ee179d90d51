"""The ``charge_drift`` family's swing-driven form (``output:travel``): a gain lost with each swing of the voltage
(charge injected per cycle), recovering at rest, told apart from a drift held by the voltage's level.

The logs are the exact P(s) (zero-order hold at 500 Hz) on a 60 s linear chirp of 3.5 +- 2.5 kV from 0.1 to 6 Hz
(its swing per second grows sixty-fold), the drift written here with scipy's lfilter, not with the library's
kernels. Before this form the swing-driven case was named nothing (forms3.py seed 1, ``cycling``: nominal NRMSE 0.91
at 350x the floor)."""
from __future__ import annotations

import math

import designs
import numpy as np
import pytest
from scipy import signal

from hasel.effects.base import EffectFit
from hasel.effects.drift import TravelStage, travel_charge
from hasel.effects.registry import FAMILIES

RATE_HZ = 500.0
DUR_S = 60.0


@pytest.fixture(scope="module")
def chirp():
    t = np.arange(int(DUR_S * RATE_HZ)) / RATE_HZ
    u = 3.5 + 2.5 * np.sin(2 * np.pi * (0.1 * t + 0.5 * (6.0 - 0.1) / DUR_S * t ** 2))
    return t, u, designs.zoh_stroke(u, RATE_HZ)


def _leaky(x: np.ndarray, tau_s: float) -> np.ndarray:
    a = math.exp(-1.0 / (RATE_HZ * tau_s))
    return signal.lfilter([1.0], [1.0, -a], x)


def test_the_swing_is_the_leaky_sum_of_the_input_steps_and_runs_in_chunks():
    """``travel_charge`` of a ramp is its steps summed with the leak (exactly, against a loop), and the stage run
    in 7 chunks gives the whole run's output to 1e-12."""
    x = np.concatenate([np.linspace(0, 3, 50), np.full(30, 3.0), np.linspace(3, 1, 40)])
    q, _ = travel_charge(x, 1e-3, 0.02)
    a, ref, acc = math.exp(-1e-3 / 0.02), [], 0.0
    for k in range(x.size):
        acc = a * acc + abs(x[k] - x[k - 1] if k else 0.0)
        ref.append(acc)
    np.testing.assert_allclose(q, ref, rtol=0, atol=1e-12)
    y = 2.0 + np.sin(np.arange(x.size) / 5.0)
    whole = TravelStage(1e-3, 0.02, 2.5, -0.03, 0.01)
    whole.reset(0.0)
    parts = TravelStage(1e-3, 0.02, 2.5, -0.03, 0.01)
    parts.reset(0.0)
    out = np.concatenate([parts.run(y[i:i + 17], x[i:i + 17]) for i in range(0, x.size, 17)])
    np.testing.assert_allclose(out, whole.run(y, x), rtol=0, atol=1e-12)
    fam = FAMILIES["charge_drift"]
    fit = EffectFit("charge_drift", "output:travel", (100.0, -1e-4, 0.0))
    assert fam.param_names(fit) == ("tau_s", "gain_per_swing", "offset_per_swing")


def test_a_gain_lost_with_each_swing_is_named_a_charge_drift_of_the_swing(chirp):
    """``z (1 - c q)``, ``q`` the swing over the last 100 s (12 % lost at the end): named ``charge_drift`` of the
    ``output:travel`` form, its time constant within a factor of 2, its gain change negative."""
    t, u, z = chirp
    q = _leaky(np.abs(np.diff(u, prepend=u[0])), 100.0)
    v = designs.diagnose_noisy(u, z * (1.0 - 0.12 * q / q.max()), 5, RATE_HZ)
    assert "charge_drift" in v.names
    p = next(e for e in v.effects if e["name"] == "charge_drift")["params"]
    assert p["variant"] == "output:travel"
    assert 50.0 <= p["tau_s"] <= 200.0
    assert p["gain_change_per_input_half_range_of_swing"] < 0


def test_a_drift_held_by_the_level_stays_the_level_form(chirp):
    """``z (1 - 0.03 lp(u))`` (a 30 s low-pass of the voltage, about 10 % lost): the level's ``output`` form, not
    the swing's."""
    t, u, z = chirp
    a = math.exp(-1.0 / (RATE_HZ * 30.0))
    lp = signal.lfilter([1.0 - a], [1.0, -a], u)
    v = designs.diagnose_noisy(u, z * (1.0 - 0.03 * lp), 5, RATE_HZ)
    assert "charge_drift" in v.names
    assert next(e for e in v.effects if e["name"] == "charge_drift")["params"]["variant"] == "output"


def test_the_swing_replaces_the_level_only_where_the_held_out_blocks_say_so(chirp):
    """The guard of the swing form (:func:`hasel.effects.drift._held_out_prefers`): outside a diagnosis (no
    ``t_min`` on the pipeline) it lets the training error decide; with the diagnosis's ``t_min`` a change that does
    not improve the validation blocks is refused and the swing drift's own validation gain is accepted (the
    diagnosis's context puts ``DiagnoseOptions.t_min`` there)."""
    from hasel import paper
    from hasel.diagnose.augment import Pipeline
    from hasel.diagnose.options import DiagnoseOptions
    from hasel.diagnose.prep import prepare
    from hasel.effects.drift import _held_out_prefers

    t, u, z = chirp
    q = _leaky(np.abs(np.diff(u, prepend=u[0])), 100.0)
    num, den = paper.plant_tf()
    pipe = Pipeline(prepare(t, u, z * (1.0 - 0.12 * q / q.max()), model_den=den), num, den)
    assert pipe.t_min is None
    swing = FAMILIES["charge_drift"].fit(pipe, {})
    assert swing is not None and swing.variant == "output:travel"  # no guard outside a diagnosis
    nothing, with_swing = {}, {"charge_drift": swing}
    assert _held_out_prefers(pipe, nothing, nothing)
    pipe.t_min = DiagnoseOptions().t_min
    assert not _held_out_prefers(pipe, nothing, nothing)  # no change: a block score of 0
    assert _held_out_prefers(pipe, nothing, with_swing)
    assert not _held_out_prefers(pipe, with_swing, nothing)
