"""A given model in the wrong units or with the wrong sign is refused before any effect is fitted.

Without the check, a model 1000x too large (m taken for mm) was "explained" by a sensor curve and a
load at exit 0: a units error named as physics."""
from __future__ import annotations

import json
import subprocess
import sys

import numpy as np
import pytest

from hasel import paper
from hasel.diagnose import diagnose
from hasel.diagnose.core import DiagnosisFailed
from hasel.diagnose.nominal import MAX_FACTOR, gain_check
from hasel.diagnose.prep import LinearSim


def _log(rate: float = 200.0, seconds: float = 30.0, seed: int = 1):
    """Random voltage levels 1-6 kV through the paper's P(s), 0.005 mm noise."""
    rng = np.random.default_rng(seed)
    n = int(rate * seconds)
    t = np.arange(n) / rate
    u = np.repeat(rng.uniform(1.0, 6.0, n // 40 + 1), 40)[:n]
    num, den = paper.plant_tf()
    y = LinearSim(num, den, rate).run(u) + 0.005 * rng.standard_normal(n)
    return t, u, y, [float(c) for c in num], [float(c) for c in den]


def test_gain_check_reads_the_scale_and_refuses_units_and_sign():
    rng = np.random.default_rng(0)
    h = rng.standard_normal(500)
    mask = np.ones(500, bool)
    g = gain_check(2.0 * h + 3.0, h, mask)
    assert g["ok"] and g["scale"] == pytest.approx(2.0) and g["offset"] == pytest.approx(3.0)
    assert not gain_check(-h, h, mask)["ok"]
    assert "sign" in gain_check(-h, h, mask)["reason"]
    low = gain_check(h / (1.01 * MAX_FACTOR), h, mask)
    assert not low["ok"] and "units" in low["reason"]
    assert gain_check(h / (0.99 * MAX_FACTOR), h, mask)["ok"]
    # a constant simulation has no scale to compare: not refused on that ground
    assert gain_check(h, np.zeros(500), mask)["ok"]


@pytest.mark.parametrize("factor", [1000.0, -1.0, 0.001])
def test_a_model_in_wrong_units_or_sign_fails_with_exit_1(factor):
    t, u, y, num, den = _log()
    with pytest.raises(DiagnosisFailed) as err:
        diagnose(t, u, y, model={"num": [factor * c for c in num], "den": den})
    p = err.value.payload
    assert p["usable"] is False and p["effects"] == []
    assert p["nominal_scale"] == pytest.approx(1.0 / factor, rel=0.05)


def test_the_right_model_passes_the_gain_check_and_the_cli_says_why_otherwise(tmp_path):
    t, u, y, num, den = _log(seconds=20.0)
    v = diagnose(t, u, y, model={"num": num, "den": den})
    assert v.names == []
    data = tmp_path / "log.csv"
    data.write_text("t_s,voltage_kv,stroke_mm\n" + "\n".join(f"{a},{b},{c}" for a, b, c in zip(t, u, y)) + "\n")
    model = tmp_path / "model.json"
    model.write_text(json.dumps({"num": [1000.0 * c for c in num], "den": den}))
    out = tmp_path / "v.json"
    p = subprocess.run([sys.executable, "-m", "hasel.cli", "diagnose", str(data), "--model", str(model),
                        "--json", str(out)], capture_output=True, text=True)
    assert p.returncode == 1, p.stderr
    last = p.stderr.strip().splitlines()[-1]
    assert last.startswith("hasel diagnose: failed:") and "units" in last
    assert json.loads(out.read_text())["usable"] is False
