"""The closed loop without ROS: the reference the node graph is tested against.

Per 200 Hz tick k (t_k = k Ts), exactly as the nodes do it:

1. the MCU reads the sensors (laser stroke, 555 elapsed time) at t_k;
2. the driver maps the elapsed time to mm through the calibration;
3. the 40 Hz low-pass filters that strain-sensor stroke;
4. the dual-mode PID computes a command from the reference and the chosen feedback
   (laser, or filtered strain sensor);
5. the amplifier limits clamp it (hard 9 kV ceiling);
6. the plant holds it over [t_k, t_{k+1}) at 10 kHz.
"""
from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from hasel import paper
from hasel.amplifier import HvLimits
from hasel.calibration import Calibration
from hasel.errors import BadInputError
from hasel.faults import PlausibilityGate
from hasel.filters import LowPass
from hasel.pid import DualModeConfig, DualModePid, PidOutput
from hasel.sensors import StrainConfig
from hasel.simulator import PlantSimulator

__all__ = ["FEEDBACKS", "LoopConfig", "LoopResult", "default_calibration", "step_reference",
           "run_closed_loop"]

FEEDBACKS = ("laser", "strain")


def default_calibration(strain: StrainConfig | None = None) -> Calibration:
    """The ideal line of a strain sensor (what a perfect calibration would find)."""
    s = strain or StrainConfig()
    return Calibration.line(1.0 / s.us_per_mm, -s.rest_pulse_us / s.us_per_mm, "ideal")


def step_reference(sequence_mm: list[float], hold_s: float) -> Callable[[float], float]:
    """Reference r(t) in mm holding each value of ``sequence_mm`` for ``hold_s`` seconds."""
    seq = [float(x) for x in sequence_mm]
    if not seq:
        raise BadInputError("the reference sequence is empty")
    if not np.all(np.isfinite(seq)):
        raise BadInputError(f"the reference sequence must be finite, got {seq}")

    def r(t: float) -> float:
        return seq[min(int(t / hold_s + 1e-9), len(seq) - 1)]

    return r


@dataclass(frozen=True)
class LoopConfig:
    """What the closed loop runs with (the paper's setup by default)."""

    feedback: str = "laser"
    pid: DualModeConfig = field(default_factory=DualModeConfig)
    limits: HvLimits = field(default_factory=HvLimits)
    calibration: Calibration | None = None
    filter_cutoff_hz: float = paper.FILTER_CUTOFF_HZ

    def __post_init__(self) -> None:
        if self.feedback not in FEEDBACKS:
            raise BadInputError(f"feedback must be one of {FEEDBACKS}, got {self.feedback!r}")


@dataclass
class LoopResult:
    """Arrays of a closed-loop run. Tick arrays at 200 Hz, sample arrays at 10 kHz."""

    t_s: np.ndarray
    reference_mm: np.ndarray
    laser_mm: np.ndarray
    strain_mm: np.ndarray
    filtered_mm: np.ndarray
    feedback_mm: np.ndarray
    requested_kv: np.ndarray
    command_kv: np.ndarray
    mode: np.ndarray
    i_kv: np.ndarray
    sample_t_s: np.ndarray
    applied_kv: np.ndarray
    true_stroke_mm: np.ndarray
    sample_laser_mm: np.ndarray
    elapsed_us: np.ndarray


def run_closed_loop(sim: PlantSimulator, reference: Callable[[float], float], duration_s: float,
                    config: LoopConfig | None = None) -> LoopResult:
    """Run the loop for ``duration_s`` seconds on ``sim`` and return every signal."""
    cfg = config or LoopConfig()
    cal = cfg.calibration or default_calibration(sim.strain.config)
    lp = LowPass(cfg.filter_cutoff_hz, 1.0 / sim.period_s)
    pid = DualModePid(cfg.pid)
    gate = PlausibilityGate()
    command = 0.0
    n = int(round(duration_s / sim.period_s))
    rec = {k: np.empty(n) for k in ("t", "r", "laser", "strain", "filt", "fb", "req", "cmd", "mode", "i")}
    blocks = []
    for k in range(n):
        rd = sim.latest()
        z_strain = float(cal(rd.elapsed_us))
        z_filt = lp(z_strain)
        fb = rd.laser_mm if cfg.feedback == "laser" else z_filt
        r = reference(rd.t_s)
        if gate.accept(fb):
            out = pid.update(r, fb)
            command = out.output_kv
        else:  # as the controller node: a rejected sample holds the last command
            out = PidOutput(command, command, math.nan, pid.mode, 0.0, pid.i_kv, 0.0, False)
        applied = cfg.limits.apply(command)
        blocks.append(sim.step(applied.applied_kv))
        for key, val in (("t", rd.t_s), ("r", r), ("laser", rd.laser_mm), ("strain", z_strain),
                         ("filt", z_filt), ("fb", fb), ("req", out.output_kv),
                         ("cmd", applied.applied_kv), ("mode", out.mode), ("i", out.i_kv)):
            rec[key][k] = val
    cat = (lambda a: np.concatenate(a)) if blocks else (lambda a: np.empty(0))
    return LoopResult(rec["t"], rec["r"], rec["laser"], rec["strain"], rec["filt"], rec["fb"],
                      rec["req"], rec["cmd"], rec["mode"], rec["i"],
                      cat([b.times_s for b in blocks]), cat([b.applied_kv for b in blocks]),
                      cat([b.true_stroke_mm for b in blocks]), cat([b.laser_mm for b in blocks]),
                      cat([b.elapsed_us for b in blocks]))
