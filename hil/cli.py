"""`hil`: the command line of the USV HIL stack.

Conventions shared by every subcommand:

* repeatable ``--config FILE`` (keys laid over ``configs/default.toml``, in order) and repeatable
  ``--set section.key=value``;
* ``--json`` prints one JSON object, the run's summary, on stdout at the end;
* human-readable progress goes to stderr;
* exit 0 on success, 1 when the run itself failed, 2 on a usage or configuration error, which is
  reported as one line and never as a traceback.
"""

from __future__ import annotations

import argparse
import importlib
import re
import sys
from typing import Any

from hil import config, console
from hil.errors import HilError

# Subcommand modules under hil/commands/, in the order `hil --help` lists them.
COMMANDS = ("run", "sim", "autopilot", "plan", "montecarlo", "bench", "soak", "vcan", "geo", "warm-up")


class ArgumentParser(argparse.ArgumentParser):
    """argparse, but a usage error is one line (and exit code 2), not usage plus message, and a value that
    starts with a minus and a digit (``--miss -6,-2``, ``--start -1.5,3``, ``--heading -1e-3``) is a value,
    not an unknown option (argparse 3.11 only knows bare negative numbers; 3.13 reads them this way)."""

    def __init__(self, *args: Any, **kwargs: Any) -> None:   # argparse.ArgumentParser's, passed on unchanged
        super().__init__(*args, **kwargs)
        self._negative_number_matcher = re.compile(r"^-\.?\d")

    def _get_value(self, action: argparse.Action, arg_string: str) -> object:
        """argparse's conversion, then every float/int option checked against its physical range
        (``hil.commands.arg_types.CLI_RANGES``): out of range, infinite or NaN is a one-line usage error."""
        value = super()._get_value(action, arg_string)
        if action.type in (float, int) and isinstance(value, (float, int)):
            from hil.commands.arg_types import check_range

            name = max(action.option_strings, key=len) if action.option_strings else action.dest
            why = check_range(name, value)
            if why is not None:
                raise argparse.ArgumentError(action, why)
        return value

    def error(self, message: str) -> None:  # type: ignore[override]
        self.exit(2, f"{self.prog}: error: {message} (see {self.prog} --help)\n")


def common_options() -> argparse.ArgumentParser:
    """The options every subcommand accepts."""
    p = argparse.ArgumentParser(add_help=False)
    g = p.add_argument_group("common options")
    g.add_argument("--config", metavar="FILE", action="append", default=None,
                   help="TOML file holding only the keys it changes, laid over configs/default.toml; "
                        "repeatable, applied in order (then --set)")
    g.add_argument("--set", metavar="SECTION.KEY=VALUE", action="append", default=[], dest="overrides",
                   help="override one configuration key, value in TOML syntax "
                        "(e.g. --set current.enabled=false); repeatable")
    g.add_argument("--json", action="store_true",
                   help="print the run's summary as one JSON object on stdout at the end")
    return p


def build_parser() -> ArgumentParser:
    parser = ArgumentParser(
        prog="hil",
        description="Hardware-in-the-loop simulation of a USV with DDRRT* online path planning "
                    "(Wen et al., J. Navigation 2019).",
        epilog="Exit codes: 0 success, 1 the run failed, 2 usage or configuration error. "
               "`hil COMMAND --help` explains each command.",
    )
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", parser_class=ArgumentParser)
    sub.required = True
    parents = [common_options()]
    for name in COMMANDS:
        importlib.import_module(f"hil.commands.{name.replace('-', '_')}").add_parser(sub, parents)
    return parser


def main(argv: list[str] | None = None) -> int:
    parser = build_parser()
    try:
        args, extra = parser.parse_known_args(argv)
    except SystemExit as exc:   # --help, or a usage error already printed in one line
        return exc.code if isinstance(exc.code, int) else 2
    if extra:  # reported by the command's own parser: 'hil COMMAND: error: ...', its --help named
        commands = next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction))
        command = commands.choices[args.command]
        flag = next((e.split("=")[0] for e in extra if e.startswith("--")), None)
        options = [o for a in command._actions for o in a.option_strings if o.startswith("--")]
        hint = config.suggest(flag, options, or_list=False) if flag else ""
        command.error(f"unrecognized arguments: {' '.join(extra)}{hint}")
    if getattr(args, "config", None) is not None:
        args.config = tuple(args.config)
    console.configure_logging()
    try:
        return int(args.func(args))
    except HilError as exc:
        print(f"hil {args.command}: error: {exc}", file=sys.stderr)
        return exc.exit_code
    except OSError as exc:   # a full disk, a vanished file: one line, never a traceback (issue 31)
        where = f" ({exc.filename})" if exc.filename else ""
        print(f"hil {args.command}: error: {exc.strerror or exc}{where}", file=sys.stderr)
        return 1
    except KeyboardInterrupt:
        print(f"hil {args.command}: interrupted", file=sys.stderr)
        return 130
