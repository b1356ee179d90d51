"""``hasel identify`` on CSV logs, through the real CLI entry (hasel.cli.main)."""
from __future__ import annotations

import json
import re

import numpy as np
import pytest

from hasel import paper
from hasel.cli import main
from hasel.plant import NominalActuator, NominalConfig
from hasel.signals import protocol_schedule

pytest.importorskip("hasel.io")  # the loader behind the command

RATE = 1000.0


def _write_csv(path, t, u, y, header="t_s,voltage_kv,stroke_mm"):
    np.savetxt(path, np.c_[t, u, y], delimiter=",", header=header, comments="", fmt="%.9g")


@pytest.fixture(scope="module")
def log_csv(tmp_path_factory):
    """Two operating points of a shortened chirp protocol at 1 kHz, the applied voltage and the stroke."""
    sch = protocol_schedule(offsets_kv=[2.0, 3.0], duration_s=10.0, rate_hz=RATE, precondition_s=2.0)
    act = NominalActuator(NominalConfig(rate_hz=RATE))
    act.reset(0.0)
    out = act.run(sch.command_kv)
    noise = 0.003 * np.random.default_rng(0).standard_normal(out.stroke_mm.size)
    path = tmp_path_factory.mktemp("ident") / "log.csv"
    _write_csv(path, sch.t_s, out.applied_kv, out.stroke_mm + noise)
    return path


def test_identify_writes_model_plot_and_report(log_csv, tmp_path, capsys):
    model, png, rep = tmp_path / "MODEL.json", tmp_path / "bode.png", tmp_path / "rep"
    code = main(["identify", str(log_csv), "--json", str(model), "--plot", str(png), "--report", str(rep)])
    out, err = capsys.readouterr()
    assert code == 0, err
    m = json.loads(model.read_text())
    num, den = paper.plant_tf()
    assert m["static_gain"] == pytest.approx(num[-1] / den[-1], rel=0.02)
    assert m["vs_paper"]["max_db"] < 1.0 and m["vs_paper"]["max_deg"] < 5.0
    assert m["signals"] == {"input": "voltage_kv", "output": "stroke_mm"}
    assert [round(p["mean_input"]) for p in m["operating_points"]] == [2, 3]
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    text = (rep / "report.md").read_text()
    assert "## Static map" in text and "bode.png" in text
    for name in ("bode.png", "coherence.png", "static_map.png", "validation.png"):
        assert (rep / name).stat().st_size > 1000
    assert "model order:" in out and "offset dependence:" in out and "held-out" in out
    assert "hasel identify: transfer-function fit" in err


def test_identify_with_named_columns(log_csv, tmp_path, capsys):
    data = np.loadtxt(log_csv, delimiter=",", skiprows=1)
    other = tmp_path / "other.csv"
    _write_csv(other, data[:, 0], data[:, 1], data[:, 2], header="time,v,z")
    code = main(["identify", str(other), "--time", "time", "--input", "v", "--output", "z", "--order", "4,5",
                 "--json", str(tmp_path / "m.json")])
    assert code == 0, capsys.readouterr().err
    m = json.loads((tmp_path / "m.json").read_text())
    assert m["order"] == {"nz": 4, "np": 5} and m["units"]["input"] == ""


@pytest.mark.parametrize("bad, match", [
    ("nan", "NaN|non-finite|finite"),
    ("constant", "constant"),
    ("column", "stroke_mm"),
])
def test_bad_logs_exit_2_with_one_line(tmp_path, capsys, bad, match):
    t = np.arange(0, 5, 1e-3)
    u = np.sin(2 * np.pi * 2 * t)
    y = 0.5 * u
    header = "t_s,voltage_kv,stroke_mm"
    if bad == "nan":
        u[100] = np.nan
    elif bad == "constant":
        u[:] = 1.0
    else:
        header = "t_s,voltage_kv,position"
    path = tmp_path / "bad.csv"
    _write_csv(path, t, u, y, header=header)
    code = main(["identify", str(path), "--json", str(tmp_path / "m.json")])
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2
    assert err[-1].startswith("hasel identify: error:")
    assert re.search(match, err[-1])
    assert "Traceback" not in "\n".join(err)
    assert not (tmp_path / "m.json").exists()
