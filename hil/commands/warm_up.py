"""`hil warm-up`: compile every numba kernel of a run now (set-up time), in parallel processes."""

from __future__ import annotations

import argparse
import os
import time

from hil.console import emit, progress


def add_parser(sub: argparse._SubParsersAction, parents: list[argparse.ArgumentParser]) -> None:
    p = sub.add_parser(
        "warm-up", parents=parents,
        help="compile the numba kernels now, in parallel processes (what a first run would do)",
        description="Compile (or, when cached, load) the numba kernels of a run: the planner, the vessel "
                    "computer and the simulator, each group in its own process (numba compiles one function "
                    "at a time per process). The machine code is kept in __pycache__ beside the sources, or "
                    "under NUMBA_CACHE_DIR, so a first `hil run` need not compile. Run it at set-up time (a "
                    "container image, CI). Prints each group's CPU and wall seconds.")
    p.add_argument("--kernels", action="store_true",
                   help="also measure each compiled function's CPU seconds (exclusive of the functions it "
                        "compiled on the way) and specialisations; meaningful on a cold cache "
                        "(NUMBA_CACHE_DIR=$(mktemp -d) hil warm-up --kernels)")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from hil.errors import RunFailed
    from hil.first_run import kernels_cold
    from hil.warm_up import GROUPS, run_all

    cold = kernels_cold()
    progress(f"warm-up: {'compiling' if cold else 'loading'} the numba kernels in {len(GROUPS)} processes "
             f"({', '.join(GROUPS)})")
    t0 = time.monotonic()
    try:
        groups = run_all(kernels=args.kernels)
    except RuntimeError as exc:
        raise RunFailed(f"warm-up: {exc}") from None
    wall = time.monotonic() - t0
    cpu = sum(float(g["cpu_s"]) for g in groups)
    summary = {"cold": cold, "wall_s": round(wall, 2), "cpu_s": round(cpu, 2), "cpus": os.cpu_count(),
               "groups": groups}
    lines = []
    for g in groups:
        top = ", ".join(f"{k['kernel'].rsplit('.', 1)[-1]} {k['cpu_s']}" for k in g.get("kernels", [])[:4])
        costliest = f" (costliest: {top})" if top else ""
        lines.append(f"{g['group']}: {g['cpu_s']} s CPU, {g['wall_s']} s wall{costliest}")
    lines.append(f"all: {cpu:.1f} s CPU in {wall:.1f} s wall ({os.cpu_count()} CPUs); "
                 + ("compiled and cached" if cold else "already cached"))
    emit(args, summary, lines)
    return 0
