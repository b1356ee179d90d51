"""The paper's dual-mode PID controller (section IV.B), discretised as the paper says.

e = r - z_hat. C+ (activation) acts when e >= 0, C- (relaxation) when e < 0, each a
parallel PID, C(s) = Kp + Ki/s + Kd s. Discretisation at Ts = 0.005 s:

- proportional: Kp e_k
- integral, trapezoidal rule: I_k = I_{k-1} + Ki Ts (e_k + e_{k-1}) / 2
- derivative, backward rectangular rule: D_k = Kd (e_k - e_{k-1}) / Ts

Bumpless switching: the integrator stores its *contribution* I_k in kV, not the
integral of the error, so a change of Ki at a C+/C- switch changes only the slope of
I from then on and never makes it jump.

Anti-windup (named as in control_toolbox): ``"conditional_integration"`` (default:
the integrator is not updated while the output is saturated and the error would
push it further into saturation), ``"back_calculation"`` (the saturation excess is
fed back into the integrator with gain Ts/Tt), or ``"none"``.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, replace

from hasel import paper
from hasel.errors import BadInputError, UnsafeParameterError
from hasel.validate import finite, positive

__all__ = ["PidGains", "DualModeConfig", "PidOutput", "DualModePid", "ANTI_WINDUP"]

ANTI_WINDUP = ("conditional_integration", "back_calculation", "none")


@dataclass(frozen=True)
class PidGains:
    """Parallel PID gains: kp in kV/mm, ki in kV/(mm s), kd in kV s/mm."""

    kp: float
    ki: float
    kd: float

    def __post_init__(self) -> None:
        for name in ("kp", "ki", "kd"):
            v = finite(name, getattr(self, name))
            if v < 0.0:
                raise BadInputError(f"{name} must be >= 0, got {v}")


@dataclass(frozen=True)
class DualModeConfig:
    """Configuration of the dual-mode PID.

    Attributes
    ----------
    plus, minus : PidGains
        C+ (e >= 0, activation) and C- (e < 0, relaxation); the paper's by default.
    period_s : float
        Loop period Ts, seconds (0.005 s: 200 Hz).
    v_min_kv, v_max_kv : float
        Output limits the amplifier enforces, kV; used for anti-windup. v_max_kv can
        never exceed the 9 kV ceiling.
    anti_windup : str
        One of :data:`ANTI_WINDUP`.
    tracking_time_s : float
        Tt of back-calculation, seconds.
    """

    plus: PidGains = PidGains(*paper.C_PLUS)
    minus: PidGains = PidGains(*paper.C_MINUS)
    period_s: float = paper.LOOP_PERIOD_S
    v_min_kv: float = 0.0
    v_max_kv: float = paper.V_MAX_KV
    anti_windup: str = "conditional_integration"
    tracking_time_s: float = 0.05

    def __post_init__(self) -> None:
        positive("period_s", self.period_s)
        positive("tracking_time_s", self.tracking_time_s)
        lo, hi = finite("v_min_kv", self.v_min_kv), finite("v_max_kv", self.v_max_kv)
        if hi > paper.V_MAX_KV:
            raise UnsafeParameterError(f"v_max_kv={hi} exceeds the {paper.V_MAX_KV} kV breakdown ceiling")
        if not lo < hi:
            raise BadInputError(f"v_min_kv ({lo}) must be below v_max_kv ({hi})")
        if self.anti_windup not in ANTI_WINDUP:
            raise BadInputError(f"anti_windup must be one of {ANTI_WINDUP}, got {self.anti_windup!r}")


@dataclass(frozen=True)
class PidOutput:
    """One update of the controller. Terms in kV; ``mode`` is +1 (C+) or -1 (C-)."""

    output_kv: float
    unclamped_kv: float
    error_mm: float
    mode: int
    p_kv: float
    i_kv: float
    d_kv: float
    saturated: bool


class DualModePid:
    """The dual-mode PID; call :meth:`update` once per loop period."""

    def __init__(self, config: DualModeConfig | None = None) -> None:
        self.config = config or DualModeConfig()
        self.reset()

    def reset(self, integral_kv: float = 0.0) -> None:
        """Clear the memory; optionally preload the integral contribution (kV)."""
        self.i_kv = float(integral_kv)
        self.prev_error: float | None = None
        self.mode = 1

    def reconfigure(self, **changes: object) -> None:
        """Change configuration fields at run time (validated); the state is kept."""
        self.config = replace(self.config, **changes)  # type: ignore[arg-type]

    def hold(self) -> None:
        """Stale or missing input: keep the integrator as is and forget the last error,
        so the derivative does not kick when input returns."""
        self.prev_error = None

    def update(self, reference_mm: float, measured_mm: float) -> PidOutput:
        """One step: reference and measurement in mm -> command in kV (within limits).

        A non-finite reference or measurement holds the controller and returns a
        command of 0 kV (never NaN).
        """
        cfg = self.config
        if not (math.isfinite(reference_mm) and math.isfinite(measured_mm)):
            self.hold()
            return PidOutput(0.0, 0.0, math.nan, self.mode, 0.0, self.i_kv, 0.0, True)
        e = reference_mm - measured_mm
        self.mode = 1 if e >= 0.0 else -1
        g = cfg.plus if self.mode > 0 else cfg.minus
        ts = cfg.period_s
        e_prev = e if self.prev_error is None else self.prev_error
        p = g.kp * e
        d = g.kd * (e - e_prev) / ts
        i_candidate = self.i_kv + g.ki * ts * 0.5 * (e + e_prev)
        u = p + i_candidate + d
        u_sat = min(max(u, cfg.v_min_kv), cfg.v_max_kv)
        saturated = u_sat != u
        if cfg.anti_windup == "conditional_integration":
            # integrate unless saturated and the error pushes further into the limit
            pushes = (u > cfg.v_max_kv and e > 0.0) or (u < cfg.v_min_kv and e < 0.0)
            if not pushes:
                self.i_kv = i_candidate
        elif cfg.anti_windup == "back_calculation":
            self.i_kv = i_candidate + (ts / cfg.tracking_time_s) * (u_sat - u)
        else:
            self.i_kv = i_candidate
        self.prev_error = e
        return PidOutput(u_sat, u, e, self.mode, p, self.i_kv, d, saturated)
