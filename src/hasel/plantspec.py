"""Plant variants by name: ``nominal``, ``truth`` and ``truth:EFFECT(param=value,...)+EFFECT...``.

``nominal`` is the paper's linear P(s). ``truth`` alone is a realistic actuator with the
effects the paper itself reports: relaxation slower and more damped than activation
(Fig. 4), charge retention (< 5 % per 180 s), a static map that is not a line
(electrostatic zipping), and a strain-sensor calibration curve with small offsets
at 2 and 4 mm. ``truth:...`` picks effects and parameters explicitly, e.g.
``truth:asymmetric_dynamics(tau_relax_s=0.06)+time_delay(delay_s=0.004)``; names and
parameters are those of :mod:`hasel.effects`. Anything else is a plant-model file
(:mod:`hasel.plantfile`: a path, e.g. ``model.json`` from ``hasel identify``). Used by
the plant node's ``variant`` and ``model_file`` parameters and every ``--plant`` option.
"""
from __future__ import annotations

import re

from hasel.errors import BadInputError
from hasel.plant import Actuator, NominalActuator

__all__ = ["PAPER_TRUTH", "parse_effects", "make_actuator", "from_file", "describe"]

#: The effects of the paper's actuator that its linear model leaves out (name, params).
PAPER_TRUTH: tuple[tuple[str, dict], ...] = (
    ("asymmetric_dynamics", {}),
    ("charge_drift", {}),
    ("static_nonlinearity", {"kind": "electrostatic", "strength": 0.3}),
    ("sensor_nonlinearity", {}),
)

_ITEM = re.compile(r"^\s*([a-z_]+)\s*(?:\((.*)\))?\s*$")


def _value(text: str) -> float | str | bool:
    t = text.strip()
    if t.lower() in ("true", "false"):
        return t.lower() == "true"
    try:
        return float(t)
    except ValueError:
        return t.strip("'\"")


def parse_effects(spec: str) -> list[tuple[str, dict]]:
    """``"a(x=1,y=2)+b"`` -> ``[("a", {"x": 1.0, "y": 2.0}), ("b", {})]``."""
    out = []
    for item in filter(None, (s.strip() for s in spec.split("+"))):
        m = _ITEM.match(item)
        if not m:
            raise BadInputError(f"cannot read effect {item!r}: write NAME or NAME(param=value,...)")
        params = {}
        for kv in filter(None, (p.strip() for p in (m.group(2) or "").split(","))):
            if "=" not in kv:
                raise BadInputError(f"effect parameter {kv!r} in {item!r} is not param=value")
            k, v = kv.split("=", 1)
            params[k.strip()] = _value(v)
        out.append((m.group(1), params))
    return out


def make_actuator(variant: str) -> Actuator:
    """The actuator model of a variant string (BadInputError explains a bad one)."""
    v = variant.strip()
    if v == "nominal":
        return NominalActuator()
    if v == "truth" or v.startswith("truth:"):
        from hasel.effects import TruthActuator, from_name

        items = list(PAPER_TRUTH) if v == "truth" else parse_effects(v[len("truth:"):])
        if not items:
            raise BadInputError("truth: names no effect; e.g. truth:asymmetric_dynamics+charge_drift")
        try:
            return TruthActuator([from_name(name, **params) for name, params in items])
        except TypeError as err:
            raise BadInputError(f"bad effect parameters in {variant!r}: {err}") from err
    from hasel.plantfile import looks_like_path

    if looks_like_path(v):
        return from_file(v)
    raise BadInputError(f"unknown plant {variant!r}; use nominal, truth, truth:EFFECT(param=value)+..., "
                        "or a plant-model file (a path ending in .json)")


def from_file(path: str) -> Actuator:
    """The actuator of the plant-model file at ``path`` (:class:`hasel.plantfile.PlantFileError` if malformed)."""
    from hasel.plantchain import build_actuator
    from hasel.plantfile import read_plant

    return build_actuator(read_plant(path))


def describe(actuator: Actuator) -> str:
    """A one-line description of an actuator model (for logs)."""
    own = getattr(actuator, "describe", None)
    if callable(own):
        return own()
    effects = getattr(actuator, "effects", None)
    if not effects:
        return "nominal P(s)"
    return "truth: " + ", ".join(f"{n}({', '.join(f'{k}={v}' for k, v in e.params().items())})"
                                 for n, e in effects.items())
