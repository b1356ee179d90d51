"""A stop signal whose raise Python swallows still ends the command with 128 + the signal."""
from __future__ import annotations

import argparse
import gc
import os
import signal

import pytest

from hasel import cli, interrupt


class _StopInDel:
    """Sends this process SIGTERM from ``__del__``: Python prints an exception raised there
    ("Exception ignored in ...") and goes on, as it does in an at-fork hook (the demo's flake)."""

    def __del__(self) -> None:
        os.kill(os.getpid(), signal.SIGTERM)


def _swallowing_command(args: argparse.Namespace) -> int:
    obj = _StopInDel()
    del obj
    gc.collect()
    args.went_on = True  # the raise was swallowed: the command ran to its end
    return 0


@pytest.mark.filterwarnings("ignore::pytest.PytestUnraisableExceptionWarning")
def test_a_stop_swallowed_in_a_callback_ends_the_command_with_143(capsys):
    previous = interrupt.install()
    try:
        ns = argparse.Namespace(went_on=False)
        cmd = cli.Command("swallow", "test", lambda p: None, _swallowing_command, False)
        code = cli._run(cmd, ns, debug=False)
    finally:
        interrupt.restore(previous)
    assert ns.went_on  # without the final check the command would have reported success
    assert code == 128 + signal.SIGTERM
    assert "stopped by SIGTERM" in capsys.readouterr().err


def test_a_nested_command_keeps_a_stop_that_is_pending():
    outer = interrupt.install()
    try:
        with interrupt.deferred():
            os.kill(os.getpid(), signal.SIGTERM)  # recorded only, inside a deferred section
        assert interrupt.requested() == signal.SIGTERM
        inner = interrupt.install()  # the demo's in-process `hasel diagnose`
        assert interrupt.requested() == signal.SIGTERM
        interrupt.restore(inner)
    finally:
        interrupt.restore(outer)
    fresh = interrupt.install()  # a later, separate command starts clean
    try:
        assert interrupt.requested() == 0
    finally:
        interrupt.restore(fresh)
