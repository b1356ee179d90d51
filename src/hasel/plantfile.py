"""The plant-model file: one versioned JSON format for any actuator model the graph can run.

A plant file is a continuous transfer function from the applied voltage to the stroke
(any proper, stable order, optional dead time), optionally followed by unmodelled
effects in the chain order the diagnosis uses::

    {"format": "hasel-plant", "version": 1,
     "num": [...], "den": [...],            # descending powers of s (rad/s)
     "delay_s": 0.0,                        # dead time between applied voltage and stroke, s
     "units": {"input": "kV", "output": "mm"},
     "effects": [{"name": "time_delay", "params": {"delay_s": 0.004}}, ...]}

``MODEL.json`` from ``hasel identify`` is such a file as it stands (it has ``num``,
``den``, ``delay_s`` and ``units``; ``format`` and ``version`` may be absent), and is read
losslessly. The units must be the graph's (kV in, mm out), another unit this module
knows (V; m, um), or be converted by stated factors ``units.kv_to_input`` and
``units.output_to_mm``. An effect is either a *truth form* (``{"name", "params"}``: the
physical parameters of :func:`hasel.effects.from_name`, as in ``--plant truth:...``) or a
*fitted form* (``{"name", "form": "fitted", "variant", "params"}``: a generic form the
diagnosis fits, its parameters named as the family names them, normalised by the file's
``scales``). The chain is run by :mod:`hasel.plantchain`.

Anything malformed raises :class:`PlantFileError` (a :class:`BadInputError`) with one
line that names the file and the problem.
"""
from __future__ import annotations

import json
import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from hasel.errors import BadInputError

__all__ = ["FORMAT", "VERSION", "PlantFileError", "EffectEntry", "PlantModel", "parse_plant", "read_plant",
           "write_plant", "truth_order", "looks_like_path", "from_verdict", "export_plant"]

FORMAT = "hasel-plant"
VERSION = 1

#: Known unit conversions: graph kV -> input unit, and output unit -> graph mm.
_INPUT_UNITS = {"kV": 1.0, "V": 1000.0}
_OUTPUT_UNITS = {"mm": 1.0, "m": 1000.0, "um": 1e-3, "µm": 1e-3}
#: Truth forms' places in the diagnosis's chain (:data:`hasel.effects.base.SLOT_ORDER`).
_TRUTH_SLOT = {"time_delay": 0, "static_nonlinearity": 2, "hysteresis": 3, "load_mass": 4,
               "asymmetric_dynamics": 6, "charge_drift": 7, "sensor_nonlinearity": 9}
#: Keys of ``scales`` a fitted form needs.
SCALE_KEYS = ("u_c", "u_s", "y_c", "y_s", "thresholds", "tau_smooth_s")


class PlantFileError(BadInputError):
    """A plant-model file is missing, unreadable or malformed; the message is one line."""


@dataclass(frozen=True)
class EffectEntry:
    """One effect of a plant file.

    Attributes
    ----------
    name : str
        One of the eight effect names.
    params : dict
        Truth form: the dataclass fields (units in their names). Fitted form: the
        family's parameter names, in order, with their values.
    form : str
        ``"truth"`` or ``"fitted"``.
    variant : str
        Fitted form only: where or how it acts (``EffectFit.variant``).
    """

    name: str
    params: dict
    form: str = "truth"
    variant: str = ""

    def slot(self) -> int:
        """Position in the diagnosis's chain (lower acts first)."""
        if self.form == "fitted":
            return self.fit().slot
        if self.name == "saturation":
            return 8 if self.params.get("kind", "amplifier") == "stroke" else 1
        return _TRUTH_SLOT[self.name]

    def fit(self):
        """The fitted form as an :class:`hasel.effects.base.EffectFit`."""
        from hasel.effects.base import EffectFit

        return EffectFit(self.name, self.variant, tuple(float(v) for v in self.params.values()))

    def to_json(self) -> dict:
        """The entry as written in a file."""
        if self.form == "fitted":
            return {"name": self.name, "form": "fitted", "variant": self.variant, "params": dict(self.params)}
        return {"name": self.name, "params": dict(self.params)}


@dataclass(frozen=True)
class PlantModel:
    """A plant model read from (or to be written to) a plant file, in the graph's units (kV -> mm).

    Attributes
    ----------
    num, den : tuple of float
        P(s) from the applied voltage (kV) to the stroke (mm), descending powers of s (rad/s).
    delay_s : float
        Dead time between the applied voltage and the stroke, s.
    effects : tuple of EffectEntry
        Unmodelled effects in chain order (all truth forms or all fitted forms).
    scales : dict
        Normalisation of the fitted forms (:data:`SCALE_KEYS`); empty for truth forms.
    source : str
        Where it came from (a path), for messages.
    extra : dict
        The file's other keys (kept, not interpreted).
    """

    num: tuple[float, ...]
    den: tuple[float, ...]
    delay_s: float = 0.0
    effects: tuple[EffectEntry, ...] = ()
    scales: dict = field(default_factory=dict)
    source: str = ""
    extra: dict = field(default_factory=dict)

    @property
    def fitted(self) -> bool:
        """Whether the effects are fitted (generic) forms."""
        return bool(self.effects) and self.effects[0].form == "fitted"

    def to_json(self) -> dict:
        """The file's content (format, version, TF, delay, units kV/mm, effects, scales)."""
        out: dict[str, Any] = {**self.extra, "format": FORMAT, "version": VERSION,
                               "num": list(self.num), "den": list(self.den), "delay_s": self.delay_s,
                               "units": {"input": "kV", "output": "mm"},
                               "effects": [e.to_json() for e in self.effects]}
        if self.scales:
            out["scales"] = {k: (list(v) if isinstance(v, (list, tuple)) else v) for k, v in self.scales.items()}
        return out

    def describe(self) -> str:
        """One line: order, static gain, delay and effects."""
        g = self.num[-1] / self.den[-1] if self.den[-1] != 0 else float("nan")
        text = (f"{len(self.num) - 1} zeros / {len(self.den) - 1} poles, {g:.4g} mm/kV static"
                + (f", delay {self.delay_s * 1e3:.3g} ms" if self.delay_s > 0 else ""))
        if self.effects:
            text += "; " + ", ".join(e.name + (f"[{e.variant}]" if e.variant else "") for e in self.effects)
        return text


def _fail(where: str, msg: str) -> PlantFileError:
    return PlantFileError(f"plant file {where}: {msg}" if where else f"plant model: {msg}")


def _coeffs(where: str, key: str, value: Any) -> np.ndarray:
    if not isinstance(value, list) or not value:
        raise _fail(where, f"{key!r} must be a non-empty list of numbers (descending powers of s)")
    if not all(isinstance(v, (int, float)) and not isinstance(v, bool) for v in value):
        raise _fail(where, f"{key!r} must hold numbers only, got {value!r}")
    arr = np.asarray(value, float)
    if not np.all(np.isfinite(arr)):
        raise _fail(where, f"{key!r} has a non-finite coefficient (NaN or infinity): {value!r}")
    return arr


def _number(where: str, key: str, value: Any, lo: float = -math.inf, hi: float = math.inf) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(float(value)):
        raise _fail(where, f"{key} must be a finite number, got {value!r}")
    v = float(value)
    if not lo <= v <= hi:
        raise _fail(where, f"{key} must be within [{lo:g}, {hi:g}], got {v:g}")
    return v


def _factors(where: str, units: Any) -> tuple[float, float]:
    """(kV -> input unit, output unit -> mm) from the ``units`` object."""
    if not isinstance(units, dict):
        raise _fail(where, 'states no units: add "units": {"input": "kV", "output": "mm"} '
                           "(or the factors kv_to_input and output_to_mm)")
    fi, fo = units.get("kv_to_input"), units.get("output_to_mm")
    uin, uout = units.get("input"), units.get("output")
    if fi is None:
        if uin not in _INPUT_UNITS:
            raise _fail(where, f"input unit {uin!r} is not the graph's kV; state units.kv_to_input "
                               f"(known: {', '.join(_INPUT_UNITS)})")
        fi = _INPUT_UNITS[uin]
    if fo is None:
        if uout not in _OUTPUT_UNITS:
            raise _fail(where, f"output unit {uout!r} is not the graph's mm; state units.output_to_mm "
                               f"(known: {', '.join(_OUTPUT_UNITS)})")
        fo = _OUTPUT_UNITS[uout]
    fi = _number(where, "units.kv_to_input", fi)
    fo = _number(where, "units.output_to_mm", fo)
    if fi == 0.0 or fo == 0.0:
        raise _fail(where, "unit factors must not be zero")
    return fi, fo


def _tf(where: str, obj: dict, fi: float, fo: float) -> tuple[np.ndarray, np.ndarray]:
    if "num" not in obj or "den" not in obj:
        raise _fail(where, 'needs "num" and "den" (a continuous transfer function, descending powers of s)')
    num, den = _coeffs(where, "num", obj["num"]), _coeffs(where, "den", obj["den"])
    num = np.trim_zeros(num, "f")
    den = np.trim_zeros(den, "f")
    if den.size == 0:
        raise _fail(where, "den is all zeros")
    if num.size == 0:
        raise _fail(where, "num is all zeros: the model never moves")
    if num.size > den.size:
        raise _fail(where, f"the transfer function is not proper (numerator degree {num.size - 1} > "
                           f"denominator degree {den.size - 1})")
    poles = np.roots(den)
    bad = poles[np.real(poles) >= 0.0]
    if bad.size:
        raise _fail(where, "the transfer function is not stable: pole(s) "
                           + ", ".join(f"{complex(p):.4g}" for p in bad) + " rad/s in the closed right half-plane")
    if fi != 1.0 or fo != 1.0:  # in kV -> mm: scale the numerator only (the poles stay)
        num = num * (fi * fo)
    return num, den


def _effect(where: str, i: int, item: Any, num: np.ndarray, den: np.ndarray) -> EffectEntry:
    from hasel.effects.base import EffectFit
    from hasel.effects.params import from_name
    from hasel.effects.registry import FAMILIES, NAMES

    at = f"effect {i + 1}"
    if not isinstance(item, dict) or not isinstance(item.get("name"), str):
        raise _fail(where, f'{at} must be {{"name": ..., "params": {{...}}}}, got {item!r}')
    name = item["name"]
    if name not in FAMILIES:
        raise _fail(where, f"{at}: unknown effect {name!r}; expected one of {', '.join(NAMES)}")
    params = item.get("params", {})
    if not isinstance(params, dict):
        raise _fail(where, f"{at} ({name}): params must be an object of name: value")
    unknown = sorted(set(item) - {"name", "params", "form", "variant"})
    if unknown:
        raise _fail(where, f"{at} ({name}): unknown key(s) {', '.join(unknown)}")
    form = item.get("form", "truth")
    if form == "truth":
        try:
            from_name(name, **params)
        except BadInputError as err:
            raise _fail(where, f"{at}: {err}") from err
        except (TypeError, ValueError) as err:
            raise _fail(where, f"{at} ({name}): bad parameters: {err}") from err
        return EffectEntry(name, dict(params))
    if form != "fitted":
        raise _fail(where, f"{at} ({name}): form must be 'truth' or 'fitted', got {form!r}")
    fam = FAMILIES[name]
    variant = item.get("variant")
    if not isinstance(variant, str) or variant.split(":")[0] not in fam.variants:
        raise _fail(where, f"{at} ({name}): variant must start with one of {', '.join(fam.variants)}, "
                           f"got {variant!r}")
    values = [_number(where, f"{at} ({name}) parameter {k}", v) for k, v in params.items()]
    expected = fam.param_names(EffectFit(name, variant, tuple(values)))
    if tuple(params) != tuple(expected):
        extra = sorted(set(params) - set(expected))
        what = f"unknown parameter(s) {', '.join(extra)}" if extra else f"parameters {', '.join(params)}"
        raise _fail(where, f"{at} ({name}, fitted {variant}): {what}; expected, in order: {', '.join(expected)}")
    return EffectEntry(name, dict(zip(params, values)), "fitted", variant)


def _scales(where: str, obj: Any) -> dict:
    if not isinstance(obj, dict):
        raise _fail(where, f"fitted effects need \"scales\": {{{', '.join(SCALE_KEYS)}}}")
    missing = [k for k in SCALE_KEYS if k not in obj]
    if missing:
        raise _fail(where, f"scales lack {', '.join(missing)}")
    out: dict[str, Any] = {}
    for k in SCALE_KEYS:
        if k == "thresholds":
            out[k] = tuple(_coeffs(where, "scales.thresholds", obj[k]).tolist())
        else:
            out[k] = _number(where, f"scales.{k}", obj[k])
    for k in ("u_s", "y_s", "tau_smooth_s"):
        if out[k] <= 0:
            raise _fail(where, f"scales.{k} must be > 0, got {out[k]:g}")
    return out


def parse_plant(obj: Any, where: str = "") -> PlantModel:
    """A :class:`PlantModel` from a parsed plant file (or MODEL.json); :class:`PlantFileError` if malformed.

    ``where`` names the source in messages (a path).
    """
    if not isinstance(obj, dict):
        raise _fail(where, "is not a JSON object")
    fmt = obj.get("format", FORMAT)
    if fmt != FORMAT:
        raise _fail(where, f"format is {fmt!r}, not {FORMAT!r}")
    if "format" in obj:  # a MODEL.json's own "version" is the tool's, not the format's
        ver = obj.get("version")
        if ver != VERSION or isinstance(ver, bool):
            raise _fail(where, f"version {ver!r} is not supported (this reader knows version {VERSION})")
    fi, fo = _factors(where, obj.get("units"))
    num, den = _tf(where, obj, fi, fo)
    delay = obj.get("delay_s", 0.0)
    delay = 0.0 if delay is None else _number(where, "delay_s", delay, 0.0, 10.0)
    items = obj.get("effects", []) or []
    if not isinstance(items, list):
        raise _fail(where, "effects must be a list of {\"name\", \"params\"}")
    effects = tuple(_effect(where, i, it, num, den) for i, it in enumerate(items))
    if effects and (fi != 1.0 or fo != 1.0):
        raise _fail(where, "effects need the graph's units (kV in, mm out): their parameters are not converted")
    forms = {e.form for e in effects}
    if len(forms) > 1:
        raise _fail(where, "effects mix truth and fitted forms; use one kind")
    names = [e.name for e in effects]
    dup = sorted({n for n in names if names.count(n) > 1})
    if dup:
        raise _fail(where, f"effect {dup[0]} given twice")
    slots = [e.slot() for e in effects]
    if slots != sorted(slots):
        order = ", ".join(e.name for e in sorted(effects, key=EffectEntry.slot))
        raise _fail(where, f"effects are not in the chain order; write them as: {order}")
    scales = _scales(where, obj.get("scales")) if "fitted" in forms else {}
    known = {"format", "num", "den", "delay_s", "units", "effects", "scales"} | ({"version"} if "format" in obj else set())
    return PlantModel(tuple(float(c) for c in num), tuple(float(c) for c in den), delay, effects, scales,
                      where, {k: v for k, v in obj.items() if k not in known})


def read_plant(path: str | Path) -> PlantModel:
    """Read and check the plant file at ``path``; :class:`PlantFileError` (one line) if it cannot be used."""
    where = str(path)
    try:
        text = Path(path).read_text()
    except FileNotFoundError as err:
        raise _fail(where, "does not exist") from err
    except (OSError, UnicodeDecodeError) as err:
        raise _fail(where, f"cannot be read: {err}") from err
    try:
        obj = json.loads(text, parse_constant=lambda c: float(c))
    except json.JSONDecodeError as err:
        raise _fail(where, f"is not JSON: {err.msg} at line {err.lineno} column {err.colno}") from err
    return parse_plant(obj, where)


def write_plant(path: str | Path, model: PlantModel) -> Path:
    """Write ``model`` as a plant file (atomically, like every output); returns the path."""
    from hasel.outputs import write_text

    return write_text(path, json.dumps(model.to_json(), indent=2, allow_nan=False) + "\n")


def truth_order(items: list[tuple[str, dict]]) -> list[tuple[str, dict]]:
    """Truth-form ``(name, params)`` pairs sorted into the chain order of a plant file."""
    return sorted(items, key=lambda it: EffectEntry(it[0], it[1]).slot())


def looks_like_path(spec: str) -> bool:
    """Whether a ``--plant`` value names a file rather than ``nominal``/``truth...``."""
    s = spec.strip()
    return s not in ("nominal", "truth") and not s.startswith("truth:") and (
        s.endswith(".json") or "/" in s or Path(s).exists())


def from_verdict(verdict: Any, units: tuple[str, str] = ("kV", "mm")) -> PlantModel:
    """The augmented model of a ``hasel diagnose`` verdict as a :class:`PlantModel` (fitted forms).

    The transfer function is the diagnosis's linear part (re-identified through the input-side
    effects if it was), with the nominal model's dead time; the effects are the named ones,
    in chain order, with the scales the diagnosis normalised them by. The data must be in
    the graph's units (kV in, mm out): fitted parameters are not converted.

    A fit the diagnosis kept in its model but did not name (a delay within one sample, folded into the
    log's timing offset: a sampling convention or a clock offset between the channels, not the actuator's
    physics) is left out of the simulated chain and listed under ``extra["not_simulated"]`` with its
    parameters (s) and why: the simulator would otherwise add a logger's convention to every step.
    """
    from hasel.diagnose.augment import split_linear
    from hasel.effects.base import LINEAR
    from hasel.effects.drift import smoothing_s

    if tuple(units) != ("kV", "mm"):
        raise PlantFileError(f"--export-plant needs the data in kV (input) and mm (output), got {units[0] or '?'} "
                             f"and {units[1] or '?'} (name the signals ..._kv and ..._mm)")
    pipe, current = verdict.plots["pipe"], verdict.plots["current"]
    num, den = (split_linear(current[LINEAR]) if LINEAR in current else (pipe.num, pipe.den))
    named = set(verdict.names)
    fits = sorted((f for n, f in current.items() if n != LINEAR and n in named), key=lambda f: f.slot)
    left = [{"name": n, "variant": f.variant,
             "params": {k: float(x) for k, x in f.named().items()},
             "why": "a timing offset within one sample (the log's sampling convention or a clock offset between "
                    "its channels), not named by the diagnosis: not the actuator's physics"}
            for n, f in current.items() if n != LINEAR and n not in named]
    effects = tuple(EffectEntry(f.name, {k: float(x) for k, x in f.named().items()}, "fitted", f.variant)
                    for f in fits)
    scales = {"u_c": float(pipe.u_c), "u_s": float(pipe.u_s), "y_c": float(pipe.y_c), "y_s": float(pipe.y_s),
              "thresholds": [float(r) for r in pipe.thresholds], "tau_smooth_s": float(smoothing_s(pipe))}
    model = PlantModel(tuple(map(float, num)), tuple(map(float, den)), float(pipe.delay_s), effects,
                       scales if effects else {},
                       extra={"tool": "hasel diagnose --export-plant",
                              "heldout": {k: verdict.heldout.get(k) for k in ("nrmse_nominal", "nrmse_augmented")},
                              **({"not_simulated": left,
                                  "heldout_note": "the held-out NRMSEs are the diagnosis's, with not_simulated in "
                                                  "its model"} if left else {})})
    return parse_plant(model.to_json(), "(exported)")  # the writer's output must read back


def export_plant(verdict: Any, path: str | Path, units: tuple[str, str] = ("kV", "mm")) -> Path:
    """Write the verdict's augmented model as a plant file at ``path`` (see :func:`from_verdict`)."""
    return write_plant(path, from_verdict(verdict, units))
