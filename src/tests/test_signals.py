"""Excitation signals and the paper's campaign schedule (hasel.signals)."""
from __future__ import annotations

import numpy as np
import pytest
from scipy import signal

from hasel import paper
from hasel.errors import BadInputError, UnsafeParameterError
from hasel.signals import linear_chirp, odd_multisine, paper_chirp, protocol_schedule, uniform_grid


def _inst_freq_hz(x: np.ndarray, rate_hz: float) -> np.ndarray:
    """Instantaneous frequency from the analytic signal (independent of the chirp formulas)."""
    phase = np.unwrap(np.angle(signal.hilbert(x)))
    return np.gradient(phase) * rate_hz / (2 * np.pi)


def test_paper_chirp_is_the_papers_formula_and_sweeps_to_twice_f_f():
    rate = 2000.0
    t = np.arange(0, 20, 1 / rate)
    v = paper_chirp(t, 0.001, 20.0, 20.0, amplitude=1.0)
    k = (20.0 - 0.001) / 20.0
    np.testing.assert_allclose(v, np.sin(2 * np.pi * (k * t) * t), atol=1e-12)
    fi = _inst_freq_hz(v, rate)
    # instantaneous frequency 2 k t: 10 Hz at 5 s, 30 Hz at 15 s (not 5 and 15 Hz)
    for t_s in (5.0, 15.0):
        i = int(t_s * rate)
        assert np.median(fi[i - 200:i + 200]) == pytest.approx(2 * k * t_s, rel=0.02)


def test_linear_chirp_sweeps_from_f0_to_f1():
    rate = 2000.0
    t = np.arange(0, 20, 1 / rate)
    v = linear_chirp(t, 1.0, 20.0, 20.0, amplitude=2.0)
    assert np.max(np.abs(v)) == pytest.approx(2.0, rel=1e-3)
    fi = _inst_freq_hz(v, rate)
    for t_s in (5.0, 10.0, 15.0):
        i = int(t_s * rate)
        assert np.median(fi[i - 200:i + 200]) == pytest.approx(1.0 + 19.0 * t_s / 20.0, rel=0.02)


def test_odd_multisine_lines_and_detection_lines():
    rng = np.random.default_rng(3)
    ms = odd_multisine(1000.0, 10.0, 0.5, 40.0, amplitude=1.5, group_size=4, rng=rng)
    assert ms.signal.size == 10000
    assert np.max(np.abs(ms.signal)) == pytest.approx(1.5)
    spec = np.abs(np.fft.rfft(ms.signal))
    power_lines = np.flatnonzero(spec > 1e-9 * spec.max())
    np.testing.assert_array_equal(power_lines, ms.excited)
    assert np.all(ms.excited % 2 == 1)
    assert np.all(ms.detection_odd % 2 == 1)
    assert not set(ms.detection_odd) & set(ms.excited)
    odd_in_band = np.arange(5, 401)[np.arange(5, 401) % 2 == 1]
    np.testing.assert_array_equal(np.union1d(ms.excited, ms.detection_odd), odd_in_band)
    # one detection line per group of 4 consecutive odd lines
    assert ms.detection_odd.size == int(np.ceil(odd_in_band.size / 4))
    # equal amplitudes on the excited lines
    np.testing.assert_allclose(spec[ms.excited], spec[ms.excited][0], rtol=1e-9)
    np.testing.assert_allclose(ms.excited_hz, ms.excited / 10.0)


def test_odd_multisine_reveals_even_and_odd_distortion():
    """Power at non-excited lines: even lines for an even nonlinearity, odd detection lines for an odd one."""
    ms = odd_multisine(1000.0, 10.0, 0.5, 40.0, rng=np.random.default_rng(5))
    u = ms.signal
    n = u.size

    def level(y: np.ndarray, lines: np.ndarray) -> float:
        Y = np.abs(np.fft.rfft(y)) / n
        return float(np.sqrt(np.mean(Y[lines] ** 2)))

    even = np.arange(2, 401, 2)
    det = ms.detection_odd
    exc = level(u, ms.excited)
    assert level(u, even) < 1e-12 * exc and level(u, det) < 1e-12 * exc
    square = u + 0.2 * u**2
    assert level(square, even) > 1e-3 * exc and level(square, det) < 1e-12 * exc
    cube = u + 0.2 * u**3
    assert level(cube, det) > 1e-3 * exc and level(cube, even) < 1e-12 * exc


def test_protocol_schedule_matches_table_one():
    sch = protocol_schedule(rate_hz=1000.0, precondition_s=2.0)
    proto = paper.CHIRP_PROTOCOL
    per = 2.0 + proto["repeats"] * proto["duration_s"]
    assert sch.command_kv.size == round(len(proto["offsets_kv"]) * per * 1000.0)
    exc = [r for r in sch.records if r.kind == "excitation"]
    pre = [r for r in sch.records if r.kind == "precondition"]
    assert [r.offset for r in exc] == list(proto["offsets_kv"])
    assert all(r.offset == -1.0 and r.end_s - r.start_s == pytest.approx(2.0) for r in pre)
    assert all(r.excitation == "paper" and r.end_s - r.start_s == pytest.approx(60.0) for r in exc)
    # inside an excitation: offset + the paper's chirp, repeated three times
    r = exc[2]
    i0 = round(r.start_s * 1000.0)
    t = np.arange(20000) / 1000.0
    chirp = paper_chirp(t, proto["f0_hz"], proto["f1_hz"], proto["duration_s"], proto["amplitude_kv"])
    for rep in range(3):
        np.testing.assert_allclose(sch.command_kv[i0 + rep * 20000:i0 + (rep + 1) * 20000], 4.0 + chirp, atol=1e-12)
    assert np.all(sch.command_kv[round(pre[0].start_s * 1000):round(pre[0].end_s * 1000)] == -1.0)
    assert sch.markers()[0] == (2.0, 62.0, 2.0)
    assert np.max(sch.command_kv) <= 8.0 + 1e-12


def test_protocol_schedule_multisine_and_settle():
    sch = protocol_schedule(offsets_kv=[3.0], amplitude_kv=0.5, f0_hz=0.5, f1_hz=20.0, duration_s=4.0, repeats=2,
                            rate_hz=500.0, kind="multisine", precondition_s=0.0, settle_s=1.0,
                            rng=np.random.default_rng(0))
    kinds = [r.kind for r in sch.records]
    assert kinds == ["settle", "excitation"]
    x = sch.command_kv[500:]
    assert np.max(np.abs(x - 3.0)) == pytest.approx(0.5)
    np.testing.assert_allclose(x[:2000], x[2000:], atol=1e-12)  # periodic


def test_protocol_schedule_rejects_unsafe_and_bad_arguments():
    with pytest.raises(UnsafeParameterError, match="9 kV"):
        protocol_schedule(offsets_kv=[8.5], amplitude_kv=1.0, rate_hz=100.0)
    with pytest.raises(BadInputError, match="kind must be one of"):
        protocol_schedule(kind="square", rate_hz=100.0)
    with pytest.raises(BadInputError, match="repeats"):
        protocol_schedule(repeats=0, rate_hz=100.0)
    with pytest.raises(BadInputError, match="duration_s must be > 0"):
        paper_chirp(np.arange(3.0), 0.0, 1.0, 0.0)
    with pytest.raises(BadInputError, match="odd lines"):
        odd_multisine(100.0, 1.0, 10.0, 12.0)


def test_uniform_grid_keeps_uniform_samples_and_interpolates_jittered_ones():
    t = np.arange(100) / 1024  # a binary step: the grid's end is exact
    x = np.sin(2 * np.pi * 5 * t)
    tu, (xu,), step, resampled = uniform_grid(t, x)
    assert not resampled and np.array_equal(tu, t) and np.array_equal(xu, x)
    assert step == 1 / 1024
    # 0.5 % jitter is still uniform; a gap of 3 steps is not
    assert not uniform_grid(t + 0.005 / 1024 * (np.arange(100) % 2), x)[3]
    tg = np.delete(t, [40, 41])
    line = 3.0 * tg - 1.0
    tu, (lu, xu), step, resampled = uniform_grid(tg, line, np.interp(tg, t, x))
    assert resampled and step == 1 / 1024
    np.testing.assert_allclose(tu, t, atol=1e-12)  # the grid of the median step from the first sample
    np.testing.assert_allclose(lu, 3.0 * tu - 1.0, atol=1e-12)  # linear interpolation is exact on a line
    assert xu[40] == pytest.approx(x[39] + (x[42] - x[39]) / 3, abs=1e-12)
