"""Helpers for tests that start child processes."""
from __future__ import annotations

import signal


def default_sigint() -> None:
    """In the child: SIGINT back to its default. A test run started in a script's background has SIGINT
    ignored, and children inherit that (the convention the commands keep); these tests send it on purpose."""
    signal.signal(signal.SIGINT, signal.SIG_DFL)
