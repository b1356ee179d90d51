"""charge_drift beside an input map: the map fitted first holds the drift's mean in its constant, and the drift
fitted after it must still find the drift (the one-tau weights fitted with a constant, the map refitted given the
drift: ``hasel.effects.drift._fit_drift``, ``hasel.diagnose.core._fit_one``; maps.py seed 41 map_33)."""
from __future__ import annotations

import math

import numpy as np
from scipy import signal

from hasel import paper

RATE = 200.0  # Hz
DUR = 40.0  # s
TAU_Q = 150.0  # s, the screening charge's time constant (longer than the log, as maps.py's drifts)
SHARE = 0.2  # screened share of the field at q = 25 kV^2 (othersim's "screening")


def _stiffen(u: np.ndarray, b: float = 0.5, v_kv: float = 5.2, w_kv: float = 0.3) -> np.ndarray:
    """maps.py's ``stiffen`` command map (kV): ``u - b w softplus((u - v) / w)``."""
    return u - b * w_kv * np.logaddexp(0.0, (u - v_kv) / w_kv)


def _log(drift: bool, seed: int = 3) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A log chirp 0.05-3 Hz of 2 kV about 4.5 kV through the stiffening map and P(s) at RATE; with ``drift`` the
    field screened by ``q``, the leaky integral (TAU_Q) of the squared voltage: ``v (1 - SHARE q / 25 kV^2)``;
    4 um white noise."""
    rng = np.random.default_rng(seed)
    n = int(DUR * RATE)
    t = np.arange(n) / RATE
    u = 4.5 + 2.0 * signal.chirp(t, 0.05, DUR, 3.0, method="logarithmic", phi=-90)
    v = _stiffen(u)
    if drift:
        a = math.exp(-1.0 / (RATE * TAU_Q))
        q = signal.lfilter([1.0 / RATE], [1.0, -a], u ** 2)  # kV^2 s
        q = q / TAU_Q  # kV^2: the low-passed square
        v = v * (1.0 - SHARE * q / 25.0)
    num, den = paper.plant_tf()
    bz, az, _ = signal.cont2discrete((num, den), 1.0 / RATE, method="zoh")
    bz = np.ravel(bz)
    z = signal.lfilter(bz, az, v, zi=signal.lfilter_zi(bz, az) * v[0])[0]
    return t, u, z + 0.004 * rng.standard_normal(n)


def _diagnose(drift: bool):
    from hasel.diagnose.core import DiagnoseOptions, diagnose
    from hasel.diagnose.pool import set_jobs

    set_jobs(1)
    t, u, y = _log(drift)
    num, den = paper.plant_tf()
    lines: list[str] = []
    v = diagnose(t, u, y, model={"num": list(num), "den": list(den)}, units=("kV", "mm"),
                 options=DiagnoseOptions(progress=lines.append))
    return v, lines


def test_drift_beside_a_map_is_named_with_the_map():
    v, _ = _diagnose(True)
    assert "static_nonlinearity" in v.names or "sensor_nonlinearity" in v.names
    assert "charge_drift" in v.names
    p = next(e["params"] for e in v.effects if e["name"] == "charge_drift")
    # screening lowers the stroke as charge builds up
    off = p.get("offset_per_input_half_range", p.get("offset_per_input_half_range_slow"))
    assert off is not None and off < 0


def test_drift_fitted_after_the_map_removes_most_of_what_the_map_leaves():
    """Round 2's candidate ``map + drift``, the drift fitted on top of round 1's map (before any pair alternation):
    every such candidate's validation NRMSE is under half the map's alone. Measured 0.20 of it here (0.87 on main
    39e164c, where the drift, a charge from zero, could not follow the zero-mean residual the map's constant left)."""
    v, _ = _diagnose(True)
    r1, r2 = v.rounds[0], v.rounds[1]
    m = r1["best"]
    assert m in ("static_nonlinearity", "sensor_nonlinearity")
    alone = next(c["nrmse_validation"] for c in r1["candidates"] if c["name"] == m)
    pair = [c["nrmse_validation"] for c in r2["candidates"] if set(c["name"].split(" + ")) == {m, "charge_drift"}]
    assert pair and max(pair) < 0.5 * alone


def test_map_alone_gets_no_drift():
    v, _ = _diagnose(False)
    assert "charge_drift" not in v.names
    assert "static_nonlinearity" in v.names or "sensor_nonlinearity" in v.names
