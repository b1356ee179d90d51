"""hasel.calibration: fitting and the YAML round trip."""
from __future__ import annotations

import numpy as np
import pytest

from hasel.calibration import Calibration, fit_calibration
from hasel.errors import BadInputError, DataFileError


def test_fit_recovers_line_and_reports_residuals():
    x = np.array([105.0, 107.5, 110.0, 112.5, 115.0, 117.5])
    y = 0.4 * x - 40.0
    fit = fit_calibration(x, y)
    assert fit.calibration.slope_mm_per_us == pytest.approx(0.4, rel=1e-12)
    assert fit.calibration.offset_mm == pytest.approx(-40.0, rel=1e-12)
    assert np.max(np.abs(fit.residual_mm)) < 1e-9


def test_quadratic_fit_captures_curvature():
    x = np.linspace(100, 120, 6)
    y = 1e-3 * (x - 100) ** 2 + 0.3 * (x - 100)
    lin, quad = fit_calibration(x, y, 1), fit_calibration(x, y, 2)
    assert np.max(np.abs(quad.residual_mm)) < 1e-9 < np.max(np.abs(lin.residual_mm))


def test_yaml_round_trip(tmp_path):
    cal = Calibration.line(0.4, -40.0, "test")
    path = tmp_path / "cal.yaml"
    cal.to_yaml(path)
    back = Calibration.from_yaml(path)
    assert back.coeffs == cal.coeffs
    assert back(110.0) == pytest.approx(4.0)


def test_bad_inputs(tmp_path):
    with pytest.raises(BadInputError, match="distinct points"):
        fit_calibration(np.array([1.0]), np.array([1.0]))
    with pytest.raises(BadInputError, match="degree"):
        fit_calibration(np.arange(5.0), np.arange(5.0), degree=5)
    bad = tmp_path / "bad.yaml"
    bad.write_text("slope: 3\n")
    with pytest.raises(DataFileError, match="coeffs"):
        Calibration.from_yaml(bad)
    with pytest.raises(DataFileError, match="cannot read"):
        Calibration.from_yaml(tmp_path / "missing.yaml")


@pytest.mark.parametrize("coeffs", [(0.4, -40.0), (1e-3, 0.3, -35.0), (-2e-6, 1e-3, 0.3, -35.0)])
def test_one_reading_gives_the_same_number_as_polyval(coeffs):
    # the driver converts one float per tick without numpy: it must agree to the last bit
    cal = Calibration(coeffs, "test")
    for us in (0.0, 99.5, 101.3, 123.456789, float("nan")):
        want = float(np.polyval(coeffs, us))
        got = cal(us)
        assert isinstance(got, float)
        assert got == want or (np.isnan(got) and np.isnan(want))
    np.testing.assert_array_equal(cal(np.array([99.5, 101.3])), np.polyval(coeffs, [99.5, 101.3]))
