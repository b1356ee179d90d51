"""Strain-sensor calibration: 555 elapsed time (us) -> stroke (mm).

The paper holds the actuator at 1 mm steps from 2 to 7 mm with the laser as ground
truth and fits the line of best fit between elapsed time and laser stroke. The
calibration is a polynomial in the elapsed time (degree 1 by default; 2-3 allowed
for a sensor whose curve is not a line). Stored as YAML so the driver node loads it.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import yaml

from hasel.errors import BadInputError, DataFileError

__all__ = ["Calibration", "fit_calibration", "CalibrationFit"]


@dataclass(frozen=True)
class Calibration:
    """stroke_mm = polyval(coeffs, elapsed_us), coefficients in descending powers.

    For a line, ``coeffs = (slope_mm_per_us, offset_mm)``.
    """

    coeffs: tuple[float, ...]
    source: str = "default"

    def __post_init__(self) -> None:
        if not 1 <= len(self.coeffs) - 1 <= 3:
            raise BadInputError(f"calibration degree must be 1 to 3, got {len(self.coeffs) - 1}")
        if not all(math.isfinite(c) for c in self.coeffs):
            raise BadInputError(f"calibration coefficients must be finite, got {self.coeffs}")

    @property
    def slope_mm_per_us(self) -> float:
        """Local slope at the first coefficient (exact for a line), mm/us."""
        return float(self.coeffs[-2])

    @property
    def offset_mm(self) -> float:
        """Constant term, mm."""
        return float(self.coeffs[-1])

    def __call__(self, elapsed_us: float | np.ndarray) -> float | np.ndarray:
        """Stroke in mm for elapsed times in us (NaN stays NaN)."""
        if isinstance(elapsed_us, float):
            # one reading per 200 Hz tick in the driver: Horner in plain floats (np.polyval
            # costs more than the arithmetic); the same operations, so the same number
            y = 0.0
            for c in self.coeffs:
                y = y * elapsed_us + c
            return y
        return np.polyval(self.coeffs, elapsed_us)

    @classmethod
    def line(cls, slope_mm_per_us: float, offset_mm: float, source: str = "line") -> Calibration:
        """A linear calibration."""
        return cls((float(slope_mm_per_us), float(offset_mm)), source)

    def to_yaml(self, path: str | Path, extra: dict | None = None) -> None:
        """Write the calibration as YAML (keys: coeffs, degree, units, source, ...)."""
        doc = {"coeffs": [float(c) for c in self.coeffs], "degree": len(self.coeffs) - 1,
               "input": "elapsed_us", "output": "stroke_mm", "source": self.source}
        if len(self.coeffs) == 2:
            doc["slope_mm_per_us"], doc["offset_mm"] = float(self.coeffs[0]), float(self.coeffs[1])
        doc.update(extra or {})
        Path(path).write_text(yaml.safe_dump(doc, sort_keys=False))

    @classmethod
    def from_yaml(cls, path: str | Path) -> Calibration:
        """Read a calibration written by :meth:`to_yaml` (or by hand: ``coeffs: [...]``)."""
        try:
            doc = yaml.safe_load(Path(path).read_text())
        except (OSError, yaml.YAMLError) as err:
            raise DataFileError(f"cannot read calibration {path}: {err}") from err
        if not isinstance(doc, dict) or "coeffs" not in doc:
            raise DataFileError(f"{path}: not a calibration file (no 'coeffs' list)")
        try:
            coeffs = tuple(float(c) for c in doc["coeffs"])
        except (TypeError, ValueError) as err:
            raise DataFileError(f"{path}: coeffs must be numbers, got {doc['coeffs']!r}") from err
        return cls(coeffs, str(doc.get("source", path)))


@dataclass(frozen=True)
class CalibrationFit:
    """A fitted calibration with its evidence: the points and residuals (mm)."""

    calibration: Calibration
    elapsed_us: np.ndarray
    laser_mm: np.ndarray
    residual_mm: np.ndarray = field(repr=False)

    @property
    def max_error_pct(self) -> float:
        """Largest |residual| relative to the stroke at that point, %."""
        return float(np.max(np.abs(self.residual_mm) / np.abs(self.laser_mm)) * 100.0)


def fit_calibration(elapsed_us: np.ndarray, laser_mm: np.ndarray, degree: int = 1) -> CalibrationFit:
    """Least-squares polynomial from elapsed time (us) to laser stroke (mm).

    Parameters
    ----------
    elapsed_us, laser_mm : ndarray, shape (n,)
        Mean elapsed time and mean laser stroke at each held point.
    degree : int
        1 (the paper's line of best fit) to 3.
    """
    x, y = np.asarray(elapsed_us, float), np.asarray(laser_mm, float)
    if x.shape != y.shape or x.ndim != 1:
        raise BadInputError(f"elapsed_us and laser_mm must be 1-D of one length, got {x.shape} and {y.shape}")
    if not 1 <= degree <= 3:
        raise BadInputError(f"degree must be 1 to 3, got {degree}")
    if x.size < degree + 1 or np.ptp(x) <= 0:
        raise BadInputError(f"need at least {degree + 1} distinct points, got {x.size}")
    if not (np.all(np.isfinite(x)) and np.all(np.isfinite(y))):
        raise BadInputError("calibration points must be finite")
    coeffs = np.polyfit(x, y, degree)
    cal = Calibration(tuple(float(c) for c in coeffs), "fit")
    return CalibrationFit(cal, x, y, y - np.polyval(coeffs, x))
