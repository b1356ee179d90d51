"""``charge_drift``: a slow gain and offset change driven by the history of the voltage.

Forms
-----
- truth :class:`ChargeDrift`: ``q`` a first-order low-pass (``tau_s``) of the applied
  voltage from no charge; the stroke becomes ``z (1 - gain_loss_per_kv q) +
  offset_mm_per_kv q``.
- generic ``output`` (``theta = (tau, g, o)``): ``y (1 + g q) + y_s o q``, ``q`` the same
  low-pass of the input pre-smoothed by two first-order stages (a tenth of the shortest
  drift time constant, :func:`smoothing_s`), over the input's half-range ``u_s``.

Both run :class:`DriftStage` (a chain of first-order low-passes from zero, their states
carried between chunks, and the law :func:`drift_law`). The stage needs the input
(voltage) beside the output: ``run(y, u)``.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import ClassVar

import numpy as np
from scipy import optimize, signal

from hasel.effects.base import Effect, EffectFamily, EffectFit, FitContext, Scales
from hasel.effects.fitkit import _ls, _sse, _with, sumsq
from hasel.validate import in_range, positive

__all__ = ["ChargeDrift", "DriftStage", "drift_law", "lowpass_chain", "tau_min", "smoothing_s",
           "fit_drift_on_repeats", "DriftFamily", "FAMILY"]


@dataclass(frozen=True)
class ChargeDrift(Effect):
    """Slow gain and offset change driven by the history of the applied voltage.

    Charge accumulates in the dielectric as ``q``, a first-order low-pass of the
    applied voltage with time constant ``tau_s`` (kV), from none at rest. The stroke becomes
    ``z (1 - gain_loss_per_kv q) + offset_mm_per_kv q``: trapped charge screens the
    field (less gain) and holds the pouches partly zipped (an offset). The paper
    found < 5 % change over any 180 s at 0-9 kV; the defaults give about 4 % at 7 kV.

    Attributes
    ----------
    tau_s : float
        Charging time constant, s.
    gain_loss_per_kv : float
        Relative gain lost per kV of accumulated charge, 1/kV.
    offset_mm_per_kv : float
        Stroke offset per kV of accumulated charge, mm/kV (either sign).
    """

    name: ClassVar[str] = "charge_drift"
    tau_s: float = 120.0
    gain_loss_per_kv: float = 0.004
    offset_mm_per_kv: float = 0.02

    def __post_init__(self) -> None:
        positive("tau_s", self.tau_s)
        in_range("gain_loss_per_kv", self.gain_loss_per_kv, -0.2, 0.2)
        in_range("offset_mm_per_kv", self.offset_mm_per_kv, -2.0, 2.0)

    @classmethod
    def sample_params(cls, rng: np.random.Generator) -> "ChargeDrift":
        sign = 1.0 if rng.random() < 0.7 else -1.0
        return cls(tau_s=float(rng.uniform(20.0, 150.0)), gain_loss_per_kv=float(rng.uniform(0.006, 0.025)),
                   offset_mm_per_kv=float(sign * rng.uniform(0.02, 0.08)))


def drift_law(y: np.ndarray, q: np.ndarray, gain: float, offset: float) -> np.ndarray:
    """``y (1 + gain q) + offset q``: the output with a charge ``q``'s gain change and offset."""
    return y * (1.0 + gain * q) + offset * q


def _pole(dt_s: float, tau_s: float) -> float:
    return -math.expm1(-dt_s / tau_s)


def lowpass_chain(x: np.ndarray, dt_s: float, taus: tuple[float, ...], zi: list | None = None
                  ) -> tuple[np.ndarray, list]:
    """``x`` through first-order low-passes (unit DC gain, time constants ``taus``, s) in series.

    ``zi``: the filters' states (``None``: all from zero). Returns the output and the
    final states (feed them to the next chunk).
    """
    out = np.asarray(x, float)
    zo = []
    for j, tau in enumerate(taus):
        a = _pole(dt_s, tau)
        z0 = np.zeros(1) if zi is None else zi[j]
        out, z1 = signal.lfilter([a], [1.0, a - 1.0], out, zi=z0)
        zo.append(z1)
    return out, zo


class DriftStage:
    """Charge ``q = lowpass_chain(u) * scale`` and :func:`drift_law` on the output, chunk by chunk.

    The filters start from zero at :meth:`reset` (nothing stored when the record starts).
    """

    def __init__(self, dt_s: float, taus: tuple[float, ...], q_scale: float, gain: float, offset: float) -> None:
        self.dt_s, self.taus = float(dt_s), tuple(float(t) for t in taus)
        self.q_scale, self.gain, self.offset = float(q_scale), float(gain), float(offset)
        self.zi: list | None = None

    def reset(self, x0: float) -> None:
        """No charge stored."""
        self.zi = None

    def charge(self, u: np.ndarray) -> np.ndarray:
        """The charge for the next input samples ``u`` (advances the state)."""
        q, self.zi = lowpass_chain(u, self.dt_s, self.taus, self.zi)
        return q * self.q_scale if self.q_scale != 1.0 else q

    def run(self, x: np.ndarray, u: np.ndarray | None = None) -> np.ndarray:
        """Output ``x`` with the drift of the input ``u`` (same samples; ``None``: ``x`` itself)."""
        x = np.asarray(x, float)
        q = self.charge(x if u is None else np.asarray(u, float))
        return drift_law(x, q, self.gain, self.offset)


def tau_min(pipe) -> float:
    """Shortest drift time constant the diagnosis tries, s: 20 dominant time constants, 30 % of the
    log, at least 50 samples."""
    return max(20.0 * pipe.t_dom, 0.3 * pipe.span_s, 50.0 * pipe.prep.dt_s)


def smoothing_s(pipe) -> float:
    """The generic form's pre-smoothing time constant, s: a tenth of :func:`tau_min`."""
    return 0.1 * tau_min(pipe)


def charge(x: np.ndarray, tau_s: float, dt_s: float, tau_smooth_s: float, u_s: float) -> np.ndarray:
    """The generic form's charge of a whole record: ``x`` pre-smoothed twice (``tau_smooth_s``), low-passed
    (``tau_s``), all from zero, over ``u_s``."""
    q, _ = lowpass_chain(x, dt_s, (tau_smooth_s, tau_smooth_s, tau_s))
    return q / u_s


_tau_min = tau_min


def _fit_drift(pipe: FitContext, effects: dict[str, EffectFit]) -> EffectFit | None:
    span = pipe.span_s
    tau_min = _tau_min(pipe)
    taus = span * np.array([0.15, 0.3, 0.6, 1.2, 2.5, 5.0])
    taus = np.unique(np.clip(taus, tau_min, None))

    # drift is slow: its weights are fitted on slow parts only, else its low-pass (a 90 degree
    # lag at any fast frequency) could pose as the quadrature part of a hysteresis loop
    n_min = min(r.u.size for r in pipe.prep.records)
    smooth = int(min(max(10.0 * pipe.t_dom, 0.25 * tau_min) * pipe.prep.rate_hz, n_min / 4))

    def ls_at(tau: float) -> EffectFit:
        def basis(ri, st):
            q = pipe.charge(st["x_sat"], tau)
            return [st["y_asym"] * q, pipe.y_s * q]

        base = {k: v for k, v in effects.items() if k != "charge_drift"}
        g, o = _ls(pipe, base, basis, smooth=smooth)
        return EffectFit("charge_drift", "output", (float(tau), float(g), float(o)))

    best = min((ls_at(float(t)) for t in taus), key=lambda f: _sse(pipe, _with(effects, f)))
    lt = math.log(best.theta[0])
    res = optimize.minimize_scalar(lambda v: _sse(pipe, _with(effects, ls_at(math.exp(v)))),
                                   bounds=(max(lt - 0.7, math.log(tau_min)), lt + 0.7), method="bounded",
                                   options={"maxiter": 12})
    cand = ls_at(math.exp(float(res.x)))
    if _sse(pipe, _with(effects, cand)) < _sse(pipe, _with(effects, best)):
        best = cand
    return best  # no refinement on the full residual: that would undo the slow-only fit


def fit_drift_on_repeats(pipe: FitContext, effects: dict[str, EffectFit], period_s: float
                         ) -> tuple[EffectFit, dict] | None:
    """Charge drift fitted on the change of the residual between repeats of the excitation.

    Where the input one period later is the same, a time-invariant model (any static map,
    lag or memory that has settled) predicts the same output, so the change of the
    residual between repeats is noise plus what varies in time: the drift's signature,
    free of the level-dependent part that a static map can take over when the levels of
    a log follow its history. The drift's weights are fitted by least squares on those
    changes over training pairs (both samples training), for each time constant of a grid.

    Returns
    -------
    (EffectFit, dict) or None
        The fit and ``{"train": (sse_before, sse_after, n, ||fitted||^2), "valid": (...)}``
        of the repeat changes (pairs with a validation sample and no final one); ``None`` when the
        log has too few matching pairs.
    """
    rec = pipe.prep.records[0]
    t, u = rec.t_s, rec.u
    tp = t + period_s
    inside = tp <= t[-1]
    same = np.zeros(t.size, bool)
    same[inside] = np.abs(np.interp(tp[inside], t, u) - u[inside]) <= 1e-3 * max(float(np.ptp(u)), 1e-300)
    k = np.clip(np.round((tp - t[0]) * pipe.prep.rate_hz).astype(int), 0, t.size - 1)
    pair_tr = same & rec.train & rec.train[k]
    pair_va = same & (rec.valid | rec.valid[k]) & ~rec.hold & ~rec.hold[k]
    if pair_tr.sum() < 50 or pair_va.sum() < 20:
        return None
    base = {k2: v for k2, v in effects.items() if k2 != "charge_drift"}
    st = pipe.stages(base, 0)

    def later(x: np.ndarray) -> np.ndarray:
        return np.interp(tp, t, x) - x

    d_r = later(rec.y - st["y"])
    tau_min = _tau_min(pipe)
    taus = np.unique(np.clip(pipe.span_s * np.array([0.15, 0.3, 0.6, 1.2, 2.5, 5.0]), tau_min, None))
    best = None
    for tau in taus:
        q = pipe.charge(st["x_sat"], float(tau))
        A = np.column_stack([later(st["y_asym"] * q), later(pipe.y_s * q)])
        sol = np.linalg.lstsq(A[pair_tr], d_r[pair_tr], rcond=None)[0]
        sse = sumsq(d_r[pair_tr] - A[pair_tr] @ sol)
        if best is None or sse < best[0]:
            best = (sse, float(tau), sol, A)
    _, tau, sol, A = best
    fit = EffectFit("charge_drift", "output", (tau, float(sol[0]), float(sol[1])))
    fitted = A @ sol

    def sse_pair(m: np.ndarray) -> tuple[float, float, int, float]:
        return sumsq(d_r[m]), sumsq(d_r[m] - fitted[m]), int(m.sum()), sumsq(fitted[m])

    return fit, {"train": sse_pair(pair_tr), "valid": sse_pair(pair_va)}



class DriftFamily(EffectFamily):
    """The ``charge_drift`` family (see the module's docstring)."""

    name = "charge_drift"
    slot = "output"
    variants = ("output",)
    truth_class = ChargeDrift
    bound_experiment = ("a longer log with a held voltage and a rest at zero: the drift's time course shows whether it "
                        "creeps and recovers as a charge would")

    def param_names(self, fit: EffectFit) -> tuple[str, ...]:
        """``("tau_s", "gain_per_charge", "offset_per_charge")`` (charge in input half-ranges)."""
        return ("tau_s", "gain_per_charge", "offset_per_charge")

    def stage(self, fit: EffectFit, scales: Scales, dt_s: float) -> DriftStage:
        """The generic form; the pre-smoothing from ``scales.tau_smooth_s`` or :func:`smoothing_s`."""
        ts = getattr(scales, "tau_smooth_s", None) or smoothing_s(scales)
        tau, g, o = fit.theta
        return DriftStage(dt_s, (ts, ts, tau), 1.0 / scales.u_s, g, scales.y_s * o)

    def truth_stage(self, effect: Effect, dt_s: float) -> DriftStage:
        """The truth form (``run(stroke, applied_kv)``)."""
        assert isinstance(effect, ChargeDrift)
        return DriftStage(dt_s, (effect.tau_s,), 1.0, -effect.gain_loss_per_kv, effect.offset_mm_per_kv)

    def fit(self, ctx: FitContext, effects: dict[str, EffectFit]) -> EffectFit | None:
        """Weights by least squares on slow parts for a grid of time constants, the time constant refined."""
        return _fit_drift(ctx, effects)

    def bounds(self, ctx: FitContext, fit: EffectFit) -> tuple[np.ndarray, np.ndarray]:
        """``tau_min <= tau <= 10 x the log``; free weights."""
        return np.array([tau_min(ctx), -np.inf, -np.inf]), np.array([10 * ctx.span_s, np.inf, np.inf])

    def describe(self, ctx: FitContext, fit: EffectFit, units: tuple[str, str],
                 effects: dict[str, EffectFit]) -> dict:
        """Time constant (s), gain change per input half-range, offset per input half-range (output unit)."""
        th = fit.theta
        return {"variant": fit.variant, "tau_s": th[0], "gain_change_per_input_half_range": th[1],
                "offset_per_input_half_range": th[2] * ctx.y_s, "unit": units[1]}


FAMILY = DriftFamily()
