"""Stopping a command by a signal without damaging what it writes.

Shell scripts, ``timeout``, job schedulers and CI stop programs with SIGTERM (or
SIGHUP when the terminal goes), not Ctrl-C; a command started in the background of
a script even has SIGINT ignored. :func:`install` makes SIGINT (unless inherited as
ignored), SIGTERM and SIGHUP behave alike:

- outside a :func:`deferred` section the handler raises :class:`Interrupted` at once
  (pure computations; every output is written atomically, so nothing half-written stays);
- inside one (a running node graph, a recorder) it only records the signal, because
  closing an MCAP file or a ROS context inside a signal handler is unsafe; the loop of
  that section polls :func:`requested` and stops cooperatively, leaves the section,
  closes its files and then raises :class:`Interrupted` through :func:`check`.

The command line turns :class:`Interrupted` into exit code 128 + the signal number.
"""
from __future__ import annotations

import contextlib
import signal
import threading
from collections.abc import Iterator

__all__ = ["Interrupted", "install", "restore", "requested", "check", "deferred", "HANDLED"]

HANDLED = ("SIGINT", "SIGTERM", "SIGHUP")


class Interrupted(BaseException):
    """A stop signal arrived; ``signum`` is its number (a BaseException, like KeyboardInterrupt,
    so that no ``except Exception`` on the way swallows it)."""

    def __init__(self, signum: int) -> None:
        self.signum = int(signum)
        super().__init__(f"stopped by {signal.Signals(self.signum).name}")

    @property
    def exit_code(self) -> int:
        """128 + the signal number, as a shell reports a process ended by that signal."""
        return 128 + self.signum


_state = {"signum": 0, "depth": 0}


def _handler(signum: int, frame) -> None:
    del frame
    if _state["signum"]:
        return  # already stopping: a second signal must not interrupt the clean-up
    _state["signum"] = signum
    if _state["depth"] == 0:
        raise Interrupted(signum)


def install() -> dict[int, object]:
    """Handle SIGINT, SIGTERM and SIGHUP alike; return the handlers replaced (for :func:`restore`).

    Main thread only (elsewhere nothing is installed). SIGINT stays ignored if it was:
    a command started in the background of a script is meant to ignore it.
    """
    previous: dict[int, object] = {}
    if threading.current_thread() is not threading.main_thread():
        return previous
    if signal.getsignal(signal.SIGTERM) is not _handler:
        # a fresh command; a nested one (the demo runs `hasel diagnose` in-process) keeps a pending stop
        _state["signum"] = 0
    for name in HANDLED:
        sig = getattr(signal, name, None)
        if sig is None:
            continue
        if sig == signal.SIGINT and signal.getsignal(sig) == signal.SIG_IGN:
            continue
        previous[sig] = signal.signal(sig, _handler)
    return previous


def restore(previous: dict[int, object]) -> None:
    """Put back the handlers :func:`install` replaced."""
    for sig, handler in previous.items():
        signal.signal(sig, handler if handler is not None else signal.SIG_DFL)


def requested() -> int:
    """The number of the stop signal received so far, or 0."""
    return _state["signum"]


def check() -> None:
    """Raise :class:`Interrupted` if a stop signal has arrived.

    Also the safety net for a raise that was lost: a signal that lands while Python runs a callback
    whose exceptions it only prints (an at-fork hook as the diagnosis starts its worker processes,
    a ``__del__``) is recorded but does not stop the command; the command line checks once more
    before it reports success."""
    if _state["signum"]:
        raise Interrupted(_state["signum"])


@contextlib.contextmanager
def deferred() -> Iterator[None]:
    """A section in which a signal is only recorded (poll :func:`requested`); sections nest."""
    _state["depth"] += 1
    try:
        yield
    finally:
        _state["depth"] -= 1
