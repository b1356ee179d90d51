"""The strain sensor's 40 Hz digital low-pass at the 200 Hz loop rate.

Design: a 2nd-order Butterworth prototype, H(s) = wc^2 / (s^2 + sqrt(2) wc s + wc^2),
mapped to discrete time by the bilinear transform s = 2 fs (z - 1)/(z + 1) with the
cut-off pre-warped, wc = 2 fs tan(pi fc / fs), so that the discrete filter's -3 dB
point is exactly fc (40 Hz at fs = 200 Hz; without pre-warping it would land at
about 33 Hz). Unity gain at DC, a double zero at Nyquist (z = -1).
"""
from __future__ import annotations

import math

import numpy as np

from hasel import paper
from hasel.errors import BadInputError
from hasel.validate import positive

__all__ = ["butter2_lowpass_biquad", "LowPass"]


def butter2_lowpass_biquad(cutoff_hz: float, rate_hz: float) -> np.ndarray:
    """Coefficients ``[b0, b1, b2, 1, a1, a2]`` of the pre-warped bilinear Butterworth biquad.

    Parameters
    ----------
    cutoff_hz : float
        -3 dB frequency, Hz; must be below the Nyquist frequency ``rate_hz / 2``.
    rate_hz : float
        Sample rate, Hz.
    """
    fc, fs = positive("cutoff_hz", cutoff_hz), positive("rate_hz", rate_hz)
    if fc >= fs / 2:
        raise BadInputError(f"cutoff_hz must be below Nyquist ({fs / 2} Hz), got {fc}")
    k = math.tan(math.pi * fc / fs)  # pre-warped wc / (2 fs)
    q = math.sqrt(2.0)
    norm = 1.0 + q * k + k * k
    b0 = k * k / norm
    return np.array([b0, 2 * b0, b0, 1.0, 2.0 * (k * k - 1.0) / norm, (1.0 - q * k + k * k) / norm])


class LowPass:
    """Stateful 40 Hz (by default) low-pass applied sample by sample at the loop rate.

    The first sample initialises the state at rest on that value, so switching the
    filter on does not produce a transient from zero.
    """

    def __init__(self, cutoff_hz: float = paper.FILTER_CUTOFF_HZ,
                 rate_hz: float = 1.0 / paper.LOOP_PERIOD_S) -> None:
        self.cutoff_hz, self.rate_hz = cutoff_hz, rate_hz
        b0, b1, b2, _, a1, a2 = butter2_lowpass_biquad(cutoff_hz, rate_hz)
        self._c = (float(b0), float(b1), float(b2), float(a1), float(a2))
        self._s1 = self._s2 = 0.0
        self._primed = False

    def reset(self) -> None:
        """Forget the state; the next sample re-initialises it."""
        self._primed = False

    def __call__(self, x: float) -> float:
        """Filter one sample (units preserved, e.g. mm).

        Direct form II transposed in plain floats: one sample at a time at 200 Hz,
        where a call into SciPy would cost a hundred times more than the arithmetic.
        """
        b0, b1, b2, a1, a2 = self._c
        if not self._primed:  # at rest on x: y = x, and the states that hold it there
            self._s1 = x - b0 * x
            self._s2 = b2 * x - a2 * x
            self._primed = True
        y = b0 * x + self._s1
        self._s1 = b1 * x - a1 * y + self._s2
        self._s2 = b2 * x - a2 * y
        return y
