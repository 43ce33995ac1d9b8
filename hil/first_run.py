"""Tell the user, on the terminal, when a command will first compile the numba kernels.

The processes of a run compile their numba kernels once per machine (``cache=True``: the machine code
is kept in ``__pycache__`` beside the sources, or under ``NUMBA_CACHE_DIR``); until then a run is silent
for tens of seconds while its processes log to their own files. This module looks for the cache's
index files (``<module>.<function>-<line>.pyXY.nbi``) without importing numba (which would add ~1 s to
every command): the kernels count as cold when one of the modules below has no index file at least as
new as its source (numba recompiles when a source changes).
"""

from __future__ import annotations

import os
import sys
from pathlib import Path

REPO = Path(__file__).resolve().parent.parent
# The modules whose kernels a run compiles first and longest (the planner's tree and grid kernels,
# the vessel computer's filter and guidance, the simulator's hull).
KERNEL_SOURCES = ("planner/_kernels.py", "planner/_tree.py", "autopilot_bridge/nav_kernel.py",
                  "autopilot_bridge/guidance.py", "simulator/vessel.py", "common/geodesy.py")
PLANNER_SOURCES = ("planner/_kernels.py", "planner/_tree.py")
# CPU seconds of a cold compile, measured on the project's shared 2-core machine (docs/performance.md
# "The first run compiles"): `NUMBA_CACHE_DIR=$(mktemp -d) hil run --duration 1` 46-50 s of user CPU
# at 6a02b12 (5-7 s cached), shared since issue 32 by three processes (hil/warm_up.py: the planner,
# the rest of the vessel computer, and the run itself); 0.84x that since the planner's and vessel
# computer's kernels compile at NUMBA_OPT=1 without numba's merge sort and slice-copy error path
# (cold `hil warm-up`: 52.6 -> 44.3 s CPU, four A/B rounds), so ~40 s; `hil plan --scenario harbour`
# ~25 s before, 0.9x that after (the planner's group: 27.1 -> 24.4 s). Since 784efb2 a run and
# `hil plan` compile only the tree core of the planner they run: cold `hil run --duration 1`
# 36.7-43.2 s of CPU (mean 40.3, 0.92x main's 43.6, three interleaved rounds at load 4); the planner's
# group 0.85x (18.3 -> 15.6 s), so `hil plan` ~19 s (22 x 0.85, not measured separately). Since
# d979b45 (no np.unique in the sensed-obstacle map, no Informed RRT* sampler in grow_ddrrt) a cold
# `hil run --duration 1` took 31.6-33.1 s of CPU against main's 35.3-40.3 s (four interleaved
# rounds at load 0.6-2.5), so ~32 s; the planner's group 13.7 s (was 14.3 s), so `hil plan` ~19 s still.
# At cf757b3 (guidance's sum and search, the PGNode's kernels in the other group) four interleaved rounds
# on fresh clones at load 0.2-2.9 gave 33.1-40.6 s of CPU (mean 37.2; bbd8929's 38.1-41.7, mean 39.3:
# docs/performance.md, "Fifth pass"), so ~37 s. At 719ad96/019714e a brand-new checkout's first run took
# 30.6 s of CPU quiet and 34.6-36.8 s on fresh clones at load ~2 ("Sixth pass"), so ~34 s.
COLD_COMPILE_S = 34
COLD_PLAN_COMPILE_S = 19


TREE_SOURCE = "planner/_tree.py"


def tree_core(algorithm: str) -> str:
    """The tree-core kernel of ``planner/_tree.py`` a planner runs (``_tree.grow_kernel``): each
    process compiles only its planner's, so a run with another planner compiles again."""
    return "grow_ddrrt" if algorithm == "ddrrt-star" else "grow_rrt"


def _index_files(source: Path, function: str = "*") -> list[Path]:
    tag = f"py{sys.version_info[0]}{sys.version_info[1]}"
    pattern = f"{source.stem}.{function}-*.{tag}*.nbi" if function != "*" else f"{source.stem}.*.{tag}*.nbi"
    cache_dir = os.environ.get("NUMBA_CACHE_DIR")
    if cache_dir:
        root = Path(cache_dir)
        return [p for d in root.glob(f"{source.parent.name}_*") for p in d.glob(pattern)] if root.is_dir() else []
    return list((source.parent / "__pycache__").glob(pattern))


def kernels_cold(sources: tuple[str, ...] = KERNEL_SOURCES, algorithm: str | None = None) -> bool:
    """Whether a run will compile numba kernels (a missing or older cache for one of the kernel
    modules ``sources``, paths relative to the repository, or with ``algorithm`` for that
    planner's tree core)."""
    checks = [(rel, "*") for rel in sources]
    if algorithm is not None:
        checks.append((TREE_SOURCE, tree_core(algorithm)))
    for rel, function in checks:
        src = REPO / rel
        try:
            stamp = src.stat().st_mtime
        except OSError:
            continue
        if not any(p.stat().st_mtime >= stamp for p in _index_files(src, function)):
            return True
    return False


def compile_notice(command: str, seconds: int = COLD_COMPILE_S, sources: tuple[str, ...] = KERNEL_SOURCES,
                   processes: int = 1, algorithm: str | None = None) -> str | None:
    """The line to print before a command that will compile, or None when the kernels (with
    ``algorithm``, that planner's tree core too) are cached."""
    if not kernels_cold(sources, algorithm):
        return None
    shared = f" shared by {processes} processes" if processes > 1 else ""
    return (f"{command}: compiling numba kernels, first run only, ~{seconds} s of CPU{shared} "
            "(longer on a busy machine; cached afterwards; `hil warm-up` does it ahead)")
