"""hasel.outputs.json_safe: what every command writes as strict JSON."""
from __future__ import annotations

import json
import math

import numpy as np

from hasel.outputs import json_safe


def test_numpy_values_become_plain_and_non_finite_numbers_null():
    doc = {"nan": np.float64("nan"), 3: (np.int32(3), np.bool_(True), [math.inf, 2.5]),
           "arr": np.array([[1.0, np.nan]]), "f32": np.float32(1.5), "text": "x", "none": None}
    out = json_safe(doc)
    assert out == {"nan": None, "3": [3, True, [None, 2.5]], "arr": [[1.0, None]], "f32": 1.5, "text": "x",
                   "none": None}
    assert type(out["3"][0]) is int and type(out["3"][1]) is bool and type(out["f32"]) is float
    json.dumps(out, allow_nan=False)  # strict JSON accepts it
