"""charge_drift's two-time-constant form: named on a two-depth trapped charge with both time constants back,
not given to an effect-free log, kept from a sensor warm-up (time only) that its start at the first input could
take, and its stage run in chunks equal to one call."""
from __future__ import annotations

import math
from types import SimpleNamespace

import numpy as np
import pytest
from scipy import signal

import os
import sys

from hasel import paper
from hasel.diagnose import diagnose
from hasel.effects.base import EffectFit, run_chunked
from hasel.effects.drift import TWO_TAU, Drift2Stage, _box_on, _history_vs_time, charges2
from hasel.effects.registry import family

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "..", "bench", "tune_diag"))

RATE = 200.0  # Hz
DUR = 60.0  # s
TAU_FAST, TAU_SLOW = 2.0, 15.0  # s, the simulated trap's time constants
#: how far a fitted time constant may be from the truth: a factor of 1.5 either way (the fast and slow
#: charges trade a little of each other's share on 60 s of levels; measured 2.04 and 18.2 s)
TAU_FACTOR = 1.5


def _lag(x: np.ndarray, tau: float) -> np.ndarray:
    """First-order lag (s) at RATE, at rest with ``x[0]``."""
    a = math.exp(-1.0 / (RATE * tau))
    return signal.lfilter([1 - a], [1, -a], x, zi=np.array([a * x[0]]))[0]


def _levels(rng: np.random.Generator, n: int, rate: float) -> np.ndarray:
    """``n`` samples at ``rate`` Hz of random levels 0.5-7.5 kV, each held 0.2-3 s (draws from ``rng``)."""
    u = np.empty(n)
    k = 0
    while k < n:
        m = int(rng.uniform(0.2, 3.0) * rate)
        u[k:k + m] = rng.uniform(0.5, 7.5)
        k += m
    return u


def _log(drift: bool, seed: int = 4) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Random levels 0.5-7.5 kV held 0.2-3 s through P(s) at RATE; with ``drift`` the voltage screened by
    charge trapped at two depths (``v - 0.12 lag(v, 2 s) - 0.10 lag(v, 15 s)``); 5 um white noise."""
    rng = np.random.default_rng(seed)
    n = int(DUR * RATE)
    u = _lag(_levels(rng, n, RATE), 2e-3)
    v = u - 0.12 * _lag(u, TAU_FAST) - 0.10 * _lag(u, TAU_SLOW) if drift else u
    num, den = paper.plant_tf()
    b, a, _ = signal.cont2discrete((num, den), 1.0 / RATE, method="zoh")
    b = np.ravel(b)
    z = signal.lfilter(b, a, v, zi=signal.lfilter_zi(b, a) * v[0])[0]
    y = z + 0.005 * rng.standard_normal(n)
    return np.arange(n) / RATE, u, y


def _diagnose(drift: bool):
    from hasel.diagnose.core import DiagnoseOptions, diagnose
    from hasel.diagnose.pool import set_jobs

    set_jobs(1)
    t, u, y = _log(drift)
    num, den = paper.plant_tf()
    return diagnose(t, u, y, model={"num": list(num), "den": list(den)}, units=("kV", "mm"),
                    options=DiagnoseOptions())


def test_two_depth_trap_is_named_charge_drift_with_both_time_constants():
    v = _diagnose(True)
    assert "charge_drift" in v.names
    p = next(e["params"] for e in v.effects if e["name"] == "charge_drift")
    assert p["variant"] == TWO_TAU
    assert TAU_FAST / TAU_FACTOR <= p["tau_fast_s"] <= TAU_FAST * TAU_FACTOR
    assert TAU_SLOW / TAU_FACTOR <= p["tau_slow_s"] <= TAU_SLOW * TAU_FACTOR
    # the screening lowers the stroke: both charges' offsets negative (mm per input half-range)
    assert p["offset_per_input_half_range_fast"] < 0 and p["offset_per_input_half_range_slow"] < 0
    assert v.heldout["nrmse_augmented"] < 0.2 * v.heldout["nrmse_nominal"]


def test_effect_free_log_is_not_given_the_drift():
    v = _diagnose(False)
    assert "charge_drift" not in v.names


@pytest.mark.parametrize("chunk", [1, 37, 500])
def test_two_tau_stage_in_chunks_equals_one_call(chunk):
    rng = np.random.default_rng(2)
    dt = 1e-3
    u = 3.0 + np.cumsum(rng.standard_normal(6000)) * 0.05
    y = 2.0 + 0.4 * u + 0.01 * rng.standard_normal(u.size)
    scales = SimpleNamespace(u_c=3.0, u_s=2.5, y_c=2.0, y_s=1.5, thresholds=(), tau_smooth_s=None)
    fit = EffectFit("charge_drift", TWO_TAU, (0.8, 6.0, -0.1, 0.05))
    fam = family("charge_drift")
    whole = fam.stage(fit, scales, dt)
    whole.reset(float(y[0]))
    w = whole.run(y, u)
    c = run_chunked(fam.stage(fit, scales, dt), y, chunk, u)
    np.testing.assert_allclose(c, w, rtol=0, atol=1e-12 * float(np.max(np.abs(w))))
    # at rest with the first input: a held input leaves the charges where they started
    qf, qs, _ = charges2(np.full(100, 4.0), dt, 0.8, 6.0)
    np.testing.assert_allclose(qf, 4.0, rtol=1e-12)
    np.testing.assert_allclose(qs, 4.0, rtol=1e-12)
    # the law: y + o_f q_f + o_s q_s with the charges over u_s, offsets in mm
    qf, qs, _ = charges2(u, dt, 0.8, 6.0)
    qf, qs = qf / 2.5, qs / 2.5
    expect = y + 1.5 * (-0.1 * qf + 0.05 * qs)
    np.testing.assert_allclose(w, expect, rtol=1e-12)
    assert isinstance(whole, Drift2Stage)
    assert fam.param_names(fit)[:2] == ("tau_fast_s", "tau_slow_s")


def test_history_beats_time_on_a_trap_not_on_a_warm_up():
    """The form is kept only when the input's history explains the residual better than a time-only warm-up.

    40 s of random levels at 200 Hz after 3 s at -1 kV (the first input far below the mean, as
    free_indep.py seed 11 case 25's pre-conditioning): a 14 s warm-up of 20 um is explained better by time
    (measured SSE ratio 1.05), two trapped charges (2 s and 15 s, 10 um per input half-range each) far better
    by the history (0.12)."""
    rate, dur = 200.0, 40.0
    rng = np.random.default_rng(5)
    n = int(dur * rate)
    t = np.arange(n) / rate
    u = _levels(rng, n, rate)
    u[:int(3 * rate)] = -1.0
    pipe = SimpleNamespace(prep=SimpleNamespace(dt_s=1.0 / rate), u_s=4.0)
    train = np.ones(n, bool)
    train[::3] = False
    box = _box_on(train, int(0.5 * rate))
    noise = 0.005 * rng.standard_normal(n)
    warm = 0.02 * (1.0 - np.exp(-t / 14.0))
    qf, qs, _ = charges2(u, 1.0 / rate, 2.0, 15.0)
    trap = -0.01 * (qf + qs)

    def ratio(r):
        form, rival = _history_vs_time(pipe, [(train, u, None, r[train], box, t[train])], (2.0, 15.0), (1.0, 400.0))
        return form / rival

    assert ratio(warm - warm.mean() + noise) > 1.02
    assert ratio(trap + noise) < 0.2


def test_fast_input_side_trap_is_within_the_two_tau_forms_reach(tmp_path):
    """drifts.py seed 1, case 2: ``v - 0.17 lp(v, 0.77 s)`` before P(s), a 2 kHz multisine, coloured noise. With the
    fast time constant held at 20 dominant time constants (1.06 s) the trap was out of reach and a map took the
    offset it leaves in the slow part only (refused: nothing named at 275 x the floor); at 10 (0.53 s) it is named."""
    import drifts

    case = drifts.make_case(str(tmp_path), 1, 2)
    assert case is not None and case["kind"].startswith("fast1:multisine") and "'t': 0.7727" in case["truth"][0]
    d = np.load(case["path"])
    v = diagnose(d["t_s"], d["voltage_kv"], d["stroke_mm"], model={"num": d["num"].tolist(), "den": d["den"].tolist()},
                 units=("kV", "mm"))
    assert v.names == ["charge_drift"]
    p = v.effects[0]["params"]
    # the fast charge's time constant lies where only the lowered bound reaches (true 0.77 s; fitted 0.60 s)
    assert p["variant"] == TWO_TAU and 0.5 < p["tau_fast_s"] < 1.06
    assert v.heldout["nrmse_nominal"] > 0.9 and v.heldout["nrmse_augmented"] < 0.02
