"""``hasel tune``: design the dual-mode gains C+ and C- on a plant model, offline.

The design runs the ROS-free closed loop (:func:`hasel.loop.run_closed_loop`: the same
40 Hz filter, 9 kV ceiling, amplifier and controller cores the node graph runs) on the
step sequence of the demo and scores each gain set on the true stroke's 10-90 % rise,
5 % settling and overshoot of every step against per-direction targets (activation
steps for C+, relaxation steps for C-; defaults: the paper's Table II activation
figures with laser feedback for both).

The optimiser is a coordinate search over the logarithms of the six gains: each gain
in turn is multiplied and divided by a factor; a move is kept if it lowers the score on
the model, no step that settled with the start gains settles later or overshoots more,
and every step that settles on the model still settles with the plant's gain 20 % lower
and 25 % higher (the robustness check); when no move helps, the factor shrinks. It is
small, deterministic and every accepted move can be printed.

The score of a step (lower is better) is the sum over rise, settling and overshoot of
the relative excess over its target, ``max(0, m / target - 1)``, plus a tenth of
``m / target`` so that among designs that meet every target the faster, less
overshooting one wins. A step that does not settle within its hold costs 5 more, and a
controller demand above the 9 kV ceiling (before the amplifier clamps it) costs 10 per
kV beyond it: a design that needs more than the actuator may get is penalised, and the
tuned gains are refused if they still need it.

Gains are read and written as a ROS 2 parameter file that ``pid_controller`` loads
with ``--ros-args --params-file FILE`` (parameters ``kp_plus`` ... ``kd_minus``).
"""
from __future__ import annotations

import argparse
import json
import math
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from hasel import paper
from hasel.errors import BadInputError, HaselError
from hasel.metrics import StepMetrics, steps_from_sequence
from hasel.pid import DualModeConfig, PidGains

__all__ = ["GAIN_KEYS", "NODE_NAME", "Target", "Targets", "parse_targets", "PAPER_GAINS", "gains_params",
           "read_gains", "write_gains", "Evaluation", "evaluate", "TuneResult", "tune", "add_arguments", "run"]

#: The controller node's gain parameters (hasel_control/controller_node.py), in the order kp, ki, kd.
GAIN_KEYS = ("kp_plus", "ki_plus", "kd_plus", "kp_minus", "ki_minus", "kd_minus")
#: The controller node's name: the key its parameters sit under in a parameter file.
NODE_NAME = "pid_controller"
#: The gains the node accepts (its declared range), kV/mm, kV/(mm s), kV s/mm.
GAIN_RANGE = (0.0, 1000.0)
#: The paper's gains (14)-(15) as parameters.
PAPER_GAINS = dict(zip(GAIN_KEYS, paper.C_PLUS + paper.C_MINUS))
DIRECTIONS = ("activation", "relaxation")
_UNSETTLED_COST = 5.0
_OVER_CEILING_COST_PER_KV = 10.0
_ROBUST_SCALES = (0.8, 1.25)


@dataclass(frozen=True)
class Target:
    """Targets of one direction: 10-90 % rise (s), 5 % settling (s), overshoot (% of the step)."""

    rise_s: float
    settling_s: float
    overshoot_pct: float


@dataclass(frozen=True)
class Targets:
    """Per-direction targets: ``activation`` (C+, rising steps) and ``relaxation`` (C-, falling steps)."""

    activation: Target
    relaxation: Target

    def of(self, mode: str) -> Target:
        """The target of ``mode`` ("activation" or "relaxation")."""
        return self.activation if mode == "activation" else self.relaxation

    def to_json(self) -> dict:
        """``{"activation": {...}, "relaxation": {...}}`` in s and %."""
        return {d: vars(self.of(d)).copy() for d in DIRECTIONS}


def default_targets() -> Targets:
    """The paper's Table II activation figures with laser feedback, for both directions."""
    rise, settle, over = paper.TABLE_II[("activation", "laser")]
    t = Target(float(rise), float(settle), float(over))
    return Targets(t, t)


_METRIC = {"rise": "rise_s", "settling": "settling_s", "overshoot": "overshoot_pct"}


def parse_targets(text: str | None) -> Targets:
    """``"rise=0.03,overshoot=5,relaxation.settling=0.3"`` -> :class:`Targets` (others: defaults).

    A bare name sets both directions; ``activation.NAME`` / ``relaxation.NAME`` one. Rise
    and settling in s, overshoot in %; each must be positive and finite.
    """
    t = default_targets()
    vals = {d: vars(t.of(d)).copy() for d in DIRECTIONS}
    for item in filter(None, (s.strip() for s in (text or "").split(","))):
        key, sep, value = item.partition("=")
        dirs, _, name = key.strip().rpartition(".")
        if not sep or name not in _METRIC or dirs not in ("", *DIRECTIONS):
            raise BadInputError(f"--targets: cannot read {item!r}; write NAME=VALUE or DIRECTION.NAME=VALUE with "
                                f"NAME in rise, settling, overshoot and DIRECTION in activation, relaxation")
        try:
            v = float(value)
        except ValueError:
            v = math.nan
        if not (math.isfinite(v) and v > 0):
            raise BadInputError(f"--targets: {key.strip()} must be a positive number, got {value.strip()!r}")
        for d in (DIRECTIONS if not dirs else (dirs,)):
            vals[d][_METRIC[name]] = v
    return Targets(Target(**vals["activation"]), Target(**vals["relaxation"]))


# ---------------------------------------------------------------- parameter files

def gains_params(plus: PidGains, minus: PidGains) -> dict[str, float]:
    """The controller node's gain parameters of C+ and C-."""
    return dict(zip(GAIN_KEYS, (plus.kp, plus.ki, plus.kd, minus.kp, minus.ki, minus.kd)))


def _split(params: dict[str, float]) -> tuple[PidGains, PidGains]:
    p = {**PAPER_GAINS, **params}
    return PidGains(*(p[k] for k in GAIN_KEYS[:3])), PidGains(*(p[k] for k in GAIN_KEYS[3:]))


def read_gains(path: str | Path) -> dict[str, float]:
    """The gain parameters of a ROS 2 parameter file for ``pid_controller``.

    The file holds ``NODE: {ros__parameters: {...}}`` with NODE ``pid_controller``,
    ``/pid_controller`` or ``/**``; the parameters are any of :data:`GAIN_KEYS` (others
    keep the paper's value). Anything the node would refuse (another key, an integer or
    non-numeric or negative gain, a gain beyond the node's range) raises :class:`BadInputError` with one line.
    """
    import yaml

    p = Path(path)
    where = f"gains file {p}"
    try:
        doc = yaml.safe_load(p.read_text())
    except FileNotFoundError:
        raise BadInputError(f"{where}: no such file") from None
    except (OSError, UnicodeDecodeError) as err:
        raise BadInputError(f"{where}: cannot read it ({err})") from None
    except yaml.YAMLError as err:
        mark = getattr(err, "problem_mark", None)
        at = f" at line {mark.line + 1}" if mark is not None else ""
        raise BadInputError(f"{where}: not valid YAML{at}") from None
    node, body = next(iter(doc.items())) if isinstance(doc, dict) and doc else (None, None)
    if isinstance(doc, dict) and set(doc) & set(GAIN_KEYS):
        raise BadInputError(f"{where}: the gains must sit under '{NODE_NAME}:' and 'ros__parameters:' "
                            "(a ROS 2 parameter file)")
    if not isinstance(doc, dict) or len(doc) != 1:
        raise BadInputError(f"{where}: expected one node entry, e.g. '{NODE_NAME}: {{ros__parameters: "
                            f"{{kp_plus: 1.15, ...}}}}'")
    if node not in (NODE_NAME, "/" + NODE_NAME, "/**"):
        raise BadInputError(f"{where}: node {node!r} is not {NODE_NAME}, /{NODE_NAME} or /**")
    if not isinstance(body, dict) or set(body) != {"ros__parameters"} or not isinstance(body["ros__parameters"], dict):
        raise BadInputError(f"{where}: {node} must hold only 'ros__parameters:' with the gains under it")
    params = body["ros__parameters"]
    out = {}
    for key, value in params.items():
        if key not in GAIN_KEYS:
            raise BadInputError(f"{where}: unknown parameter {key!r}; the gains are {', '.join(GAIN_KEYS)}")
        if isinstance(value, int) and not isinstance(value, bool):
            # the node declares doubles and refuses an integer: say so now, not at its start
            raise BadInputError(f"{where}: {key} must be written as a float ({value}.0): pid_controller refuses "
                                "an integer for a double parameter")
        if not isinstance(value, float) or not math.isfinite(value):
            raise BadInputError(f"{where}: {key} must be a finite number, got {value!r}")
        if not GAIN_RANGE[0] <= value <= GAIN_RANGE[1]:
            raise BadInputError(f"{where}: {key} = {value} is outside the node's range {GAIN_RANGE[0]:g} .. "
                                f"{GAIN_RANGE[1]:g}")
        out[key] = value
    if not out:
        raise BadInputError(f"{where}: no gain under ros__parameters")
    return out


def write_gains(path: str | Path, params: dict[str, float], comment: str = "") -> Path:
    """Write the gains as a parameter file for ``pid_controller`` (``comment``: lines put on top as # ...)."""
    from hasel.outputs import write_text

    head = "".join(f"# {line}\n" for line in comment.splitlines())
    body = "".join(f"    {k}: {float(params[k])!r}\n" for k in GAIN_KEYS if k in params)
    return write_text(path, f"{head}{NODE_NAME}:\n  ros__parameters:\n{body}")


# ---------------------------------------------------------------- evaluation on the model

class _ScaledOutput:
    """An actuator whose stroke is scaled by ``gain`` (the robustness check's plant gain error)."""

    def __init__(self, inner, gain: float) -> None:
        self.inner, self.gain = inner, gain
        self.rate_hz = inner.rate_hz
        self.strain_curve = getattr(inner, "strain_curve", None)

    def reset(self, command_kv: float = 0.0) -> None:
        """Put the inner model at rest."""
        self.inner.reset(command_kv)

    def run(self, command_kv: np.ndarray):
        """The inner model's samples with the stroke scaled."""
        from hasel.plant import ActuatorSamples

        out = self.inner.run(command_kv)
        return ActuatorSamples(out.applied_kv, out.stroke_mm * self.gain)


@dataclass(frozen=True)
class Evaluation:
    """One gain set on one plant: per-step metrics, the controller's peak demand (kV, before the
    9 kV clamp), the largest request sent (kV), the seconds at the ceiling, and the score."""

    steps: list[StepMetrics]
    peak_demand_kv: float
    max_requested_kv: float
    ceiling_s: float
    score: float

    def to_json(self) -> dict:
        """JSON-ready dict (NaN as None)."""
        return {"steps": [m.to_json() for m in self.steps], "peak_demand_kv": self.peak_demand_kv,
                "max_requested_kv": self.max_requested_kv, "ceiling_s": self.ceiling_s, "score": self.score}


def _peak_demand(res, cfg: DualModeConfig) -> float:
    """The largest PID output before the clamp, kV, rebuilt from the recorded integrator state.

    Each tick with an update: u = kp e + I_candidate + kd (e - e_prev) / Ts, with
    I_candidate = I_prev + ki Ts (e + e_prev) / 2 (what the PID computes before deciding
    whether to keep it), with the gains of the mode that tick used.
    """
    ts = cfg.period_s
    r, fb, req = res.reference_mm, res.feedback_mm, res.requested_kv
    valid = np.isfinite(r) & np.isfinite(fb) & np.isfinite(req)
    e = r - fb
    e_prev = np.where(np.concatenate([[False], valid[:-1]]), np.concatenate([[0.0], e[:-1]]), e)
    i_prev = np.concatenate([[0.0], res.i_kv[:-1]])
    plus = e >= 0
    kp = np.where(plus, cfg.plus.kp, cfg.minus.kp)
    ki = np.where(plus, cfg.plus.ki, cfg.minus.ki)
    kd = np.where(plus, cfg.plus.kd, cfg.minus.kd)
    u = kp * e + i_prev + ki * ts * 0.5 * (e + e_prev) + kd * (e - e_prev) / ts
    u = u[valid]
    return float(u.max()) if u.size else 0.0


def step_score(m: StepMetrics, target: Target, window_s: float) -> float:
    """Score of one step against its target (0 when it meets every target exactly; lower is better).

    A step that never reaches 90 % or never settles within its ``window_s`` (s) counts
    that metric as ``window_s`` and costs :data:`_UNSETTLED_COST` more, so the score
    still tells a poor design from a worse one.
    """
    total = 0.0
    for value, goal in ((m.rise_s, target.rise_s), (m.settling_s, target.settling_s),
                        (m.overshoot_pct, target.overshoot_pct)):
        if not math.isfinite(value):
            value, total = window_s, total + _UNSETTLED_COST
        total += max(0.0, value / goal - 1.0) + 0.1 * value / goal
    return total


def evaluate(make_plant: Callable[[], object], params: dict[str, float], targets: Targets,
             sequence_mm: list[float], hold_s: float, *, feedback: str = "laser", seed: int = 0,
             plant_gain: float = 1.0) -> Evaluation:
    """Run the offline closed loop with ``params`` on a fresh plant from ``make_plant`` and score it.

    ``plant_gain`` scales the plant's stroke (1: the model as it is). Metrics are taken on
    the true stroke, as ``hasel steps`` reports them; the score is the mean step score
    plus the ceiling penalty (see the module's docstring).
    """
    from hasel.loop import LoopConfig, run_closed_loop, step_reference
    from hasel.simulator import PlantSimulator

    plus, minus = _split(params)
    cfg = DualModeConfig(plus=plus, minus=minus)
    act = make_plant()
    if plant_gain != 1.0:
        act = _ScaledOutput(act, plant_gain)
    sim = PlantSimulator(act, seed=seed, strain_curve=getattr(act, "strain_curve", None))
    res = run_closed_loop(sim, step_reference(sequence_mm, hold_s), hold_s * len(sequence_mm),
                          LoopConfig(feedback=feedback, pid=cfg))
    steps = steps_from_sequence(res.sample_t_s, res.true_stroke_mm, sequence_mm, hold_s)
    peak = _peak_demand(res, cfg)
    req = res.requested_kv[np.isfinite(res.requested_kv)]
    at_ceiling = float(np.sum(req >= paper.V_MAX_KV - 1e-9) * sim.period_s)
    score = float(np.mean([step_score(m, targets.of(m.mode), hold_s) for m in steps]))
    score += _OVER_CEILING_COST_PER_KV * max(0.0, peak - paper.V_MAX_KV)
    return Evaluation(steps, peak, float(req.max()) if req.size else 0.0, at_ceiling, score)


# ---------------------------------------------------------------- the search

@dataclass
class TuneResult:
    """What :func:`tune` found: start and tuned gains with their evaluations, the robustness
    check of the tuned gains (plant gain -> evaluation), the accepted moves, the evaluations run."""

    start: dict[str, float]
    start_eval: Evaluation
    tuned: dict[str, float]
    tuned_eval: Evaluation
    robustness: dict[float, Evaluation] = field(default_factory=dict)
    moves: list[str] = field(default_factory=list)
    evaluations: int = 0
    wall_s: float = 0.0

    @property
    def robust(self) -> bool:
        """True if every step that settles on the model settles with the plant's gain off by the checked factors."""
        return all(_robust(self.tuned_eval, e) for e in self.robustness.values())


def _robust(on_model: Evaluation, perturbed: Evaluation) -> bool:
    """True if every step that settles on the model also settles on the perturbed plant,
    within the 9 kV ceiling."""
    return perturbed.peak_demand_kv <= paper.V_MAX_KV and all(
        math.isfinite(p.settling_s) for m, p in zip(on_model.steps, perturbed.steps) if math.isfinite(m.settling_s))


def tune(make_plant: Callable[[], object], *, start: dict[str, float] | None = None,
         targets: Targets | None = None, sequence_mm: list[float] | None = None, hold_s: float = 1.0,
         feedback: str = "laser", seed: int = 0, max_evals: int = 120, factor: float = 2.0,
         min_factor: float = 1.05, log: Callable[[str], None] | None = None) -> TuneResult:
    """Coordinate search over the log-gains from ``start`` (default the paper's) on the plant model.

    Each round tries every gain times and divided by ``factor``; a move that lowers the
    score is kept if no step that settled with ``start`` settles later or overshoots more,
    and every step that settles on the model still settles (within the 9 kV ceiling) with
    the plant's gain scaled by 0.8 and 1.25; a kept move is repeated with the step squared
    while it helps. A round without a kept move shrinks ``factor`` to its square root; the
    search ends below ``min_factor`` or after ``max_evals`` loop runs. Gains stay in the
    node's range; a gain of 0 stays 0 (that term is off).
    """
    t0 = time.monotonic()
    targets = targets or default_targets()
    seq = list(sequence_mm or paper.STEP_SEQUENCE_MM)
    say = log or (lambda _m: None)
    start_params = {**PAPER_GAINS, **(start or {})}
    count = [0]

    def run(p: dict[str, float], g: float = 1.0) -> Evaluation:
        count[0] += 1
        return evaluate(make_plant, p, targets, seq, hold_s, feedback=feedback, seed=seed, plant_gain=g)

    first = run(start_params)

    def acceptable(key: str, f: float, e: Evaluation, best: Evaluation, cand: dict[str, float]) -> bool:
        """Better score, no step worse than the start's, and robust to the plant gain."""
        if e.score >= best.score - 1e-9:
            return False
        if not _no_worse(e, first):
            say(f"  {key} x{f:.3g}: score {e.score:.3f}, but a step settles or overshoots worse than at the "
                "start; not kept")
            return False
        if not all(_robust(e, run(cand, g)) for g in _ROBUST_SCALES):
            say(f"  {key} x{f:.3g}: score {e.score:.3f}, but a step fails to settle with the plant's gain "
                f"x{_ROBUST_SCALES[0]:g} or x{_ROBUST_SCALES[1]:g}; not kept")
            return False
        return True

    cur, best = start_params, first
    moves: list[str] = []
    while factor >= min_factor and count[0] < max_evals:
        improved = False
        for key in GAIN_KEYS:
            if cur[key] <= 0.0:
                continue
            for f in (factor, 1.0 / factor):
                step = f
                # a kept move is tried again with the step squared (a gain far from its best
                # value, e.g. the paper's negligible kd, gets there in a few runs)
                while count[0] < max_evals:
                    cand = {**cur, key: min(GAIN_RANGE[1], cur[key] * step)}
                    if cand[key] == cur[key]:
                        break
                    e = run(cand)
                    if not acceptable(key, step, e, best, cand):
                        break
                    moves.append(f"{key} {cur[key]:.4g} -> {cand[key]:.4g}: score {best.score:.3f} -> {e.score:.3f}")
                    say("  " + moves[-1])
                    cur, best, improved = cand, e, True
                    step = step * step
                if step != f:
                    break  # moved this way: the other way cannot help
        if not improved:
            factor = math.sqrt(factor)
    robustness = {g: run(cur, g) for g in _ROBUST_SCALES}
    return TuneResult(start_params, first, cur, best, robustness, moves, count[0], time.monotonic() - t0)


def _no_worse(e: Evaluation, ref: Evaluation, settle_tol_s: float = 0.002, over_tol_pct: float = 0.2) -> bool:
    """True if no step of ``e`` settles later or overshoots more than the same step of ``ref``
    (beyond ``settle_tol_s`` s and ``over_tol_pct`` %); a step ``ref`` never settled is free."""
    for a, b in zip(e.steps, ref.steps):
        if not math.isfinite(b.settling_s):
            continue
        if not a.settling_s <= b.settling_s + settle_tol_s or a.overshoot_pct > b.overshoot_pct + over_tol_pct:
            return False
    return True


# ---------------------------------------------------------------- report

def _fmt(x: float | None, fmt: str) -> str:
    return "-" if x is None or (isinstance(x, float) and not math.isfinite(x)) else fmt.format(x)


def format_report(columns: list[tuple[str, Evaluation]], targets: Targets) -> str:
    """Per-step rise (s), settling (s) and overshoot (%) of each evaluation beside the targets."""
    names = [c[0] for c in columns]
    w = max(12, *(len(n) + 2 for n in names))
    lines = [f"{'step (mm)':<12}{'mode':<12}{'':<14}{'target':>8}" + "".join(f"{n:>{w}}" for n in names)]
    for i, m in enumerate(columns[0][1].steps):
        label, mode = f"{m.from_mm:g} -> {m.to_mm:g}", m.mode
        t = targets.of(m.mode)
        for attr, unit, fmt, goal in (("rise_s", "rise (s)", "{:.3f}", t.rise_s),
                                      ("settling_s", "settling (s)", "{:.3f}", t.settling_s),
                                      ("overshoot_pct", "overshoot (%)", "{:.1f}", t.overshoot_pct)):
            vals = [getattr(e.steps[i], attr) for _, e in columns]
            lines.append(f"{label:<12}{mode:<12}{unit:<14}{_fmt(goal, fmt):>8}"
                         + "".join(f"{_fmt(v, fmt):>{w}}" for v in vals))
            label = mode = ""
    lines.append(f"{'peak demand (kV, before the 9 kV clamp)':<46}"
                 + "".join(f"{e.peak_demand_kv:>{w}.2f}" for _, e in columns))
    lines.append(f"{'score (lower is better)':<46}" + "".join(f"{e.score:>{w}.3f}" for _, e in columns))
    return "\n".join(lines)


def format_gains(columns: list[tuple[str, dict[str, float]]]) -> str:
    """The gains of each column (kp kV/mm, ki kV/(mm s), kd kV s/mm)."""
    w = 14
    lines = [f"{'gain':<26}" + "".join(f"{n:>{w}}" for n, _ in columns)]
    units = {"kp": "kV/mm", "ki": "kV/(mm s)", "kd": "kV s/mm"}
    for k in GAIN_KEYS:
        lines.append(f"{k + ' (' + units[k[:2]] + ')':<26}" + "".join(f"{g[k]:>{w}.4g}" for _, g in columns))
    return "\n".join(lines)


# ---------------------------------------------------------------- CLI

def add_arguments(p: argparse.ArgumentParser) -> None:
    """Options of ``hasel tune``."""
    from hasel.validate import seed

    p.add_argument("--plant", required=True, metavar="PLANT",
                   help="nominal | truth | truth:EFFECT(p=v)+... | a plant-model file (e.g. from diagnose "
                        "--export-plant)")
    p.add_argument("--targets", default=None, metavar="NAME=V,...",
                   help="rise=S, settling=S, overshoot=PCT, for both directions or as activation.NAME / "
                        "relaxation.NAME (default: Table II activation with laser: rise=0.026,settling=0.185,"
                        "overshoot=6)")
    p.add_argument("--start", default=None, metavar="GAINS.yaml", help="start from these gains (default the paper's)")
    p.add_argument("--sequence", default="2,4,6,4,2", help="step references, mm (default 2,4,6,4,2)")
    p.add_argument("--hold", type=float, default=1.0, help="seconds per reference (default 1)")
    p.add_argument("--feedback", choices=["laser", "strain"], default="laser", help="feedback sensor (default laser)")
    p.add_argument("--seed", type=seed, default=0, help="noise seed of the simulated sensors (default 0)")
    p.add_argument("--max-evals", type=int, default=120, help="most closed-loop runs of the search (default 120)")
    p.add_argument("--out", default="gains.yaml", metavar="GAINS.yaml",
                   help="parameter file for pid_controller to write (default gains.yaml)")
    p.add_argument("--json", default=None, metavar="FILE", help="write the design (gains, metrics) as JSON")


def _sequence(text: str) -> list[float]:
    try:
        seq = [float(x) for x in str(text).split(",")]
    except ValueError:
        raise BadInputError(f"--sequence must be comma-separated numbers in mm, got {text!r}") from None
    if len(seq) < 2 or not all(math.isfinite(x) and x >= 0 for x in seq) or len(set(seq)) < 2:
        raise BadInputError(f"--sequence needs at least two different finite values >= 0 mm, got {text!r}")
    return seq


def run(args: argparse.Namespace) -> int:
    """CLI: ``hasel tune``."""
    from hasel.outputs import write_text
    from hasel.plantfile import looks_like_path
    from hasel.plantspec import make_actuator

    targets = parse_targets(args.targets)
    seq = _sequence(args.sequence)
    if not (math.isfinite(args.hold) and 0.2 <= args.hold <= 60):
        raise BadInputError(f"--hold must be between 0.2 and 60 s, got {args.hold}")
    if not 1 <= args.max_evals <= 100_000:
        raise BadInputError(f"--max-evals must be between 1 and 100000, got {args.max_evals}")
    plant = str(Path(args.plant).resolve()) if looks_like_path(args.plant) else args.plant
    make_actuator(plant)  # a bad plant: one line before the search
    start = read_gains(args.start) if args.start else None
    print(f"tuning C+ and C- on {args.plant} (offline loop, {args.feedback} feedback, steps "
          f"{' -> '.join(f'{x:g}' for x in seq)} mm, {args.hold:g} s each)")
    res = tune(lambda: make_actuator(plant), start=start, targets=targets, sequence_mm=seq, hold_s=args.hold,
               feedback=args.feedback, seed=args.seed, max_evals=args.max_evals, log=print)
    start_name = "start" if start else "paper"
    print(f"{res.evaluations} closed-loop runs in {res.wall_s:.1f} s; {len(res.moves)} moves kept")
    print(format_gains([(start_name, res.start), ("tuned", res.tuned)]))
    print("predicted on the model (true stroke):")
    print(format_report([(start_name, res.start_eval), ("tuned", res.tuned_eval)], targets))
    rob = ", ".join(f"x{g:g}: score {e.score:.3f}, peak {e.peak_demand_kv:.2f} kV"
                    for g, e in res.robustness.items())
    print(f"robustness (plant gain scaled): {rob}")
    if res.tuned_eval.peak_demand_kv > paper.V_MAX_KV:
        raise HaselError(f"the best design still asks for {res.tuned_eval.peak_demand_kv:.2f} kV, above the "
                         f"{paper.V_MAX_KV:g} kV ceiling; no gains written (lower the targets or the sequence)")
    if args.json:
        doc = {"plant": args.plant, "feedback": args.feedback, "sequence_mm": seq, "hold_s": args.hold,
               "seed": args.seed, "targets": targets.to_json(), "start": {"gains": res.start,
                                                                          **res.start_eval.to_json()},
               "tuned": {"gains": res.tuned, **res.tuned_eval.to_json()},
               "robustness": {f"{g:g}": e.to_json() for g, e in res.robustness.items()},
               "robust": res.robust, "moves": res.moves, "evaluations": res.evaluations,
               "units": {"rise_s": "s", "settling_s": "s", "overshoot_pct": "%", "kv": "kV",
                         "kp": "kV/mm", "ki": "kV/(mm s)", "kd": "kV s/mm"}}
        write_text(args.json, json.dumps(doc, indent=2) + "\n")
        print(f"wrote {args.json}")
    write_gains(args.out, res.tuned, f"hasel tune --plant {args.plant}: C+ (_plus) and C- (_minus) gains\n"
                f"load: ros2 run hasel_control pid_controller --ros-args --params-file {Path(args.out).name}")
    print(f"wrote {args.out}")
    return 0
