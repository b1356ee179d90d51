"""``hasel``: the one command in front of every job.

Each subcommand is a :class:`Command`: its name, help and options, and its work, a
plain function ``run(args) -> int`` imported only when that subcommand runs. The
offline ones are the rows of :data:`COMMANDS`, in this ROS-free core. Other installed
packages add theirs through the ``hasel.commands`` entry-point group
(:data:`ENTRY_POINT_GROUP`, one entry point per command naming its ``Command``): the
node-graph commands in the ament package ``hasel_sysid`` (``setup.py``), the benchmarks
in ``bench/`` (``pyproject.toml``). The core names none of them. ``hasel --help``
imports no command module (only the small modules that declare the commands), so it
is instant and works without ROS.

Exit codes: 0 success; 2 bad input (one line on stderr, no traceback); 1 other failure
(one line too; ``hasel --debug COMMAND`` shows the traceback); 128 + N when stopped by
signal N (SIGINT, SIGTERM and SIGHUP alike, see :mod:`hasel.interrupt`), after every
file was closed. Output options are declared per command (:class:`hasel.outputs.Output`):
they get ``--overwrite`` and are checked before any work.
"""
from __future__ import annotations

import argparse
import functools
import importlib
import os
import sys
import threading
import traceback
from collections.abc import Callable, Sequence
from dataclasses import dataclass

from hasel import interrupt
from hasel.errors import BadInputError, HaselError
from hasel.outputs import Output, add_overwrite_option, check_outputs
from hasel.validate import text_file

__all__ = ["main", "Command", "COMMANDS", "ENTRY_POINT_GROUP", "commands", "build_parser"]

#: Entry-point group in which installed packages declare more subcommands (each a :class:`Command`).
ENTRY_POINT_GROUP = "hasel.commands"
#: Top-level modules of the built ROS workspace: a command missing one needs `make setup`.
_WORKSPACE_MODULES = frozenset({"rclpy", "hasel_ros", "hasel_msgs", "hasel_driver", "hasel_control", "sim_plant",
                                "hasel_sysid", "hasel_bench"})


class _Parser(argparse.ArgumentParser):
    """argparse, but a usage error is one line and exit code 2 (no usage dump), and an option must be spelled
    whole: argparse's prefix matching read ``identify --out X`` as ``--output X`` and then failed on a column
    named X, far from the typo."""

    def __init__(self, *args, **kwargs) -> None:
        kwargs.setdefault("allow_abbrev", False)
        super().__init__(*args, **kwargs)

    def error(self, message: str) -> None:  # type: ignore[override]
        name = self.prog.split()[-1]
        sys.stderr.write(f"hasel{'' if name == 'hasel' else ' ' + name}: error: {message}\n")
        raise SystemExit(2)


@dataclass(frozen=True)
class Command:
    """A subcommand: name, one-line help, its options, where its work lives, whether it needs ROS.

    ``add_arguments`` and ``target`` are functions or ``"module:function"`` strings of
    the declaring package, imported only when that command is parsed or run.
    """

    name: str
    help: str
    add_arguments: Callable[[argparse.ArgumentParser], None] | str  # or "module:function"
    target: Callable[[argparse.Namespace], int] | str  # takes the parsed args, returns the exit code
    needs_ros: bool
    outputs: tuple[Output, ...] = ()  # output options: --overwrite, checked before the run
    text_inputs: tuple[str, ...] = ()  # options naming a text file (YAML, JSON) read by the command


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


#: The core's own subcommands (offline; ``env`` only sets up the workspace's environment).
COMMANDS: list[Command] = [
    Command("env", "run a command in the workspace's ROS environment: hasel env -- CMD",
            _env_args, "hasel.cli:run_env", True),
    Command("tune", "design the dual-mode gains C+ and C- on a plant model (offline loop); writes a parameter file",
            "hasel.tune:add_arguments", "hasel.tune:run", False, (Output("out"), Output("json")), ("start",)),
    Command("identify", "frequency response, static map and transfer-function fit of a log (MCAP, CSV or MAT)",
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


def _workspace_paths() -> list[str]:
    """Python paths of the built ROS workspace's packages that are not on ``sys.path`` yet (no ROS import)."""
    from hasel.rosenv import ros_environment

    paths = ros_environment({}).get("PYTHONPATH", "").split(os.pathsep)
    return [p for p in paths if p and p not in sys.path]


def _unavailable(name: str, err: BaseException) -> Command:
    """A stand-in for a declared command whose declaring module cannot be imported: running it says why."""
    def add(p: argparse.ArgumentParser) -> None:
        _rest_args(p)
        p.set_defaults(_unavailable=err)

    def run(args: argparse.Namespace) -> int:
        raise err

    return Command(name, f"[unavailable: {err}]", add, run, True)


def _rest_args(p: argparse.ArgumentParser) -> None:
    """Accept any arguments (of a command that cannot run here: it will say why instead)."""
    p.add_argument("rest", nargs=argparse.REMAINDER, help=argparse.SUPPRESS)


@functools.cache
def commands() -> tuple[Command, ...]:
    """Every subcommand: :data:`COMMANDS`, then those declared in the :data:`ENTRY_POINT_GROUP` entry points.

    The built ROS workspace's Python paths are appended to ``sys.path`` first (its
    packages are not in the venv), so its commands are listed without sourcing anything;
    declaring a command imports only the small module that holds its :class:`Command`.
    """
    from importlib.metadata import entry_points

    sys.path.extend(_workspace_paths())
    found = list(COMMANDS)
    seen = {c.name for c in found}
    for ep in entry_points(group=ENTRY_POINT_GROUP):
        if ep.name in seen:
            continue
        try:
            cmd = ep.load()
        except Exception as err:  # noqa: BLE001 - a broken or half-installed package must not break `hasel`
            cmd = _unavailable(ep.name, err)
        if not isinstance(cmd, Command) or cmd.name != ep.name:
            cmd = _unavailable(ep.name, TypeError(f"entry point {ep.value} is not the Command {ep.name!r}"))
        seen.add(cmd.name)
        found.append(cmd)
    return tuple(found)


def _resolve(ref: Callable | str) -> Callable:
    """A function given as itself or as ``"module:function"`` (imported now)."""
    if callable(ref):
        return ref
    module, func = ref.split(":")
    return getattr(importlib.import_module(module), func)


def build_parser(only: str | None = None) -> argparse.ArgumentParser:
    """The argument parser of ``hasel`` with every subcommand.

    With ``only`` (a command name, or ``""`` for none) only that command's options are
    declared, so that parsing one command imports no other command's module.
    """
    parser = _Parser(prog="hasel", description="HASEL soft-actuator toolkit: closed loop, "
                     "MCAP logs, identification and sim-to-real gap diagnosis (mm, kV, s).")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", parser_class=_Parser)
    for cmd in commands():
        p = sub.add_parser(cmd.name, help=cmd.help, description=cmd.help)
        p.set_defaults(_command=cmd)
        if only is not None and cmd.name != only:
            continue
        try:
            add = _resolve(cmd.add_arguments)
        except ImportError as err:  # a part of the toolkit that is not installed: running it says so
            p.description = f"{cmd.help} [unavailable: {err}]"
            _rest_args(p)
            p.set_defaults(_unavailable=err)
            continue
        add(p)
        if cmd.outputs:
            add_overwrite_option(p)
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
        unavailable = getattr(args, "_unavailable", None)
        if unavailable is not None:
            raise unavailable
        check_outputs(args, cmd.outputs)
        code = int(_resolve(cmd.target)(args) or 0)
        interrupt.check()  # a stop whose raise Python swallowed (see interrupt.check) still ends the command
        return code
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
        if cmd.needs_ros and err.name and err.name.split(".")[0] in _WORKSPACE_MODULES:
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


def _one_blas_thread() -> None:
    """One BLAS/OpenMP thread per process unless the user set otherwise (before numpy loads).

    Why, for every command: the same log gives the same result on any machine. Threaded BLAS
    sums in an order that depends on the thread count: ``make demo``'s identification differed
    in the 5th digit between 1 and 2 threads, and its final held-out NRMSE was 0.0033 against
    0.0024 (the drift's time constant sits on a flat optimum). And ``diagnose`` starts one
    fitting process per core (:mod:`hasel.diagnose.pool`);
    BLAS threads on top of them oversubscribe the cores. Silverbox log, 2 cores, one run each:
    2 processes took 86.8 s with OpenBLAS's default threads and 62.9 s with one thread
    (serial: 81.9 s and 80.6 s)."""
    for name in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
        os.environ.setdefault(name, "1")


def main(argv: Sequence[str] | None = None) -> int:
    """Parse ``argv`` (default ``sys.argv[1:]``), run the subcommand, return its exit code."""
    argv, debug = _split_debug(list(sys.argv[1:] if argv is None else argv))
    first = next((a for a in argv if not a.startswith("-")), None)
    if any(c.name == first and c.needs_ros for c in commands()):
        # its options may live in a ROS package: get the workspace on the path first
        from hasel.rosenv import ensure_ros_environment

        ensure_ros_environment()
    parser = build_parser(first or "")
    args, extra = parser.parse_known_args(argv)
    if extra and getattr(args, "_unavailable", None) is None:  # as parse_args; an unavailable command says why
        parser.error(f"unrecognized arguments: {' '.join(extra)}")
    cmd: Command | None = getattr(args, "_command", None)
    if cmd is None:
        parser.print_help()
        return 0
    if cmd.needs_ros:
        from hasel.rosenv import ensure_ros_environment

        ensure_ros_environment()
    _one_blas_thread()
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
