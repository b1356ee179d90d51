"""Bad logs for identify and diagnose: one line and exit 2, or a repair that is said (issue 14, "Bad input")."""
from __future__ import annotations

import numpy as np
import pytest

from hasel.cli import main
from hasel.errors import DataFileError
from hasel.io import load_io
from hasel.io.dataset import MAX_FILL_SAMPLES

RATE = 1000.0


def _write(path, t, u, y):
    np.savetxt(path, np.column_stack([t, u, y]), delimiter=",", header="t_s,voltage_kv,stroke_mm", comments="",
               fmt="%.9g")
    return path


def _log(seconds: float = 20.0):
    t = np.arange(int(seconds * RATE)) / RATE
    u = 4.0 + 1.5 * np.sin(2 * np.pi * (0.2 + 0.4 * t) * t)
    y = 1.35 * (u - 4.0) + 5.4 + 0.01 * np.random.default_rng(1).standard_normal(t.size)
    return t, u, y


def test_a_long_gap_is_refused_naming_where_it_is(tmp_path):
    t, u, y = _log()
    keep = np.ones(t.size, bool)
    keep[5000:5000 + MAX_FILL_SAMPLES + 1] = False  # one sample more than is filled
    path = _write(tmp_path / "gap.csv", t[keep], u[keep], y[keep])
    with pytest.raises(DataFileError, match=r"the longest 0.007 s \(6 samples of 0.001 s missing\) after t = 4.999 s"):
        load_io(path)


def test_short_gaps_are_filled_and_said(tmp_path):
    t, u, y = _log()
    keep = np.ones(t.size, bool)
    keep[[100, 2000, 2001]] = False
    data = load_io(_write(tmp_path / "short_gaps.csv", t[keep], u[keep], y[keep]))
    assert data.n == t.size - 3  # the loader keeps the samples; the analyses fill the grid
    assert any("2 short gap(s)" in n and "3 in all" in n and "linear interpolation" in n for n in data.notes)
    # jitter is no gap
    jittered = load_io(_write(tmp_path / "jitter.csv", t + 1e-5 * (np.arange(t.size) % 2), u, y))
    assert not any("gap" in n for n in jittered.notes)


@pytest.mark.parametrize("command", ["identify", "diagnose"])
def test_gap_and_constant_input_are_one_line_and_exit_2(tmp_path, capsys, command):
    t, u, y = _log()
    cases = {"gap": (np.delete(t, np.s_[3000:4000]), np.delete(u, np.s_[3000:4000]), np.delete(y, np.s_[3000:4000])),
             "constant": (t, np.full(t.size, 4.0), y)}
    words = {"gap": "split the log at the gap", "constant": "is constant (4)"}
    for name, (tt, uu, yy) in cases.items():
        capsys.readouterr()
        assert main([command, str(_write(tmp_path / f"{name}.csv", tt, uu, yy))]) == 2
        err = capsys.readouterr().err.strip().splitlines()
        assert err[-1].startswith(f"hasel {command}: error:") and words[name] in err[-1], err
        assert not any("Traceback" in line or "Warning" in line for line in err), err


def test_identify_on_a_log_too_short_for_a_static_map_says_so(tmp_path, capsys):
    t, u, y = _log(0.3)
    assert main(["identify", str(_write(tmp_path / "short.csv", t, u, y))]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert "too short for a static map (0.299 s)" in err[-1], err
    # 5 s of a sine that never holds still: longer than one 2 s window, short of the three the map needs
    t = np.arange(int(5.0 * RATE)) / RATE
    u = 4.0 + np.sin(10.0 * t)
    y = 1.35 * (u - 4.0) + 5.4
    assert main(["identify", str(_write(tmp_path / "five.csv", t, u, y))]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert "too short for a static map (5 s)" in err[-1] and "6 s of samples" in err[-1], err
