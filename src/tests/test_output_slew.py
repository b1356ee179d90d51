"""The ``saturation`` family's speed limit of the output (``output:slew``): a stroke that cannot move faster than
S mm/s either way (the liquid's flow through the zipping front), told apart from the one-way rate limit of
``asymmetric_dynamics``.

The logs are the exact P(s) (zero-order hold at 500 Hz) on a raised-cosine chirp of 0-7 kV, 0.2-20 Hz (the stroke
moves at up to 76 mm/s), then limited by the loops written here, not by the library's kernels. Before this form a
symmetric limit (forms3.py seed 1, ``zrate``) was named a load, a delay and a sensor curve.
"""
from __future__ import annotations

import designs
import numpy as np
import pytest

RATE_HZ = 500.0


def _limit(z: np.ndarray, up: float, down: float) -> np.ndarray:
    """``z`` followed sample by sample, rising at most ``up`` and falling at most ``down`` mm/s."""
    out = np.empty_like(z)
    y = float(z[0])
    for k, v in enumerate(z):
        y += min(max(v - y, -down / RATE_HZ), up / RATE_HZ)
        out[k] = y
    return out


@pytest.fixture(scope="module")
def chirp():
    u = designs.cosine_chirp(RATE_HZ, 20.0)
    return u, designs.zoh_stroke(u, RATE_HZ)


def test_a_symmetric_stroke_speed_limit_is_named_a_saturation_of_the_output_with_its_rate(chirp):
    """25 mm/s both ways (a third of the chirp's fastest stroke speed; the gap 1 mm rms against 0.005 mm of
    noise): named ``saturation`` alone, variant ``output:slew``, its rate within 2 %, in mm/s."""
    u, z = chirp
    v = designs.diagnose_noisy(u, _limit(z, 25.0, 25.0), 3, RATE_HZ)
    assert v.names == ["saturation"]
    p = v.effects[0]["params"]
    assert p["variant"] == "output:slew" and p["acts_on"] == "output" and p["unit"] == "mm/s"
    assert p["slew_rate_limit"] == pytest.approx(25.0, rel=0.02)


def test_a_one_way_limit_stays_the_asymmetric_rate_limit(chirp):
    """The same 25 mm/s on the fall only: ``asymmetric_dynamics`` (``rate_limit:falling``), not the output slew."""
    u, z = chirp
    v = designs.diagnose_noisy(u, _limit(z, np.inf, 25.0), 3, RATE_HZ)
    assert v.names == ["asymmetric_dynamics"]
    assert v.effects[0]["params"]["variant"] == "rate_limit:falling"
