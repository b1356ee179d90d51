"""The closed loop without ROS: the reference the node graph is tested against.

It composes the same core objects the nodes call, so the graph and this loop decide
alike by construction, faults included. Per 200 Hz tick k (t_k = k Ts):

1. the MCU reads the sensors (laser stroke, 555 elapsed time) at t_k;
2. the driver maps the elapsed time to mm (:class:`hasel.channels.StrainChannel`);
3. the 40 Hz low-pass filters that stroke (:class:`hasel.channels.FilterChannel`);
4. the controller core (:class:`hasel.controller.ControllerCore`) decides on the
   feedback (laser, or filtered strain): a command, a held command, or none; with no
   sample, its stale check runs as the node's deadline timer would;
5. the amplifier core (:class:`hasel.amplifier.AmplifierCore`) limits the request
   (hard 9 kV), or, with none, runs its watchdog as the node's timer would;
6. the plant holds the amplifier's first output of the tick over [t_k, t_{k+1}) at
   10 kHz, or, with none, what the DAC holds (:class:`hasel.amplifier.HeldOutput`).

:class:`LoopFaults` injects sensor and link faults (lost or corrupted samples) at
the points where a graph would see them, for studying the fault handling offline.
"""
from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass, field

import numpy as np

from hasel import paper
from hasel.amplifier import AmplifierCore, HeldOutput, HvLimits, Watchdog
from hasel.calibration import Calibration
from hasel.channels import FilterChannel, StrainChannel, default_calibration
from hasel.controller import ControllerCore, ReferenceSchedule
from hasel.errors import BadInputError
from hasel.faults import PlausibilityGate, StuckDetector
from hasel.metrics import reference_starts
from hasel.pid import DualModeConfig, DualModePid
from hasel.simulator import PlantSimulator
from hasel.timeconv import ns_to_s, s_to_ns

__all__ = ["FEEDBACKS", "LoopConfig", "LoopFaults", "LoopResult", "default_calibration", "step_reference",
           "run_closed_loop"]

FEEDBACKS = ("laser", "strain")

Fault = Callable[[float, float], "float | None"]


def step_reference(sequence_mm: list[float], hold_s: float | Sequence[float]) -> ReferenceSchedule:
    """Reference r(t) in mm holding each value of ``sequence_mm`` for ``hold_s`` seconds from t = 0
    (one hold for every value, or one per value: :func:`hasel.metrics.reference_starts`).

    The schedule the reference node publishes (value i stamped at its start); call it
    with a time in s for the value then.
    """
    seq = [float(x) for x in sequence_mm]
    if not seq:
        raise BadInputError("the reference sequence is empty")
    if not np.all(np.isfinite(seq)):
        raise BadInputError(f"the reference sequence must be finite, got {seq}")
    schedule = ReferenceSchedule()
    for t, r in zip(reference_starts(len(seq), hold_s), seq):
        schedule.set(s_to_ns(float(t)), r)
    return schedule


@dataclass(frozen=True)
class LoopConfig:
    """What the closed loop runs with (the paper's setup and the nodes' defaults)."""

    feedback: str = "laser"
    pid: DualModeConfig = field(default_factory=DualModeConfig)
    limits: HvLimits = field(default_factory=HvLimits)
    calibration: Calibration | None = None
    filter_cutoff_hz: float = paper.FILTER_CUTOFF_HZ
    stale_periods: float = 3.0
    gate_max_step_mm: float = 1.5
    watchdog_periods: float = 3.0

    def __post_init__(self) -> None:
        if self.feedback not in FEEDBACKS:
            raise BadInputError(f"feedback must be one of {FEEDBACKS}, got {self.feedback!r}")


@dataclass(frozen=True)
class LoopFaults:
    """Faults injected into the loop, each ``rule(t_s, value) -> value`` (None: the message is lost).

    ``timing``: the 555 reading (us) before the driver; ``feedback``: the stroke (mm)
    the controller receives; ``command``: the request (kV) between controller and
    amplifier.
    """

    timing: Fault | None = None
    feedback: Fault | None = None
    command: Fault | None = None


@dataclass
class LoopResult:
    """Arrays of a closed-loop run. Tick arrays at 200 Hz, sample arrays at 10 kHz.

    Per tick: ``requested_kv`` the controller's request (NaN: none), ``command_kv`` the
    voltage the plant held over the period, ``reason`` the amplifier's reason for its
    output that tick (-1: no output, the DAC held), ``stale`` the controller's state
    after the tick. Lost samples are NaN in ``strain_mm``/``filtered_mm``/``feedback_mm``.
    """

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
    reason: np.ndarray = field(default_factory=lambda: np.empty(0, dtype=np.int64))
    stale: np.ndarray = field(default_factory=lambda: np.empty(0, dtype=bool))


def _inject(rule: Fault | None, t_s: float, value: float) -> float | None:
    return value if rule is None else rule(t_s, value)


def run_closed_loop(sim: PlantSimulator, reference: Callable[[float], float], duration_s: float,
                    config: LoopConfig | None = None, faults: LoopFaults | None = None) -> LoopResult:
    """Run the loop for ``duration_s`` seconds on ``sim`` and return every signal.

    ``reference`` is a :class:`~hasel.controller.ReferenceSchedule` (see
    :func:`step_reference`) or any function of time (s) -> mm, read at each tick.
    """
    cfg = config or LoopConfig()
    flt = faults or LoopFaults()
    strain = StrainChannel(cfg.calibration or default_calibration(sim.strain.config))
    lowpass = FilterChannel(cfg.filter_cutoff_hz, 1.0 / sim.period_s)
    ctl = ControllerCore(DualModePid(cfg.pid), PlausibilityGate(max_step_mm=cfg.gate_max_step_mm),
                         StuckDetector(), cfg.stale_periods)
    amp = AmplifierCore(cfg.limits, Watchdog(sim.period_s, cfg.watchdog_periods))
    dac = HeldOutput(3)
    scheduled = isinstance(reference, ReferenceSchedule)
    if scheduled:
        ctl.references = reference
    period_ns = s_to_ns(sim.period_s)
    n = int(round(duration_s / sim.period_s))
    rec = {k: np.empty(n) for k in ("t", "r", "laser", "strain", "filt", "fb", "req", "cmd", "mode", "i")}
    reason = np.empty(n, dtype=np.int64)
    stale = np.empty(n, dtype=bool)
    nan = float("nan")
    blocks = []
    for k in range(n):
        rd = sim.latest()
        t_ns = sim.tick * period_ns  # the plant's stamp of this tick
        t_s = ns_to_s(t_ns)  # the nodes' clock in seconds
        if not scheduled:
            ctl.references.set(t_ns, reference(rd.t_s))
        us = _inject(flt.timing, t_s, rd.elapsed_us)
        z_strain = nan if us is None else strain(us)
        z_filt = nan if us is None else lowpass(z_strain)
        fb = rd.laser_mm if cfg.feedback == "laser" else (None if us is None else z_filt)
        fb = None if fb is None else _inject(flt.feedback, t_s, fb)
        # a message of this tick, or else the deadline timer (the cores decide alike in either order)
        req = None
        if fb is None:
            ctl.poll(t_ns)
        else:
            req = ctl.on_sample(t_ns, fb).command_kv
        req = None if req is None else _inject(flt.command, t_s, req)
        outs = amp.command(t_s, req) if req is not None else (amp.poll(t_s),)
        first = outs[0]  # the plant steps with the tick's first output; a later one comes too late
        applied = dac.fresh(first[0].applied_kv) if first is not None else dac.missing()
        reason[k] = first[0].reason if first is not None else -1
        stale[k] = ctl.stale
        blocks.append(sim.step(applied))
        for key, val in (("t", rd.t_s), ("r", ctl.references.at(t_ns)), ("laser", rd.laser_mm),
                         ("strain", z_strain), ("filt", z_filt), ("fb", nan if fb is None else fb),
                         ("req", nan if req is None else req), ("cmd", applied), ("mode", ctl.pid.mode),
                         ("i", ctl.pid.i_kv)):
            rec[key][k] = val
    cat = (lambda a: np.concatenate(a)) if blocks else (lambda a: np.empty(0))
    return LoopResult(rec["t"], rec["r"], rec["laser"], rec["strain"], rec["filt"], rec["fb"],
                      rec["req"], rec["cmd"], rec["mode"], rec["i"],
                      cat([b.times_s for b in blocks]), cat([b.applied_kv for b in blocks]),
                      cat([b.true_stroke_mm for b in blocks]), cat([b.laser_mm for b in blocks]),
                      cat([b.elapsed_us for b in blocks]), reason, stale)
