"""`hil vcan -- COMMAND ...`: run a command where a virtual CAN bus vcan0 exists."""

from __future__ import annotations

import argparse
import os
import shutil
import subprocess
import sys

from hil.console import progress
from hil.errors import RunFailed, UsageError


def add_parser(sub: argparse._SubParsersAction, parents: list[argparse.ArgumentParser]) -> None:
    p = sub.add_parser(
        "vcan",
        help="run a command on a virtual CAN bus vcan0 (native, else inside User-Mode Linux)",
        description="Run COMMAND where SocketCAN's vcan0 exists: on this machine if its kernel has vcan "
                    "(created with `ip link add dev vcan0 type vcan` when run as root), otherwise inside "
                    "User-Mode Linux (Debian package user-mode-linux; needs root), which boots a Linux "
                    "kernel with can, can-raw and vcan as an ordinary process, with this machine's files "
                    "through hostfs. COMMAND runs in the current directory with the current PATH; a "
                    "leading `hil` is this same installation. Its standard error (progress) is shown as "
                    "it is written; its standard output at the end. Exits with COMMAND's exit code.",
        epilog="Example: hil vcan -- hil soak --duration 3600 --json   (the hour-long CAN soak, docs/can.md)",
    )
    p.add_argument("--mem", default="1536M", help="memory of the User-Mode Linux guest (default: 1536M)")
    p.add_argument("--timeout", type=float, default=6 * 3600.0, metavar="S",
                   help="kill COMMAND after this many seconds (default: 21600)")
    p.add_argument("cmdline", nargs=argparse.REMAINDER, metavar="-- COMMAND [ARG ...]",
                   help="the command to run, after `--`")
    p.set_defaults(func=run)


def _argv(command: list[str]) -> list[str]:
    if command and command[0] == "--":
        command = command[1:]
    if not command:
        raise UsageError("no command given (usage: hil vcan -- COMMAND [ARG ...])")
    if command[0] == "hil":
        return [sys.executable, "-m", "hil", *command[1:]]
    if shutil.which(command[0]) is None:
        raise UsageError(f"command not found: {command[0]}")
    return command


def run(args: argparse.Namespace) -> int:
    from hil import uml

    argv = _argv(args.cmdline)
    if not args.timeout > 0:
        raise UsageError("--timeout must be > 0")
    try:
        kind, why = uml.detect("vcan0")
    except uml.VcanUnavailable as exc:
        raise RunFailed(str(exc)) from None
    progress(f"vcan: {why}")
    if kind == "native":
        try:
            return subprocess.run(argv, timeout=args.timeout).returncode
        except subprocess.TimeoutExpired:
            raise RunFailed(f"{argv[0]} killed after {args.timeout:g} s") from None
    job = uml.Job("command", argv, cwd=os.getcwd(), timeout=args.timeout)
    try:
        result = uml.run_in_uml([job], mem=args.mem, follow=sys.stderr).results[0]
    except RuntimeError as exc:
        raise RunFailed(str(exc).splitlines()[0]) from None
    sys.stdout.write(result.stdout)
    sys.stdout.flush()
    if result.returncode is None:
        raise RunFailed(f"{argv[0]} killed after {args.timeout:g} s")
    return result.returncode
