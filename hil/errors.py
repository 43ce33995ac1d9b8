"""Errors that end a `hil` command with a one-line message and exit code 2 (user mistakes)."""

from __future__ import annotations


class HilError(Exception):
    """Base class of user-facing errors: reported as one line, never as a traceback."""

    exit_code = 2


class UsageError(HilError):
    """A bad command-line argument or input file (exit code 2)."""


class ConfigError(HilError):
    """A configuration file or override that is missing, malformed or physically impossible (exit code 2)."""


class RunFailed(HilError):
    """The run itself failed (collision, goal not reached ...): exit code 1."""

    exit_code = 1
