"""`hil ARGV` in-process through :func:`hil.cli.main`, for tests of argument and configuration
errors: no interpreter start-up, the same exit code and output a subprocess would give."""

from __future__ import annotations

import subprocess

import pytest


def run_cli(capsys: pytest.CaptureFixture[str], *argv: str) -> subprocess.CompletedProcess:
    """Exit code, stdout and stderr of ``hil.cli.main(argv)``; an exception that escapes main() (a
    traceback a user would see) fails the test where it happens."""
    from hil import cli

    capsys.readouterr()
    try:
        code = cli.main(list(argv))
    except SystemExit as exc:  # argparse's usage errors
        code = exc.code if isinstance(exc.code, int) else 1
    out = capsys.readouterr()
    return subprocess.CompletedProcess(["hil", *argv], code, out.out, out.err)
