"""load_io on CSV and MATLAB files: the shared real datasets, their quirks, and every bad-input path."""
from __future__ import annotations

import csv
import json
import subprocess
import sys
from pathlib import Path

from realdata import datasets_dir

import numpy as np
import pytest
import scipy.io

from hasel.errors import BadInputError, DataFileError
from hasel.io import load_io

DATA = datasets_dir()


@pytest.fixture
def rng():
    return np.random.default_rng(2)


def _csv(path: Path, header, rows, delimiter=","):
    with open(path, "w", newline="") as f:
        w = csv.writer(f, delimiter=delimiter)
        if header:
            w.writerow(header)
        w.writerows(rows)
    return path


def test_project_csv_defaults(tmp_path, rng):
    t = np.arange(50) * 1e-3
    u = rng.normal(size=50)
    y = 0.3 * u
    p = _csv(tmp_path / "a.csv", ["t_s", "voltage_kv", "stroke_mm"], zip(t, u, y))
    d = load_io(p)
    np.testing.assert_array_equal(d.t_s, t)
    np.testing.assert_array_equal(d.u, u)
    np.testing.assert_array_equal(d.y, y)
    assert (d.input_name, d.output_name, d.segments, d.notes) == ("voltage_kv", "stroke_mm", [], ())
    assert d.sample_rate_hz == pytest.approx(1000)
    by_index = load_io(p, time="0", input="2", output="1")
    np.testing.assert_array_equal(by_index.u, y)
    case = load_io(p, time="T_S", input="VOLTAGE_KV", output="Stroke_mm")
    np.testing.assert_array_equal(case.y, y)


@pytest.mark.parametrize("delimiter", ["\t", ";"])
def test_other_delimiters(tmp_path, rng, delimiter):
    u = rng.normal(size=20)
    p = _csv(tmp_path / "d.csv", ["t_s", "voltage_kv", "stroke_mm"], zip(np.arange(20.0), u, 2 * u), delimiter)
    np.testing.assert_array_equal(load_io(p).y, 2 * u)


def test_whitespace_separated_without_header(tmp_path, rng):
    u = rng.normal(size=15)
    p = tmp_path / "w.txt"
    p.write_text("".join(f"{i * 0.5}  {float(a)!r}   {float(2 * a)!r}\n" for i, a in enumerate(u)))
    d = load_io(p, time="0", input="1", output="2")
    np.testing.assert_array_equal(d.u, u)
    np.testing.assert_array_equal(d.t_s, np.arange(15) * 0.5)


def test_bad_csv_inputs(tmp_path, rng):
    rows = [[i * 0.1, float(v), float(2 * v)] for i, v in enumerate(rng.normal(size=30))]
    p = _csv(tmp_path / "a.csv", ["t_s", "voltage_kv", "stroke_mm"], rows)
    with pytest.raises(BadInputError, match=r"no input column 'volts'; columns: t_s, voltage_kv, stroke_mm"):
        load_io(p, input="volts")
    with pytest.raises(BadInputError, match=r"no time column 'time'"):
        load_io(p, time="time")
    nan_rows = [r[:] for r in rows]
    nan_rows[4][2] = float("nan")
    with pytest.raises(DataFileError, match=r"stroke_mm has 1 NaN/inf values, the first at sample 4 \(line 6\)"):
        load_io(_csv(tmp_path / "n.csv", ["t_s", "voltage_kv", "stroke_mm"], nan_rows))
    back = [r[:] for r in rows]
    back[7][0] = back[5][0]
    with pytest.raises(DataFileError, match=r"not strictly increasing at sample 7 \(line 9\)"):
        load_io(_csv(tmp_path / "b.csv", ["t_s", "voltage_kv", "stroke_mm"], back))
    with pytest.raises(DataFileError, match="only 5 samples; at least 10"):
        load_io(_csv(tmp_path / "s.csv", ["t_s", "voltage_kv", "stroke_mm"], rows[:5]))
    text = [r[:] for r in rows]
    text[12][1] = "abc"
    with pytest.raises(DataFileError, match=r"line 14, column 'voltage_kv': 'abc' is not a number"):
        load_io(_csv(tmp_path / "t.csv", ["t_s", "voltage_kv", "stroke_mm"], text))
    empty = [r[:] for r in rows]
    empty[2][2] = ""
    with pytest.raises(DataFileError, match=r"line 4, column 'stroke_mm': an empty cell"):
        load_io(_csv(tmp_path / "e.csv", ["t_s", "voltage_kv", "stroke_mm"], empty))
    (tmp_path / "z.csv").write_text("")
    with pytest.raises(DataFileError, match="empty file"):
        load_io(tmp_path / "z.csv")
    (tmp_path / "x.xlsx").write_bytes(b"PK")
    with pytest.raises(BadInputError, match="unsupported file type .xlsx"):
        load_io(tmp_path / "x.xlsx")
    with pytest.raises(BadInputError, match="rate or period must be > 0"):
        load_io(p, time="fs=-3")
    with pytest.raises(BadInputError, match="expected fs=RATE_HZ or dt=PERIOD_S"):
        load_io(p, time="dt=abc")


def test_shared_cascaded_tanks_uses_its_sample_period_column():
    d = load_io(DATA / "CTS_dataBenchmark.csv", input="uEst", output="yEst")
    assert d.n == 1024 and d.t_s[1] == 4.0 and "Ts = 4" in d.notes[0]
    raw = np.genfromtxt(DATA / "CTS_dataBenchmark.csv", delimiter=",", skip_header=1)
    np.testing.assert_array_equal(d.u, raw[:, 0])
    np.testing.assert_array_equal(d.y, raw[:, 2])
    assert (d.y >= 10.0 - 1e-9).sum() == 47  # the README's clipped samples of the estimation data
    with pytest.raises(BadInputError, match=r"no input column 'voltage_kv'; columns: uEst, uVal, yEst, yVal, Ts"):
        load_io(DATA / "CTS_dataBenchmark.csv")


def test_shared_headerless_files_by_index():
    piezo = load_io(DATA / "piezo_hysteresis_v_150_1hz.csv", time="1", input="3", output="2")
    assert piezo.n == 50001 and piezo.sample_rate_hz == pytest.approx(5000, rel=1e-3)
    assert piezo.u.max() == pytest.approx(150, rel=0.01)
    with pytest.raises(BadInputError, match=r"no header row; columns are numbered 0\.\.3"):
        load_io(DATA / "piezo_hysteresis_v_150_1hz.csv", input="voltage")
    silver = load_io(DATA / "SNLS80mV.csv", time="fs=610.35", input="0", output="1")
    assert silver.n == 131072
    assert silver.t_s[-1] == pytest.approx(131071 / 610.35)
    with pytest.raises(BadInputError, match=r"no time column 't_s'.*fs=RATE_HZ"):
        load_io(DATA / "SNLS80mV.csv", input="0", output="1")


def test_shared_matlab_files():
    d = load_io(DATA / "rtl_dc_step_5_15_00.mat", time="Zeit", input="Motorspannung", output="Geschwindigkeit")
    raw = scipy.io.loadmat(DATA / "rtl_dc_step_5_15_00.mat")
    np.testing.assert_array_equal(d.y, raw["Geschwindigkeit"].ravel())
    assert d.n == 1221 and d.sample_rate_hz == pytest.approx(100)
    with pytest.raises(BadInputError, match=r"no variable 'voltage_kv'; variables: .*Motorspannung"):
        load_io(DATA / "rtl_dc_step_5_15_05.mat")


def test_matlab_round_trip_and_bad_files(tmp_path, rng):
    u = rng.normal(size=(40, 1))
    scipy.io.savemat(tmp_path / "m.mat", {"t": np.arange(40.0)[:, None] / 50, "u": u, "y": 3 * u, "name": "x"})
    d = load_io(tmp_path / "m.mat", time="t", input="u", output="y")
    np.testing.assert_array_equal(d.y, 3 * u.ravel())
    (tmp_path / "h.mat").write_bytes(b"\x89HDF\r\n\x1a\n" + b"\x00" * 600)
    with pytest.raises(DataFileError, match=r"h\.mat"):
        load_io(tmp_path / "h.mat", time="t", input="u", output="y")


def test_binary_garbage_is_a_data_file_error(tmp_path):
    from hasel.errors import DataFileError
    from hasel.io import load_io

    p = tmp_path / "garbage.csv"
    p.write_bytes(b"t_s,voltage_kv,stroke_mm\n0,1,2\n\xff\xfe\x00\x81,2,3\n")
    with pytest.raises(DataFileError, match="UTF-8"):
        load_io(p)


def test_identify_reads_a_mat_log_as_it_reads_csv(tmp_path):
    """``hasel identify`` takes a MATLAB log (its help says so): random levels through P(s), 200 Hz."""
    from hasel import paper
    from hasel.diagnose.prep import LinearSim

    num, den = paper.plant_tf()
    fs = 200.0
    t = np.arange(6000) / fs
    u = np.repeat(np.random.default_rng(0).uniform(1.0, 6.0, 200), 30)
    y = LinearSim(num, den, fs).run(u) + 0.005 * np.random.default_rng(1).standard_normal(t.size)
    scipy.io.savemat(tmp_path / "log.mat", {"t_s": t, "voltage_kv": u, "stroke_mm": y})
    out = tmp_path / "model.json"
    p = subprocess.run([sys.executable, "-m", "hasel.cli", "identify", str(tmp_path / "log.mat"), "--json", str(out)],
                       capture_output=True, text=True, timeout=600)
    assert p.returncode == 0, p.stderr
    m = json.loads(out.read_text())
    g0 = np.polyval(m["num"], 0.0) / np.polyval(m["den"], 0.0)
    assert m["usable"] is True and g0 == pytest.approx(float(np.polyval(num, 0.0) / np.polyval(den, 0.0)), rel=0.03)
