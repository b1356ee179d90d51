"""``hasel diagnose`` end to end on files: VERDICT.json, --export-sim, --report, bad input."""
from __future__ import annotations

import csv
import json

import numpy as np
import pytest

from hasel import paper
from hasel.cli import main
from hasel.effects import TruthActuator, from_name
from hasel.plant import NominalConfig, amplifier_filter_tf


@pytest.fixture(scope="module")
def files(tmp_path_factory):
    d = tmp_path_factory.mktemp("diag")
    rng = np.random.default_rng(8)
    rate = 2000.0
    t = np.arange(int(16 * rate)) / rate
    u = 3.5 + 2.0 * np.sin(2 * np.pi * 0.25 * t) + 0.7 * np.sin(2 * np.pi * (0.5 + 0.4 * t) * t)
    act = TruthActuator([from_name("time_delay", delay_s=0.015)], NominalConfig(rate_hz=rate))
    act.reset(u[0])
    y = act.run(u).stroke_mm + 0.003 * rng.standard_normal(u.size)
    data = d / "log.csv"
    with open(data, "w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(["t_s", "voltage_kv", "stroke_mm"])
        w.writerows(zip(t, u, y))
    an, ad = amplifier_filter_tf()
    num, den = paper.plant_tf()
    model = d / "model.json"
    model.write_text(json.dumps({"num": list(np.polymul(an, num)), "den": list(np.polymul(ad, den))}))
    return d, data, model


def test_diagnose_writes_verdict_export_and_report(files, capsys):
    d, data, model = files
    verdict, sim, rep = d / "v.json", d / "sim.csv", d / "rep"
    rc = main(["diagnose", str(data), "--model", str(model), "--json", str(verdict), "--export-sim", str(sim),
               "--report", str(rep)])
    assert rc == 0
    v = json.loads(verdict.read_text())
    assert v["effects"][0]["name"] == "time_delay"
    assert v["effects"][0]["params"]["delay_s"] == pytest.approx(0.015, rel=0.1)
    assert v["heldout"]["nrmse_augmented"] < 0.2 * v["heldout"]["nrmse_nominal"]
    assert v["noise_floor_nrmse"] > 0
    with open(sim) as fh:
        rows = list(csv.reader(fh))
    assert rows[0] == ["t_s", "measured", "nominal", "augmented"] and len(rows) == v["heldout"]["n_samples"] + 1
    m = np.array(rows[1:], float)
    e_nom, e_aug = m[:, 1] - m[:, 2], m[:, 1] - m[:, 3]
    assert np.linalg.norm(e_aug) < 0.2 * np.linalg.norm(e_nom)
    for png in ("residual_spectrum.png", "residual_level.png", "residual_time.png", "overlay.png", "nrmse.png"):
        assert (rep / png).stat().st_size > 1000
    assert "time_delay" in (rep / "report.md").read_text()
    assert "time_delay" in capsys.readouterr().out


@pytest.mark.parametrize("argv,msg", [
    (["--model", "MISSING.json"], "no such model file"),
    (["--max-effects", "-1"], "--max-effects must be >= 0"),
    (["--input", "nope"], "nope"),
])
def test_bad_input_is_one_line_and_exit_2(files, capsys, argv, msg):
    d, data, model = files
    argv = [a.replace("MISSING", str(d / "missing")) for a in argv]
    rc = main(["diagnose", str(data)] + argv)
    err = capsys.readouterr().err.strip().splitlines()
    assert rc == 2
    assert err[-1].startswith("hasel diagnose: error:") and msg in err[-1]
    assert not any("Traceback" in line for line in err)
