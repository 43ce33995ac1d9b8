"""`hil bench TARGET`: speed benchmarks (figures reported as measured in one run)."""

from __future__ import annotations

import argparse
import importlib

# Targets: modules under hil/benches/.
TARGETS = ("sim", "planner", "loop", "can", "can_flood", "gcs", "frame", "ardupilot", "station")


def add_parser(sub: argparse._SubParsersAction, parents: list[argparse.ArgumentParser]) -> None:
    p = sub.add_parser(
        "bench",
        help="speed benchmarks (simulator, planner, control loop)",
        description="Speed benchmarks. Each target measures in one run and reports ratios "
                    "measured side by side, since machines here are shared and noisy.",
    )
    targets = p.add_subparsers(dest="target", metavar="TARGET", parser_class=type(p))
    targets.required = True
    for name in TARGETS:
        importlib.import_module(f"hil.benches.{name}").add_parser(targets, parents)
