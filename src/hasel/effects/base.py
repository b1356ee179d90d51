"""The protocol every effect family obeys, and the fitted-effect record.

An *effect family* (one of the eight names of ``shared/interfaces.md``) lives in a
module of its own under :mod:`hasel.effects` and is registered in
:mod:`hasel.effects.registry`. A family has

- a **slot** in the chain: ``"input"`` (acts on the voltage before the linear
  dynamics), ``"dynamics"`` (changes the linear model itself) or ``"output"`` (acts on
  the stroke after the dynamics, or on what the sensor reports);
- **forms**: named parametrisations. The *truth* forms are the physical dataclasses the
  simulated actuator uses (:class:`Effect` subclasses, units in their field names); the
  *generic* forms are what the diagnosis fits (an :class:`EffectFit`, its parameters
  named by :meth:`EffectFamily.param_names`). Where a truth form and a generic form are
  the same law (a delay, a clip, a heavier resonance, a direction-dependent lag, a
  drift's output law) they run the same kernel;
- :meth:`EffectFamily.stage` and :meth:`EffectFamily.truth_stage`: a :class:`Stage`
  that simulates the effect chunk by chunk with its state carried over, so that a plant
  stepping 5 ms at a time runs the same code, with the same numbers, as one long call
  (:meth:`EffectFamily.simulate`);
- :meth:`EffectFamily.fit` (named parameters, with the other effects held fixed),
  :meth:`EffectFamily.bounds`, :meth:`EffectFamily.describe` (parameters with units),
  :meth:`EffectFamily.sample` (random truth parameters for generated cases) and
  :meth:`EffectFamily.signature` (the family's own evidence, e.g. where in frequency it
  moves the response).

Fits see the data through a :class:`FitContext` (the diagnosis's ``Pipeline`` obeys it);
the effect modules never import the diagnosis.
"""
from __future__ import annotations

from abc import ABC, abstractmethod
from dataclasses import dataclass, fields
from typing import Any, ClassVar, Protocol

import numpy as np

__all__ = ["AT_BOUND_REL_TOL", "SLOTS", "Effect", "EffectFit", "Stage", "Scales", "FitContext", "EffectFamily", "LINEAR", "SLOT_ORDER",
           "run_chunked"]

#: A fitted parameter within this share of its range of a limit of the form is reported as at that bound
#: (:meth:`EffectFamily.at_bound`): the refinements stop at the bound itself, or within their tolerance of it.
AT_BOUND_REL_TOL = 1e-3

#: The three places an effect can act, in chain order.
SLOTS = ("input", "dynamics", "output")
#: Name of the pseudo-effect holding a re-identified linear model (not an effect: never named).
LINEAR = "_linear"
#: Position of each ``name:variant-side`` in the diagnosis's chain (the generic forms' order):
#: delay, input clip or slew limit, input lag (``asymmetric_dynamics:input``), input map, hysteresis, map after
#: the hysteresis (offered only beside an accepted hysteresis: ``static_nonlinearity:after_hysteresis``, 3.5),
#: linear model with load, internal map,
#: asymmetric lag or speed limit, hysteresis of the output (``hysteresis:output``), drift, output clip, sensor map,
#: measured clip.
SLOT_ORDER = {LINEAR: 4, "time_delay": 0, "saturation:input": 1, "saturation:slew": 1,
              "asymmetric_dynamics:input": 1.5, "static_nonlinearity:input": 2, "hysteresis": 3,
              "static_nonlinearity:after_hysteresis": 3.5, "load_mass": 4, "static_nonlinearity:internal": 5,
              "asymmetric_dynamics": 6, "hysteresis:output": 6.5, "charge_drift": 7, "saturation:output": 8, "sensor_nonlinearity": 9,
              "saturation:measured": 10}


class Effect:
    """Base of the truth forms' dataclasses: a ``name`` and a dict view of the parameters."""

    name: ClassVar[str] = ""

    def params(self) -> dict[str, Any]:
        """The parameters as a plain dict (JSON-ready)."""
        return {f.name: getattr(self, f.name) for f in fields(self)}  # type: ignore[arg-type]

    @classmethod
    def sample_params(cls, rng: np.random.Generator) -> "Effect":  # pragma: no cover - overridden
        """A random instance for a blind case."""
        raise NotImplementedError


@dataclass(frozen=True)
class EffectFit:
    """One fitted generic effect.

    Attributes
    ----------
    name : str
        Effect name.
    variant : str
        Where or how it acts (e.g. ``"input"``/``"internal"``, ``"output:upper"``).
    theta : tuple of float
        Parameters in the family's order (:meth:`EffectFamily.param_names`).
    """

    name: str
    variant: str
    theta: tuple[float, ...]

    @property
    def n_params(self) -> int:
        """Number of fitted parameters (what the penalty counts; a re-identified nominal counts none)."""
        return 0 if self.name == LINEAR else len(self.theta)

    @property
    def slot(self) -> int:
        """Position in the chain (:data:`SLOT_ORDER`)."""
        key = f"{self.name}:{self.variant.split(':')[0]}"
        return SLOT_ORDER.get(key, SLOT_ORDER.get(self.name, 0))

    def named(self) -> dict[str, float]:
        """The parameters by name (see the family's :meth:`EffectFamily.param_names`)."""
        from hasel.effects.registry import family

        names = family(self.name).param_names(self)
        return dict(zip(names, self.theta))


class Stage(Protocol):
    """One effect instance simulated chunk by chunk; its state is carried between calls."""

    def reset(self, x0: float) -> None:
        """At rest with the input ``x0`` held forever (in the stage's input unit)."""

    def run(self, x: np.ndarray, u: np.ndarray | None = None) -> np.ndarray:
        """The stage's output for the next samples ``x`` (continues from the last call).

        ``u``: the chain's input (voltage) at the same samples, for the stages whose effect
        depends on its history (a drift's charge); the others ignore it."""


class Scales(Protocol):
    """Normalisation of the generic forms (the diagnosis's training data set them).

    ``u_c``, ``u_s``: centre and half-range of the input; ``y_c``, ``y_s``: of the nominal
    output; ``thresholds``: the play operators' half-widths (input unit); ``tau_smooth_s``:
    the drift's pre-smoothing time constant, s.
    """

    u_c: float
    u_s: float
    y_c: float
    y_s: float
    thresholds: tuple[float, ...]


class FitContext(Scales, Protocol):
    """What a fit needs from the diagnosis (obeyed by ``hasel.diagnose.augment.Pipeline``)."""

    prep: Any
    t_dom: float
    t_min: float | None  # the held-out block score a family's choice between forms asks (None: no such choice)
    span_s: float
    clips: dict

    def stages(self, effects: dict[str, EffectFit], ri: int, upto: int = 99) -> dict[str, np.ndarray]:
        """Intermediate signals of record ``ri`` through the chain."""

    def residuals(self, effects: dict[str, EffectFit], mask: str) -> np.ndarray:
        """Stacked measured minus simulated output over the ``mask`` samples."""

    def linear_of(self, effects: dict[str, EffectFit]) -> Any:
        """The linear part (with load) of the chain for ``effects``."""


def run_chunked(stage: Stage, x: np.ndarray, chunk: int, u: np.ndarray | None = None) -> np.ndarray:
    """``stage`` run on ``x`` (and the chain's input ``u``) in consecutive chunks of ``chunk`` samples,
    from rest at ``x[0]``."""
    x = np.asarray(x, float)
    if x.size == 0:
        return x.copy()
    stage.reset(float(x[0]))
    return np.concatenate([stage.run(x[i:i + chunk], None if u is None else u[i:i + chunk])
                           for i in range(0, x.size, chunk)])


class EffectFamily(ABC):
    """One effect family: its forms, chunked simulation, fit, bounds, description and sampling.

    Subclasses set :attr:`name`, :attr:`slot`, :attr:`truth_class` and implement the
    abstract methods; a new family is one module with one subclass plus one line in
    :mod:`hasel.effects.registry`.
    """

    #: One of the eight names of ``shared/interfaces.md``.
    name: ClassVar[str] = ""
    #: Where it acts: one of :data:`SLOTS` (the slot of its first generic variant).
    slot: ClassVar[str] = "input"
    #: Generic variants the diagnosis fits (``EffectFit.variant`` prefixes).
    variants: ClassVar[tuple[str, ...]] = ()
    #: Whether a previous fit is a good start (a grid search can be skipped: :meth:`refine_from`).
    warm_start: ClassVar[bool] = False
    #: The truth form's dataclass.
    truth_class: ClassVar[type[Effect]] = Effect
    #: The experiment that would tell whether the form fits when a parameter is pinned at a limit of it.
    bound_experiment: ClassVar[str] = ("a log over another band, amplitude or rate, where the effect's form can "
                                       "be checked against another one")

    # -- parameters -----------------------------------------------------------------------
    @abstractmethod
    def param_names(self, fit: EffectFit) -> tuple[str, ...]:
        """Names of ``fit.theta``'s entries, in order."""

    def sample(self, rng: np.random.Generator) -> Effect:
        """A random truth instance (the ranges make the effect visible above a laser's noise)."""
        return self.truth_class.sample_params(rng)

    # -- simulation -----------------------------------------------------------------------
    @abstractmethod
    def stage(self, fit: EffectFit, scales: Scales, dt_s: float) -> Stage:
        """A chunked simulator of the generic ``fit`` (normalised by ``scales``) at ``dt_s``."""

    @abstractmethod
    def truth_stage(self, effect: Effect, dt_s: float) -> Stage:
        """A chunked simulator of the truth form ``effect`` at ``dt_s``."""

    def simulate(self, fit: EffectFit, x: np.ndarray, scales: Scales, dt_s: float) -> np.ndarray:
        """The generic ``fit`` applied to a whole signal ``x`` (at rest at ``x[0]`` before)."""
        st = self.stage(fit, scales, dt_s)
        x = np.asarray(x, float)
        if x.size == 0:
            return x.copy()
        st.reset(float(x[0]))
        return st.run(x)

    # -- fitting --------------------------------------------------------------------------
    @abstractmethod
    def fit(self, ctx: FitContext, effects: dict[str, EffectFit]) -> EffectFit | None:
        """Fit on the training samples with ``effects`` (the others) held fixed; ``None`` if it cannot."""

    def bounds(self, ctx: FitContext, fit: EffectFit) -> tuple[np.ndarray, np.ndarray]:
        """Lower and upper bounds of ``fit.theta`` (for refinement; default: free)."""
        inf = np.full(fit.n_params, np.inf)
        return -inf, inf

    def form_limits(self, ctx: FitContext, fit: EffectFit) -> tuple[np.ndarray, np.ndarray]:
        """The bounds of ``fit.theta`` that are limits of the family's *form* (default: :meth:`bounds`): a fit
        pinned at one says the form may not fit the data. A family whose bounds are also ordinary values
        (non-negative weights of which some are zero, a start branch of -1 or 1) returns infinities there."""
        return self.bounds(ctx, fit)

    def at_bound(self, ctx: FitContext, fit: EffectFit, rel_tol: float = AT_BOUND_REL_TOL) -> list[str]:
        """Names of ``fit.theta``'s entries at (or within ``rel_tol`` of the range between) a limit of
        :meth:`form_limits`. With a one-sided range the tolerance is ``rel_tol`` of the bound's size (only
        an exact pin at a bound of zero), plus 1e-12 (units of the parameter)."""
        lo, hi = (np.broadcast_to(np.asarray(b, float), (len(fit.theta),)) for b in self.form_limits(ctx, fit))
        names = self.param_names(fit)
        out = []
        for j, x in enumerate(fit.theta):
            span = hi[j] - lo[j]
            for b in (lo[j], hi[j]):
                if not np.isfinite(b):
                    continue
                tol = rel_tol * (span if np.isfinite(span) else abs(b)) + 1e-12
                if abs(float(x) - b) <= tol:
                    out.append(names[j] if j < len(names) else f"theta_{j}")
                    break
        return out

    def refine_from(self, ctx: FitContext, effects: dict[str, EffectFit], init: EffectFit) -> EffectFit | None:
        """A warm-started fit from ``init``: a bounded refinement (10 evaluations) for the families
        with :attr:`warm_start`, else a fresh :meth:`fit`."""
        if not self.warm_start:
            return self.fit(ctx, effects)
        from hasel.effects.fitkit import refine

        lo, hi = self.bounds(ctx, init)
        return refine(ctx, effects, init, lo, hi, max_nfev=10)

    @abstractmethod
    def describe(self, ctx: FitContext, fit: EffectFit, units: tuple[str, str],
                 effects: dict[str, EffectFit]) -> dict:
        """The fitted parameters in physical terms, with units (JSON-ready)."""

    # -- evidence -------------------------------------------------------------------------
    def signature(self, ctx: FitContext, fit: EffectFit, effects: dict[str, EffectFit]) -> dict:
        """The family's own evidence for ``fit`` (JSON-ready; empty when it has none)."""
        return {}
