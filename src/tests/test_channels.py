"""hasel.channels: the driver's and filter's decisions (555 reading -> mm, the NaN rules)."""
from __future__ import annotations

import math

import numpy as np
import pytest

from hasel.calibration import Calibration
from hasel.channels import FilterChannel, StrainChannel, default_calibration
from hasel.filters import LowPass
from hasel.sensors import StrainConfig


def test_reading_goes_through_the_calibration():
    ch = StrainChannel(Calibration.line(0.4, -40.0))
    assert ch(110.0) == pytest.approx(4.0, abs=1e-12)
    s = StrainConfig()
    assert StrainChannel()(s.rest_pulse_us + 3 * s.us_per_mm) == pytest.approx(3.0, abs=1e-9)
    assert StrainChannel().calibration == default_calibration()


@pytest.mark.parametrize("bad", [math.nan, math.inf, -math.inf, 0.0, -12.5])
def test_unusable_readings_give_nan(bad):
    assert math.isnan(StrainChannel()(bad))


def test_filter_passes_nan_without_touching_its_state():
    x = 3.0 + np.sin(np.arange(40) * 0.3)
    clean, ref = FilterChannel(), LowPass()
    with_nan = FilterChannel()
    out_clean = [clean(v) for v in x]
    out = []
    for i, v in enumerate(x):
        if i in (10, 11, 25):
            assert math.isnan(with_nan(math.nan)) and math.isnan(with_nan(math.inf))
        out.append(with_nan(v))
    # the bad samples were skipped, not filtered: the output equals the clean run's, sample for sample
    assert out == out_clean == [ref(v) for v in x]
