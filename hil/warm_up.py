"""Compile the numba kernels of a run in parallel processes, each filling the on-disk cache.

A run's kernels are compiled once per machine (``cache=True``: kept in ``__pycache__`` or under
``NUMBA_CACHE_DIR``). In a run they used to compile one after another inside the vessel computer:
the planner's (``planner.warm_up_info``, the tree core: most of it), then the navigation filter's,
the guidance's, the sensed-obstacle map's and the plan check's. Numba compiles one function at a
time per process (a global compiler lock), so the only way to use a second CPU is a second process.

Each group below is compiled by its own process (``python -m hil.warm_up GROUP``), which holds an
exclusive lock on its group's lock file while it compiles. ``hil run`` starts them when the cache is
cold (:func:`start`), and the vessel computer waits for a group's lock (:func:`wait_for`) just before
it needs the group's kernels, then loads them from the cache instead of compiling them a second time.
``hil warm-up`` runs every group in parallel and waits (a compile at set-up time).

The groups call the same functions with the same argument types as the run's processes, so the
machine code they leave in the cache is the run's (``tests/test_warm_up.py`` checks that a run's
vessel computer then compiles nothing).
"""

from __future__ import annotations

import fcntl
import hashlib
import json
import os
import resource
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable
from pathlib import Path

REPO = Path(__file__).resolve().parent.parent
READY = "locked"


# `python -m hil.warm_up --algorithm NAME GROUP`, as `hil run` starts its groups: only that planner's
# kernels (the tree core of DDRRT* and that of RRT*/Informed RRT* are two kernels), the tree core in
# the planner's group (its searches without the PGNode: the same tree-core types) and the tree reuse
# (`seed_tree`, ~2 s) and the PGNode's kernels (its target and repair, ~1.5 s) at the end of the
# vessel computer's, off the planner's group, the longest chain.
_ALGORITHMS: list[str] = []


def _planner() -> None:
    import planner

    planner.warm_up_info(tuple(_ALGORITHMS) or None, tree_reuse=not _ALGORITHMS, png=not _ALGORITHMS)


def _vessel_computer() -> None:
    """What ``autopilot_bridge.autopilot.Autopilot`` compiles when it is built (the planner apart)."""
    import numpy as np

    from autopilot_bridge import guidance, navigation
    from autopilot_bridge.obstacle_map import SensedObstacles
    from planner.global_route import plan_chart_route
    from planner.gridmap import OccupancyGrid

    navigation._warm_up()
    guidance.warm_up()
    SensedObstacles(np.zeros((8, 8), dtype=bool), 1.0)
    occ = np.zeros((40, 40), dtype=bool)
    occ[5:35, 19:21] = True   # a wall: the global route's any-angle search runs
    grid = OccupancyGrid(occ, 0.5)
    grid.polyline_free(np.zeros((0, 2)))
    plan_chart_route(grid, np.array([[2.0, 10.0], [18.0, 10.0]]), 0.5)
    if _ALGORITHMS:
        import planner

        planner.warm_up_tree_reuse(tuple(_ALGORITHMS))
        planner.warm_up_png(tuple(_ALGORITHMS))


def _simulator() -> None:
    """The simulator's hull, ray march and geodesy (as ``hil sim`` builds its core), and the
    geodesy every process uses."""
    import numpy as np

    from hil import settings
    from hil.assembly.simulator import simulator_settings
    from simulator.core import SimulatorCore
    from simulator.rangefinder import WorldMap

    core = SimulatorCore(simulator_settings(settings.load()), WorldMap(np.zeros((8, 8), dtype=bool), 1.0))
    core.frame()
    core.geo.geodetic_to_ned(*core.geo.ned_to_geodetic(1.0, 2.0, 0.0))
    core.geo.geodetic_to_sea_level(*core.geo.sea_level_to_geodetic(1.0, 2.0))


GROUPS: dict[str, Callable[[], None]] = {"planner": _planner, "vessel-computer": _vessel_computer,
                                         "simulator": _simulator}
# What `hil run` compiles in the background on a cold cache: the vessel computer's groups (the
# simulator's kernels take ~1 s and compile in the simulator's own process). With the tree reuse and
# the PGNode in the vessel computer's group their compiles are ~11.6 s of CPU each (a cold run at
# 7999673, load 2.3: they ended 0.2 s apart), so that neither ends long after the other at equal
# priority (a nice level on one of them starved it behind other load:
# docs/performance.md, "The first run compiles").
RUN_GROUPS = ("planner", "vessel-computer")


def lock_path(group: str) -> Path:
    """The lock file of a group, one per checkout and numba cache (two clones never wait for each other)."""
    key = f"{REPO}|{os.environ.get('NUMBA_CACHE_DIR', '')}|{group}"
    digest = hashlib.sha1(key.encode()).hexdigest()[:12]
    return Path(tempfile.gettempdir()) / f"usv-hil-compile-{group}-{digest}.lock"


def _cpu_s() -> float:
    r = resource.getrusage(resource.RUSAGE_SELF)
    return r.ru_utime + r.ru_stime


class KernelTimes:
    """CPU seconds numba spent compiling each function (``module.name``), exclusive of the functions
    it compiled on the way (a caller compiles its callees first), and how many specialisations.
    Listens to numba's ``numba:compile`` events."""

    def __init__(self) -> None:
        self.exclusive: dict[str, float] = {}
        self.count: dict[str, int] = {}
        self._stack: list[list[float]] = []
        self._listener: object | None = None

    def install(self) -> None:
        from numba.core import event

        times = self

        class _Listener(event.Listener):
            def on_start(self, ev: event.Event) -> None:
                times._stack.append([time.process_time(), 0.0])

            def on_end(self, ev: event.Event) -> None:
                t0, inner = times._stack.pop()
                spent = time.process_time() - t0
                fn = ev.data["dispatcher"].py_func
                name = f"{fn.__module__}.{fn.__qualname__}"
                times.exclusive[name] = times.exclusive.get(name, 0.0) + spent - inner
                times.count[name] = times.count.get(name, 0) + 1
                if times._stack:
                    times._stack[-1][1] += spent

        self._listener = _Listener()
        event.register("numba:compile", self._listener)

    def uninstall(self) -> None:
        from numba.core import event

        if self._listener is not None:
            event.unregister("numba:compile", self._listener)
            self._listener = None

    def top(self, n: int = 12) -> list[dict[str, float | str | int]]:
        """The ``n`` costliest functions of ours (numba's own helpers are counted in ``numba``)."""
        ours = {k: v for k, v in self.exclusive.items() if not k.startswith("numba.")}
        rows: list[dict[str, float | str | int]] = [
            {"kernel": k, "cpu_s": round(v, 2), "specialisations": self.count[k]}
            for k, v in sorted(ours.items(), key=lambda kv: -kv[1])[:n]]
        helpers = sum(v for k, v in self.exclusive.items() if k.startswith("numba."))
        rows.append({"kernel": "numba (its own helpers: array and builtin implementations)",
                     "cpu_s": round(helpers, 2), "specialisations": sum(
                         c for k, c in self.count.items() if k.startswith("numba."))})
        return rows


def compile_group(group: str, kernels: bool = False) -> dict:
    """Compile (or load) one group's kernels under its lock; its CPU and wall seconds (and with
    ``kernels`` each function's compile CPU, :class:`KernelTimes`)."""
    t0, c0 = time.monotonic(), _cpu_s()
    times = KernelTimes()
    if kernels:
        times.install()
    with open(lock_path(group), "a") as fh:
        fcntl.flock(fh, fcntl.LOCK_EX)
        print(READY, flush=True)
        GROUPS[group]()
    out: dict = {"group": group, "cpu_s": round(_cpu_s() - c0, 2), "wall_s": round(time.monotonic() - t0, 2)}
    if kernels:
        out["kernels"] = times.top()
    return out


def start(groups: tuple[str, ...] = RUN_GROUPS, log_dir: Path | None = None,
          algorithm: str | None = None) -> list[subprocess.Popen]:
    """Start one compiling process per group and return once each holds its lock (so that a
    :func:`wait_for` that follows waits for it). Their stderr goes to ``log_dir/compile-GROUP.log``.
    ``algorithm``: only that planner's kernels (the one a run uses), its tree reuse in the vessel
    computer's group."""
    procs = []
    for group in groups:
        err = open(log_dir / f"compile-{group}.log", "w") if log_dir is not None else subprocess.DEVNULL
        extra = ["--algorithm", algorithm] if algorithm and group in ("planner", "vessel-computer") else []
        try:
            proc = subprocess.Popen([sys.executable, "-m", "hil.warm_up", *extra, group], cwd=REPO, text=True,
                                    stdout=subprocess.PIPE, stderr=err, stdin=subprocess.DEVNULL)
        finally:
            if err is not subprocess.DEVNULL:
                err.close()  # type: ignore[union-attr]
        procs.append(proc)
    for proc in procs:
        assert proc.stdout is not None
        proc.stdout.readline()   # READY, or "" if it failed to start: nothing to wait for then
    return procs


def wait_for(group: str, timeout_s: float = 600.0) -> float:
    """Wait until no process compiles ``group`` (its lock is free); the seconds waited. Gives up
    after ``timeout_s`` (the caller then compiles what is still missing itself)."""
    path = lock_path(group)
    if not path.exists():
        return 0.0
    t0 = time.monotonic()
    with open(path, "a") as fh:
        while True:
            try:
                fcntl.flock(fh, fcntl.LOCK_EX | fcntl.LOCK_NB)
                break
            except OSError:
                if time.monotonic() - t0 > timeout_s:
                    break
                time.sleep(0.05)
    return time.monotonic() - t0


def run_all(groups: tuple[str, ...] | None = None, kernels: bool = False) -> list[dict]:
    """Every group (or ``groups``) in its own process, in parallel; each one's figures."""
    names = tuple(GROUPS) if groups is None else groups
    extra = ["--kernels"] if kernels else []
    procs = [subprocess.Popen([sys.executable, "-m", "hil.warm_up", "--json", *extra, g], cwd=REPO, text=True,
                              stdout=subprocess.PIPE, stdin=subprocess.DEVNULL) for g in names]
    out = []
    for g, proc in zip(names, procs, strict=True):
        text, _ = proc.communicate()
        lines = [ln for ln in text.splitlines() if ln.startswith("{")]
        if proc.returncode != 0 or not lines:
            raise RuntimeError(f"compiling {g} failed (exit {proc.returncode})")
        out.append(json.loads(lines[-1]))
    return out


def main(argv: list[str]) -> int:
    from hil import numba_env
    from planner.params import ALGORITHM_NAMES

    as_json = "--json" in argv
    args = list(argv)
    if "--algorithm" in args:
        at = args.index("--algorithm")
        _ALGORITHMS[:] = args[at + 1:at + 2] or [""]   # no name: a usage error below
        del args[at:at + 2]
    names = [a for a in args if a not in ("--json", "--kernels")]
    if len(names) != 1 or names[0] not in GROUPS or (_ALGORITHMS and _ALGORITHMS[0] not in ALGORITHM_NAMES):
        print(f"usage: python -m hil.warm_up [--json] [--kernels] "
              f"[--algorithm {{{','.join(ALGORITHM_NAMES)}}}] {{{','.join(GROUPS)}}}", file=sys.stderr)
        return 2
    if names[0] in numba_env.LOW_OPT_GROUPS:
        numba_env.apply()
    figures = compile_group(names[0], kernels="--kernels" in argv)
    if as_json:
        print(json.dumps(figures), flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
