"""hasel.plantspec: plant variants by name."""
from __future__ import annotations

import numpy as np
import pytest

from hasel.errors import BadInputError
from hasel.plant import NominalActuator
from hasel.plantspec import describe, make_actuator, parse_effects


def test_parse_effects():
    assert parse_effects("a(x=1,y=two)+b") == [("a", {"x": 1.0, "y": "two"}), ("b", {})]
    with pytest.raises(BadInputError, match="param=value"):
        parse_effects("a(x)")


def test_variants():
    assert isinstance(make_actuator("nominal"), NominalActuator)
    truth = make_actuator("truth")
    assert set(truth.effects) == {"asymmetric_dynamics", "charge_drift", "static_nonlinearity",
                                  "sensor_nonlinearity"}
    assert truth.strain_curve is not None and "asymmetric_dynamics" in describe(truth)
    delayed = make_actuator("truth:time_delay(delay_s=0.01)")
    delayed.reset(0.0)
    out = delayed.run(np.full(300, 2.0))
    assert np.all(out.stroke_mm[:99] == 0.0) and out.stroke_mm[-1] > 0.0
    for bad in ("imaginary", "truth:", "truth:nope", "truth:time_delay(lag=3)"):
        with pytest.raises(BadInputError):
            make_actuator(bad)
