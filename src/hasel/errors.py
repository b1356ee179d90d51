"""The toolkit's exceptions: one root, leaves below it.

Every failure that a user can cause (a bad file, a bad option, an unsafe parameter)
raises a :class:`BadInputError`; the CLI turns it into one line on stderr and exit
code 2. Anything else is a bug or an environment failure (exit code 1).
"""
from __future__ import annotations

__all__ = ["HaselError", "BadInputError", "UnsafeParameterError", "DataFileError"]


class HaselError(Exception):
    """Root of every exception the toolkit raises on purpose."""


class BadInputError(HaselError, ValueError):
    """Input given by the user is unusable: the message says what and where."""


class UnsafeParameterError(BadInputError):
    """A parameter would allow an unsafe actuator voltage; the message gives the reason."""


class DataFileError(BadInputError):
    """A data file (MCAP, CSV, MAT) is missing, truncated, corrupt or lacks a signal."""
