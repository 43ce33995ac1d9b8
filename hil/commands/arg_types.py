"""argparse types shared by the command modules: connection strings checked by role (common.connection)."""

from __future__ import annotations

import argparse
from collections.abc import Callable

from common import connection


def endpoint(role: connection.Role) -> Callable[[str], str]:
    """An argparse type checking a connection string for ``role`` (common.connection)."""
    def check(text: str) -> str:
        try:
            connection.parse(text, role)
        except ValueError as exc:
            raise argparse.ArgumentTypeError(str(exc)) from None
        return text
    check.__name__ = "connection string"
    return check


sending = endpoint(connection.SEND_UDP)
receiving = endpoint(connection.RECEIVE_UDP)


# The physical range of every number the command line takes (issue 31): (low, high), inclusive, in the
# option's unit; `hil.cli.ArgumentParser` checks every `type=float`/`type=int` option against it, and
# an option not listed against DEFAULT_REAL / DEFAULT_INTEGER. Out of range: one line naming the
# option, exit 2 (`hil plan --resolution 1e300` used to end in an OverflowError traceback).
CLI_RANGES: dict[str, tuple[float, float]] = {
    "--resolution": (1e-3, 1e3),          # m per map cell
    "--deadline": (1e-3, 3600.0),         # s of planning
    "--iterations": (0, 10_000_000),      # planner iterations (0: the deadline only)
    "--local-iterations": (0, 100_000),   # as autopilot.lockstep_iterations; 0: --local-time only
    "--local-time": (1e-4, 600.0),        # s (0.1 ms: a few hundred iterations of the compiled core)
    "--cycle-time": (1e-3, 600.0),        # s
    "--inflate": (0.0, 1e3),              # m
    "--step": (1e-3, 1e4),                # m
    "--seed": (0, (1 << 63) - 1),
    "--seeds": (1, 1000),
    "--runs": (1, 1_000_000),
    "--jobs": (1, 1024),
    "--figure-runs": (0, 10_000),
    "--ships": (0, 100),
    "--duration": (0.0, 1e6),             # s (simulated or wall, by command)
    "--realtime-duration": (0.0, 1e6),    # s
    "--pipelined-duration": (0.0, 1e6),   # s
    "--wall-timeout": (0.0, 1e6),         # s
    "--timeout": (0.0, 1e6),              # s
    "--warmup": (0.0, 1e6),               # s
    "--block": (0.0, 3600.0),             # s
    "--speedup": (1e-3, 1e3),             # simulated s per wall s
    "--rate": (1e-3, 1e6),                # per s
    "--steps": (1, 100_000_000),
    "--model-steps": (1, 100_000_000),
    "--lockstep-steps": (1, 100_000_000),
    "--sim-steps": (1, 100_000_000),
    "--top": (0, 10_000),
    "--max-rss-growth": (0.0, 1e6),       # MB per hour
    "--rss-noise": (0.0, 1e6),            # MB
    "--max-overruns": (0, 1_000_000_000),
    "--load-per-overrun": (0.0, 1e6),     # CPU s
    "--max-fd-growth": (0, 1_000_000),
    "--start-fd": (0, 65535),
    "--ready-fd": (0, 65535),
    "--instance": (0, 99),
}
DEFAULT_REAL = (-1e9, 1e9)
DEFAULT_INTEGER = (-(1 << 31), (1 << 31) - 1)


def check_range(option: str, value: float) -> str | None:
    """Why ``value`` is out of ``option``'s range (one line), or None."""
    low, high = CLI_RANGES.get(option, DEFAULT_INTEGER if isinstance(value, int) else DEFAULT_REAL)
    if isinstance(value, float) and value != value:
        return "not a number"
    if not low <= value <= high:
        return f"{value:g} is out of range [{low:g}, {high:g}]"
    return None
