"""`hil soak`: run the HIL loop (or the CAN actuator path alone) for a long time and check it stays clean."""

from __future__ import annotations

import argparse
import tempfile
from pathlib import Path

from hil import soak
from hil.commands.can_options import add_can_arguments, can_overrides, check_can
from hil.console import emit, load_settings, progress
from hil.errors import ConfigError, UsageError
from hil.files import check_output_folder

LOOP_RATE_HZ = 100.0  # the HIL loop commands the thrusters once per IMU frame (sensors.imu.rate_hz)


def add_parser(sub: argparse._SubParsersAction, parents: list[argparse.ArgumentParser]) -> None:
    p = sub.add_parser(
        "soak", parents=parents,
        help="soak test: the HIL loop (or the CAN actuator path alone) for a long time, leak and loss checks",
        description="Runs the HIL loop in real time (x1) for --duration seconds, on CAN actuators by default, "
                    "without stopping at the goal; or, with --rate above the loop's command rate "
                    f"({LOOP_RATE_HZ:g} Hz), only the CAN actuator path: this process commanding the ESC "
                    "nodes (a separate process) at --rate. Reports frames/transfers sent and received per data "
                    "type and node, transfers lost (gaps in transfer IDs) and duplicated, command->applied "
                    "latency p50/p99/max, stale-command failsafe events, rejected frames per reason, planner "
                    "deadline overruns, resident memory and open file descriptors of each process at start and "
                    "end, and memory growth per hour. Shows progress every 5 s.",
        epilog="Exit 0 when clean; 1 when a transfer was lost, a frame was rejected, memory grew faster than "
               "--max-rss-growth (and by more than --rss-noise), open file descriptors grew by more than "
               "--max-fd-growth, or the planner's deadline overruns exceeded what the load allows; 2 on a "
               "usage error. Overruns are judged against the load the run saw, never failing on a busy machine "
               "alone: from /proc, the CPU-seconds that processes other than the soak's own (and the "
               "hypervisor's steal) took during the run; each --load-per-overrun CPU-seconds of that beyond a "
               "quiet machine's 5 percent of one CPU excuses one overrun on top of --max-overruns (docs/can.md).",
    )
    p.add_argument("--duration", type=float, default=60.0, metavar="S", help="seconds to run (default: 60)")
    p.add_argument("--rate", type=float, default=None, metavar="HZ",
                   help=f"command rate of the CAN path alone; at or below {LOOP_RATE_HZ:g} Hz the HIL loop runs")
    p.add_argument("--scenario", default="harbour", help="HIL loop scenario (default: harbour)")
    p.add_argument("--seed", type=int, default=1, help="seed (default: 1)")
    p.add_argument("--max-rss-growth", type=float, default=64.0, metavar="MB_PER_H",
                   help="fail when a process's resident memory grows faster than this (default: 64 MB/h)")
    p.add_argument("--rss-noise", type=float, default=4.0, metavar="MB",
                   help="growth below this many MB is allocator noise, never a failure (default: 4)")
    p.add_argument("--max-overruns", type=int, default=0,
                   help="planner deadline overruns allowed on a quiet machine (default: 0)")
    p.add_argument("--load-per-overrun", type=float, default=1.0, metavar="CPU_S",
                   help="one more overrun is allowed per this many CPU-seconds that other processes or steal took "
                        "during the run beyond 5%% of one CPU (an overrun means the worker missed >= 0.3 s of "
                        "CPU in one planning cycle; default: 1.0)")
    p.add_argument("--max-fd-growth", type=int, default=2, metavar="N",
                   help="fail when a process ends with more than N open file descriptors above its baseline "
                        "(default: 2)")
    p.add_argument("--warmup", type=float, default=None, metavar="S",
                   help="memory baseline taken this long after start (default: 10%% of --duration, 5-60 s)")
    p.add_argument("--out", metavar="DIR", default=None, help="keep the run folder here (default: temporary)")
    add_can_arguments(p, default="can, for a soak")
    p.set_defaults(func=run, actuators="can")


def run(args: argparse.Namespace) -> int:
    if not 0 < args.duration < float("inf"):
        raise ConfigError("--duration: must be a finite number > 0 of seconds")
    if args.rate is not None and not 0 < args.rate < float("inf"):
        raise ConfigError("--rate: must be a finite number > 0 of Hz")
    if not args.load_per_overrun > 0 or args.max_overruns < 0 or args.max_fd_growth < 0:
        raise ConfigError("--load-per-overrun must be > 0, --max-overruns and --max-fd-growth >= 0")
    args.overrides = list(args.overrides) + can_overrides(args)
    cfg = load_settings(args)
    check_can(cfg, "hil soak")
    if args.out:
        check_output_folder(args.out, "--out")
    with tempfile.TemporaryDirectory(prefix="hil-soak-") as tmp:
        out = Path(args.out) if args.out else Path(tmp)
        out.mkdir(parents=True, exist_ok=True)
        if args.rate is not None and args.rate > LOOP_RATE_HZ:
            if cfg.can.actuators != "can":
                raise UsageError("--rate above the loop's rate soaks the CAN path: it needs --actuators can")
            result = soak.soak_can_path(args, cfg, out)
        else:
            result = soak.soak_loop(args, cfg, out)
    problems = result["problems"]
    result["clean"] = not problems
    emit(args, result)
    progress("soak: clean" if not problems else "soak: NOT clean: " + "; ".join(problems))
    return 0 if not problems else 1
