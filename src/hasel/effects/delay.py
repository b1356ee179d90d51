"""``time_delay``: latency between the command and the actuation (loop, DAC, amplifier).

Forms
-----
- truth :class:`TimeDelay`: ``delay_s``, rounded to the simulator's sample period.
- generic ``input``: ``x(t - d)``, a fractional delay by linear interpolation between
  samples (``d`` in seconds; ``theta = (d,)``).

Both run :class:`DelayStage` (an integer delay is the fractional one with no
fraction: bit for bit a pure shift). Signature: a delay moves only the phase, by
``-360 f d`` degrees, linear in frequency, and leaves the magnitude alone
(:func:`phase_signature`).
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import ClassVar

import numpy as np

from hasel.effects.base import Effect, EffectFamily, EffectFit, FitContext, Scales
from hasel.effects.fitkit import _fit_scalar
from hasel.effects.operators import DelayStage
from hasel.validate import in_range

__all__ = ["TimeDelay", "DelayStage", "shift", "delay_max", "DelayFamily", "FAMILY"]


@dataclass(frozen=True)
class TimeDelay(Effect):
    """Latency between the command and the actuator (loop, DAC, amplifier).

    Attributes
    ----------
    delay_s : float
        Pure delay, s (rounded to the simulator's sample period).
    """

    name: ClassVar[str] = "time_delay"
    delay_s: float = 0.01

    def __post_init__(self) -> None:
        in_range("delay_s", self.delay_s, 0.0, 10.0)

    @classmethod
    def sample_params(cls, rng: np.random.Generator) -> "TimeDelay":
        return cls(delay_s=float(rng.uniform(0.003, 0.025)))


def shift(t: np.ndarray, x: np.ndarray, d: float) -> np.ndarray:
    """``x`` delayed by ``d`` seconds (>= 0) on the uniform time grid ``t`` (s), from rest at ``x[0]``."""
    x = np.asarray(x, float)
    if x.size < 2 or d <= 0:
        return x.copy()
    t = np.asarray(t, float)
    steps = np.diff(t)
    dt = float(steps[0])
    if float(np.ptp(steps)) > 1e-6 * abs(dt):  # not a uniform grid: interpolate in time
        return np.interp(t - d, t, x, left=x[0], right=x[-1])
    st = DelayStage(d / dt)
    st.reset(float(x[0]))
    return st.run(x)


def delay_max(pipe: FitContext) -> float:
    """Longest delay the diagnosis tries, s: a tenth of the log, at most half the dominant time constant
    (at least 60 samples)."""
    dt = pipe.prep.dt_s
    return min(0.1 * pipe.span_s, max(60.0 * dt, 0.5 * pipe.t_dom))


def phase_signature(freqs_hz: np.ndarray, ratio: np.ndarray) -> dict:
    """How much of a frequency-response ratio (measured over nominal) a pure delay explains.

    A delay leaves the magnitude at 0 dB and turns the phase by ``-360 f d`` degrees:
    the best ``d`` by least squares on the unwrapped phase, and the RMS magnitude (dB)
    and phase (deg) left over. A load moves the magnitude near the resonance instead.

    Parameters
    ----------
    freqs_hz : ndarray
        Frequencies, Hz.
    ratio : ndarray of complex
        Measured over nominal response at ``freqs_hz``.
    """
    f = np.asarray(freqs_hz, float)
    r = np.asarray(ratio, complex)
    ph = np.unwrap(np.angle(r))
    d = float(-(f @ ph) / (2 * math.pi * max(float(f @ f), 1e-300)))
    mag_db = 20 * np.log10(np.maximum(np.abs(r), 1e-300))
    res_ph = np.degrees(ph + 2 * math.pi * f * d)
    return {"delay_s": d, "magnitude_rms_db": float(np.sqrt(np.mean(mag_db ** 2))),
            "phase_residual_rms_deg": float(np.sqrt(np.mean(res_ph ** 2)))}


class DelayFamily(EffectFamily):
    """The ``time_delay`` family (see the module's docstring)."""

    name = "time_delay"
    slot = "input"
    variants = ("input",)
    truth_class = TimeDelay
    bound_experiment = ("a step or a sweep at a higher rate: a pure delay shifts the phase linearly in frequency with "
                        "the magnitude unchanged, another lag does not")

    def param_names(self, fit: EffectFit) -> tuple[str, ...]:
        """``("delay_s",)``."""
        return ("delay_s",)

    def stage(self, fit: EffectFit, scales: Scales, dt_s: float) -> DelayStage:
        """Fractional delay of ``theta[0]`` seconds at ``dt_s``."""
        return DelayStage(fit.theta[0] / dt_s)

    def truth_stage(self, effect: Effect, dt_s: float) -> DelayStage:
        """Integer delay: ``delay_s`` rounded to samples."""
        assert isinstance(effect, TimeDelay)
        return DelayStage(int(round(effect.delay_s / dt_s)))

    def fit(self, ctx: FitContext, effects: dict[str, EffectFit]) -> EffectFit | None:
        """Grid of half a sample to 256 samples (up to :func:`delay_max`), then a bounded refinement."""
        dt = ctx.prep.dt_s
        d_max = delay_max(ctx)
        grid = dt * np.array([0.5, 1, 1.5, 2, 3, 4, 6, 8, 12, 16, 24, 32, 48, 64, 96, 128, 192, 256])
        grid = grid[grid <= d_max]
        return _fit_scalar(ctx, effects, lambda d: EffectFit("time_delay", "input", (d,)), grid)

    def bounds(self, ctx: FitContext, fit: EffectFit) -> tuple[np.ndarray, np.ndarray]:
        """``0 <= d <= delay_max``."""
        return np.zeros(1), np.array([delay_max(ctx)])

    def describe(self, ctx: FitContext, fit: EffectFit, units: tuple[str, str],
                 effects: dict[str, EffectFit]) -> dict:
        """``{"variant", "delay_s"}``."""
        return {"variant": fit.variant, "delay_s": fit.theta[0]}


    def signature(self, ctx: FitContext, fit: EffectFit, effects: dict[str, EffectFit]) -> dict:
        """The measured-over-model response read as a delay and as a load, without this family in the
        model (:func:`hasel.effects.evidence.load_or_delay`)."""
        from hasel.effects.evidence import load_or_delay

        base = {k: v for k, v in effects.items() if k != self.name}
        return {"frequency_response": load_or_delay(ctx, base, getattr(ctx, "den"))}


FAMILY = DelayFamily()
