"""The strain-sensor channel before the controller: the driver's and the filter's decisions.

:class:`StrainChannel` maps one LMC555 reading (elapsed time, us) to a stroke (mm)
through the calibration. A reading that is not finite or not positive (no pulse, a
timer overflow, a disconnected sensor) gives NaN, which the controller's
plausibility gate rejects as missing: a wrong number is never invented for it.

:class:`FilterChannel` is the 40 Hz low-pass at the loop rate with its NaN rule: a
non-finite sample is passed on as NaN without entering the filter, so one bad reading
cannot poison the filter's state; the next good sample continues from the state the
last good one left.

A frozen sensor (readings that stop changing) is not decided here: telling it from an
actuator at rest needs the command, so the controller core does it
(:class:`hasel.faults.StuckDetector`).

The driver and filter nodes call these once per message; :mod:`hasel.loop` composes
the same objects, so the node graph and the offline loop decide alike.
"""
from __future__ import annotations

import math

from hasel import paper
from hasel.calibration import Calibration
from hasel.filters import LowPass
from hasel.sensors import StrainConfig

__all__ = ["default_calibration", "StrainChannel", "FilterChannel"]


def default_calibration(strain: StrainConfig | None = None) -> Calibration:
    """The ideal line of a strain sensor (what a perfect calibration would find), mm per us."""
    s = strain or StrainConfig()
    return Calibration.line(1.0 / s.us_per_mm, -s.rest_pulse_us / s.us_per_mm, "ideal")


class StrainChannel:
    """555 elapsed time (us) -> stroke (mm); NaN for a non-finite or non-positive reading."""

    def __init__(self, calibration: Calibration | None = None) -> None:
        self.calibration = calibration or default_calibration()

    def __call__(self, elapsed_us: float) -> float:
        """Stroke in mm of one reading in us (NaN when the reading is not usable)."""
        us = float(elapsed_us)
        return float(self.calibration(us)) if math.isfinite(us) and us > 0.0 else math.nan


class FilterChannel:
    """The low-pass (40 Hz at 200 Hz by default) with the NaN rule, one sample at a time (mm)."""

    def __init__(self, cutoff_hz: float = paper.FILTER_CUTOFF_HZ,
                 rate_hz: float = 1.0 / paper.LOOP_PERIOD_S) -> None:
        self.lowpass = LowPass(cutoff_hz, rate_hz)

    def __call__(self, z_mm: float) -> float:
        """Filtered stroke (mm) of one sample; NaN in, NaN out, the state untouched."""
        return self.lowpass(z_mm) if math.isfinite(z_mm) else math.nan
