"""The one place where effect families are registered.

Adding a family: write ``hasel/effects/<family>.py`` with an
:class:`hasel.effects.base.EffectFamily` subclass and a module-level ``FAMILY``, and add
one line to :data:`_MODULES`. Everything else (the truth plant, the diagnosis's fits,
bounds and descriptions, ``from_name`` and random draws) looks families up here.
"""
from __future__ import annotations

from importlib import import_module

from hasel.effects.base import EffectFamily
from hasel.errors import BadInputError

__all__ = ["FAMILIES", "NAMES", "family", "families"]

# in the order of shared/interfaces.md; one line per family
_MODULES = (
    "hasel.effects.static_map",
    "hasel.effects.asymmetric",
    "hasel.effects.drift",
    "hasel.effects.saturation",
    "hasel.effects.delay",
    "hasel.effects.sensor",
    "hasel.effects.load",
    "hasel.effects.hysteresis",
)

#: name -> family, in the order of ``shared/interfaces.md``.
FAMILIES: dict[str, EffectFamily] = {}
for _m in _MODULES:
    _f = import_module(_m).FAMILY
    if _f.name in FAMILIES:
        raise RuntimeError(f"effect family {_f.name} registered twice")
    FAMILIES[_f.name] = _f
#: The registered names, in order.
NAMES: tuple[str, ...] = tuple(FAMILIES)


def family(name: str) -> EffectFamily:
    """The family called ``name``; :class:`BadInputError` for an unknown name."""
    f = FAMILIES.get(name)
    if f is None:
        raise BadInputError(f"unknown effect {name!r}; expected one of {', '.join(NAMES)}")
    return f


def families() -> tuple[EffectFamily, ...]:
    """All registered families, in order."""
    return tuple(FAMILIES.values())
