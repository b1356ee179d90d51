"""``hasel``: the one command in front of every job.

Each subcommand is a row of :data:`COMMANDS`: its options are declared here (so
``hasel --help`` is instant and needs no ROS), its work is a plain function
``run(args) -> int`` imported only when that subcommand runs. Commands that drive the
node graph live in the ament package ``hasel_sysid``; offline ones in this core.

Exit codes: 0 success; 2 bad input (one line on stderr, no traceback); 1 other failure
(one line too; ``hasel --debug COMMAND`` shows the traceback); 128 + N when stopped by
signal N (SIGINT, SIGTERM and SIGHUP alike, see :mod:`hasel.interrupt`), after every
file was closed. Output options are declared per command (:class:`hasel.outputs.Output`):
they get ``--overwrite`` and are checked before any work.
"""
from __future__ import annotations

import argparse
import importlib
import sys
import threading
import traceback
from collections.abc import Callable, Sequence
from dataclasses import dataclass

from hasel import interrupt
from hasel.errors import BadInputError, HaselError
from hasel.outputs import Output, add_overwrite_option, check_outputs
from hasel.validate import seed, text_file

__all__ = ["main", "COMMANDS", "build_parser"]


class _Parser(argparse.ArgumentParser):
    """argparse, but a usage error is one line and exit code 2 (no usage dump)."""

    def error(self, message: str) -> None:  # type: ignore[override]
        name = self.prog.split()[-1]
        sys.stderr.write(f"hasel{'' if name == 'hasel' else ' ' + name}: error: {message}\n")
        raise SystemExit(2)


@dataclass(frozen=True)
class Command:
    """A subcommand: name, one-line help, its options, where its work lives, whether it needs ROS."""

    name: str
    help: str
    add_arguments: Callable[[argparse.ArgumentParser], None] | str  # or "module:function"
    target: str  # "module:function" taking the parsed args, returning the exit code
    needs_ros: bool
    outputs: tuple[Output, ...] = ()  # output options: --overwrite, checked before the run
    text_inputs: tuple[str, ...] = ()  # options naming a text file (YAML, JSON) read by the command


def _no_args(p: argparse.ArgumentParser) -> None:
    del p


def _demo_args(p: argparse.ArgumentParser) -> None:
    p.add_argument("--out", default="out/demo", help="directory for the demo's files (default out/demo)")
    p.add_argument("--quick", action="store_true", help="shorter runs (for CI smoke tests)")


def _steps_args(p: argparse.ArgumentParser) -> None:
    p.add_argument("--sequence", default="2,4,6,4,2", help="stroke references, mm, comma-separated (default 2,4,6,4,2)")
    p.add_argument("--hold", type=float, default=1.0, help="seconds per reference (default 1)")
    p.add_argument("--feedback", choices=["laser", "strain"], default="laser", help="feedback sensor (default laser)")
    p.add_argument("--plant", default="nominal", help="plant variant (default nominal)")
    p.add_argument("--calibration", default=None, help="strain-sensor calibration YAML (from hasel calibrate)")
    p.add_argument("--gains", default=None, metavar="GAINS.yaml", help="controller gains (parameter file, hasel tune)")
    p.add_argument("--seed", type=seed, default=0, help="noise seed, 0 .. 2^31-1 (default 0)")
    p.add_argument("--record", metavar="FILE.mcap", default=None, help="record every topic to this MCAP file")
    p.add_argument("--json", metavar="FILE", default=None, help="write the step metrics as JSON")
    p.add_argument("--plot", metavar="FILE.png", default=None, help="write a plot of the run")


def _calibrate_args(p: argparse.ArgumentParser) -> None:
    p.add_argument("--points", default="2,3,4,5,6,7", help="strokes to hold, mm (default 2,3,4,5,6,7)")
    p.add_argument("--hold", type=float, default=1.0, help="seconds per point (default 1)")
    p.add_argument("--degree", type=int, choices=[1, 2, 3], default=1, help="polynomial degree (default 1: a line)")
    p.add_argument("--plant", default="nominal", help="plant variant (default nominal)")
    p.add_argument("--seed", type=seed, default=0, help="noise seed, 0 .. 2^31-1 (default 0)")
    p.add_argument("--out", default="calibration.yaml", help="calibration YAML to write (default calibration.yaml)")


def _record_args(p: argparse.ArgumentParser) -> None:
    p.add_argument("-o", "--output", required=True, metavar="FILE.mcap", help="MCAP file to write")
    p.add_argument("--topics", default="", help="comma-separated topics (default: all, discovered as they appear)")
    p.add_argument("--duration", type=float, default=None, help="stop after this many seconds (default: Ctrl-C)")


def _replay_args(p: argparse.ArgumentParser) -> None:
    p.add_argument("file", metavar="FILE", help="MCAP file to replay")
    p.add_argument("--rate", type=float, default=1.0, help="speed factor of the recorded timing (0: as fast as possible)")
    p.add_argument("--topics", default="", help="comma-separated topics to replay (default: all)")
    p.add_argument("--remap", action="append", metavar="FROM:=TO", help="publish a topic under another name")
    p.add_argument("--clock", action="store_true", help="also publish /clock from the log times")
    p.add_argument("--wait", type=float, default=1.0, help="seconds for discovery before the first message")


def _env_args(p: argparse.ArgumentParser) -> None:
    p.add_argument("argv", nargs=argparse.REMAINDER, help="command to run (after --)")


def run_env(args: argparse.Namespace) -> int:
    """Run a command in the workspace's ROS environment (as if install/setup.bash were sourced)."""
    import os

    argv = list(args.argv)
    if argv[:1] == ["--"]:
        argv = argv[1:]
    if not argv:
        raise BadInputError("no command given: hasel env -- CMD [ARGS...]")
    try:
        os.execvp(argv[0], argv)
    except FileNotFoundError as err:
        raise BadInputError(f"command not found: {argv[0]}") from err
    return 1


COMMANDS: list[Command] = [
    Command("env", "run a command in the workspace's ROS environment: hasel env -- CMD",
            _env_args, "hasel.cli:run_env", True),
    Command("steps", "closed-loop step test through the node graph on the simulated plant",
            _steps_args, "hasel_sysid.steps:run", True,
            (Output("record"), Output("json"), Output("plot")), ("calibration",)),
    Command("compare", "a measured closed-loop log against simulated plants: steps and NRMSE per plant",
            "hasel_sysid.compare:add_arguments", "hasel_sysid.compare:run", True,
            (Output("json"), Output("plot"))),
    Command("tune", "design the dual-mode gains C+ and C- on a plant model (offline loop); writes a parameter file",
            "hasel.tune:add_arguments", "hasel.tune:run", False, (Output("out"), Output("json")), ("start",)),
    Command("calibrate", "strain-sensor calibration against the laser (1 mm steps, 2-7 mm)",
            _calibrate_args, "hasel_sysid.calibrate:run", True, (Output("out"),)),
    Command("chirp", "the paper's identification experiment (chirps on DC offsets), recorded to MCAP",
            "hasel_sysid.chirp:add_arguments", "hasel_sysid.chirp:run", True, (Output("out"),)),
    Command("bench", "the benchmarks that `make bench` runs: one table of ratios, and JSON",
            "hasel_sysid.bench:add_arguments", "hasel_sysid.bench:run", True),
    Command("record", "record topics of the running graph to an MCAP file (rosbag2 layout)",
            _record_args, "hasel_sysid.replay:run_record", True, (Output("output"),)),
    Command("replay", "publish a recorded MCAP file back into the graph", _replay_args,
            "hasel_sysid.replay:run_replay", True),
    Command("demo", "the end-to-end demo that `make demo` runs", _demo_args, "hasel_sysid.demo:run", True),
    Command("identify", "frequency response, static map and transfer-function fit of a log (MCAP or CSV)",
            "hasel.ident.cli:add_arguments", "hasel.ident.cli:run", False,
            (Output("json"), Output("plot"), Output("report", "report.md"))),
    Command("diagnose", "sim-to-real gap diagnosis: where, which unmodelled effect, how far it shrinks",
            "hasel.diagnose.cli:add_arguments", "hasel.diagnose.cli:run", False,
            (Output("json"), Output("export_sim"), Output("report", "report.md")), ("model",)),
    Command("info", "summary of an MCAP file (topics, types, counts, rates); what a damaged file still holds",
            "hasel.io.cli:add_info_arguments", "hasel.io.cli:run_info", False, (Output("json"),)),
    Command("salvage", "rewrite the readable part of a damaged MCAP file as a valid one",
            "hasel.io.cli:add_salvage_arguments", "hasel.io.cli:run_salvage", False, (Output("out"),)),
]


def build_parser() -> argparse.ArgumentParser:
    """The argument parser of ``hasel`` with every subcommand."""
    parser = _Parser(prog="hasel", description="HASEL soft-actuator toolkit: closed loop, "
                     "MCAP logs, identification and sim-to-real gap diagnosis (mm, kV, s).")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", parser_class=_Parser)
    for cmd in COMMANDS:
        p = sub.add_parser(cmd.name, help=cmd.help, description=cmd.help)
        add = cmd.add_arguments
        if isinstance(add, str):
            module, func = add.split(":")
            try:
                add = getattr(importlib.import_module(module), func)
            except ImportError as err:  # a part of the toolkit that is not installed
                p.description = f"{cmd.help} [unavailable: {err}]"
                continue
        add(p)
        if cmd.outputs:
            add_overwrite_option(p)
        p.set_defaults(_command=cmd)
    return parser


class _HeldStderr:
    """stderr whose lines are held for the first ``hold_s`` seconds of a command.

    A bad input is almost always found in the first moments (arguments, a small file);
    its error should then be the only line on stderr, not the third after "loading ...".
    Held lines are written when the hold ends (a timer), when the command succeeds, or
    dropped when it ends with a bad-input error.
    """

    def __init__(self, stream, hold_s: float = 1.0) -> None:
        self.stream, self.held, self.lock = stream, [], threading.Lock()
        self.holding = True
        self.timer = threading.Timer(hold_s, self.release)
        self.timer.daemon = True
        self.timer.start()

    def write(self, text: str) -> int:
        with self.lock:
            if self.holding:
                self.held.append(text)
                return len(text)
        return self.stream.write(text)

    def release(self, keep_last_only: bool = False) -> None:
        """Stop holding; write what was held (only its last write, the error, if ``keep_last_only``)."""
        with self.lock:
            if not self.holding:
                return
            self.holding = False
            self.stream.write("".join(self.held[-1:] if keep_last_only else self.held))
            self.stream.flush()
            self.held.clear()
        self.timer.cancel()

    def __getattr__(self, name: str):
        return getattr(self.stream, name)


def _split_debug(argv: list[str]) -> tuple[list[str], bool]:
    """Remove ``--debug`` (before any ``--``) from ``argv``; return the rest and whether it was there."""
    end = argv.index("--") if "--" in argv else len(argv)
    head = [a for a in argv[:end] if a != "--debug"]
    return head + argv[end:], len(head) != end


def _run(cmd: Command, args: argparse.Namespace, debug: bool) -> int:
    """Run a parsed command; map its end to the documented exit code and one line on stderr."""
    name = f"hasel {cmd.name}"
    try:
        for opt in cmd.text_inputs:
            if getattr(args, opt, None):
                text_file("--" + opt.replace("_", "-"), getattr(args, opt))
        check_outputs(args, cmd.outputs)
        module, func = cmd.target.split(":")
        run = getattr(importlib.import_module(module), func)
        return int(run(args) or 0)
    except interrupt.Interrupted as stop:
        sys.stderr.write(f"{name}: {stop}; files closed\n")
        return stop.exit_code
    except KeyboardInterrupt:
        sys.stderr.write(f"{name}: interrupted\n")
        return 130
    except BadInputError as err:
        if debug:
            traceback.print_exc()
        sys.stderr.write(f"{name}: error: {err}\n")
        return 2
    except UnicodeDecodeError as err:  # a binary file where a text file was expected
        if debug:
            traceback.print_exc()
        sys.stderr.write(f"{name}: error: a file given is not text ({err.reason} at byte {err.start})\n")
        return 2
    except HaselError as err:
        if debug:
            traceback.print_exc()
        sys.stderr.write(f"{name}: failed: {err}\n")
        return 1
    except ModuleNotFoundError as err:
        if cmd.needs_ros and err.name and err.name.split(".")[0] in {
                "rclpy", "hasel_sysid", "hasel_msgs", "hasel_driver", "hasel_control", "sim_plant"}:
            sys.stderr.write(f"{name}: needs the built ROS workspace ({err.name} not found); run `make setup`\n")
            return 1
        return _failed(name, err, debug)
    except Exception as err:  # noqa: BLE001 - a bug: one line for the user, the traceback on --debug
        return _failed(name, err, debug)


def _failed(name: str, err: BaseException, debug: bool) -> int:
    if debug:
        traceback.print_exc()
    hint = "" if debug else " (run `hasel --debug ...` for the traceback)"
    sys.stderr.write(f"{name}: failed: {type(err).__name__}: {err}{hint}\n")
    return 1


def main(argv: Sequence[str] | None = None) -> int:
    """Parse ``argv`` (default ``sys.argv[1:]``), run the subcommand, return its exit code."""
    argv, debug = _split_debug(list(sys.argv[1:] if argv is None else argv))
    first = next((a for a in argv if not a.startswith("-")), None)
    if any(c.name == first and c.needs_ros for c in COMMANDS):
        # its options may live in a ROS package: get the workspace on the path first
        from hasel.rosenv import ensure_ros_environment

        ensure_ros_environment()
    parser = build_parser()
    args = parser.parse_args(argv)
    cmd: Command | None = getattr(args, "_command", None)
    if cmd is None:
        parser.print_help()
        return 0
    if cmd.needs_ros:
        from hasel.rosenv import ensure_ros_environment

        ensure_ros_environment()
    previous = interrupt.install()
    held = _HeldStderr(sys.stderr)
    sys.stderr = held
    code = 1
    try:
        code = _run(cmd, args, debug)
    finally:
        sys.stderr = held.stream
        interrupt.restore(previous)
        held.release(keep_last_only=code == 2 and not debug)
    return code

if __name__ == "__main__":
    sys.exit(main())
