"""The planners of ``planner.params.REGISTRY``, built and warmed up from the table.

Above the concrete planners: ``planner.core`` (the shared solve loop) knows none of its
subclasses; this module imports each one named by the table, on first use.
"""

from __future__ import annotations

import dataclasses
import importlib
import time
from typing import TYPE_CHECKING

import numpy as np

from planner.params import ALGORITHM_NAMES, ENTRIES, REGISTRY, Objective, PlannerParams

if TYPE_CHECKING:
    from planner.core import TreePlanner
    from planner.field import GridField
    from planner.problem import PlanningProblem


def planner_class(name: str) -> type[TreePlanner]:
    """The class registered as ``name``; ValueError for an unknown name."""
    entry = ENTRIES.get(name)
    if entry is None:
        raise ValueError(f"unknown planner {name!r} (expected one of: {', '.join(ALGORITHM_NAMES)})")
    module, cls = entry.target.split(":")
    return getattr(importlib.import_module(module), cls)


def make_planner(name: str, params: PlannerParams, seed: int | None = None) -> TreePlanner:
    """The planner called ``name`` (one of ALGORITHM_NAMES); ValueError for an unknown name."""
    return planner_class(name)(params, seed)


@dataclasses.dataclass(frozen=True)
class WarmUp:
    """What :func:`warm_up_info` did: ``seconds`` spent, and whether numba had to compile
    (``compiled``: a cold or stale cache; otherwise the machine code came from the cache)."""

    seconds: float
    compiled: bool


_WARM: WarmUp | None = None
# warm_up_info(algorithms): the planners warmed up so far in this process, and the last record
_WARMED: set[str] = set()
_WARMED_RECORD: list[WarmUp] = []


def _cache_misses() -> int:
    from planner import _kernels, _png, _tree, png

    n = 0
    for mod in (_tree, _kernels, _png, png):
        for obj in vars(mod).values():
            stats = getattr(obj, "stats", None)
            if stats is not None and hasattr(stats, "cache_misses"):
                n += sum(stats.cache_misses.values())
    return n


def warm_up_info(algorithms: tuple[str, ...] | None = None, tree_reuse: bool = True,
                 png: bool = True) -> WarmUp:
    """Load (or, with a cold cache, compile) every compiled function by solving tiny problems
    with every registered planner (or only those named in ``algorithms``: a process that runs one
    planner compiles only its kernels), with and without a current field, as the online loop does
    (heading, reference path, perceptual domain). Only the first call in a process does work;
    later calls return the first call's record. The first solve in a process otherwise pays
    ~0.2 s of cache loading (~7 s of compilation with a cold cache) inside its time budget.
    ``tree_reuse`` False: not the searches from a reused tree (``seed_tree``), which another
    process compiles at the same time (:func:`warm_up_tree_reuse`); ``png`` False: searches without
    the PGNode (``png_probability`` 0: the same tree-core types, the PGNode's kernels not called),
    which another process compiles likewise (:func:`warm_up_png`). Either makes the call
    unrecorded as a warm-up."""
    global _WARM
    for name in algorithms or ():
        planner_class(name)   # ValueError for an unknown name
    if _WARM is not None:
        return _WARM
    if algorithms is not None:
        if set(algorithms) <= _WARMED:
            return _WARMED_RECORD[0]
    from planner.core import compiled_clock_ok, compiled_cpu_clock_ok
    from planner.termination import Termination

    t0 = time.monotonic()
    misses0 = _cache_misses()
    problems = _warm_up_problems()
    grid = problems[0][1].grid
    grid.segment_free(1.0, 1.0, 18.0, 18.0)
    grid.polyline_free(np.array([[2.0, 10.0], [18.0, 10.0]]))
    names = [e.name for e in REGISTRY if algorithms is None or e.name in algorithms]
    for objective, problem in problems:
        for repair in (False, True) if png else (False,):
            params = PlannerParams(max_nodes=2000, objective=objective, png_repair=repair)
            if not png:
                params = dataclasses.replace(params, png_probability=0.0)
            for name in names:
                if repair and not planner_class(name).uses_png:
                    continue
                r = make_planner(name, params).solve(problem, Termination.iterations(300))
                if not repair and tree_reuse:   # a search from a reused tree (online tree_reuse): seed_tree too
                    reuse = dataclasses.replace(problem, initial_tree=(r.tree_nodes, r.tree_parents))
                    make_planner(name, params).solve(reuse, Termination.iterations(10))
    compiled_clock_ok()
    compiled_cpu_clock_ok()  # else the first thread-CPU deadline checks its clock inside its budget
    record = WarmUp(seconds=time.monotonic() - t0, compiled=_cache_misses() > misses0)
    if not (tree_reuse and png):
        return record
    if algorithms is None:
        _WARM = record
    else:
        _WARMED.update(names)
        _WARMED_RECORD[:] = [record]
    return record


def warm_up_tree_reuse(algorithms: tuple[str, ...]) -> None:
    """Compile (or load) only what a search from a reused tree adds (``seed_tree``), with the
    argument types :func:`warm_up_info` gives it, without running a search: searches of 0
    iterations from a 3-node tree never call the tree core. For a process that compiles beside
    one running ``warm_up_info(algorithms, tree_reuse=False)``."""
    from planner.termination import Termination

    for name in algorithms:
        planner_class(name)   # ValueError for an unknown name
    tree = (np.array([[2.0, 10.0], [3.0, 10.0], [4.0, 10.5]]), np.array([-1, 0, 1]))
    for objective, problem in _warm_up_problems():
        params = PlannerParams(max_nodes=2000, objective=objective)
        for name in algorithms:
            make_planner(name, params).solve(dataclasses.replace(problem, initial_tree=tree),
                                             Termination.iterations(0))


def warm_up_png(algorithms: tuple[str, ...]) -> None:
    """Compile (or load) only the PGNode's kernels (``planner._png``: the target and its repair),
    with the argument types :func:`warm_up_info`'s searches give them, without a search
    (``png_node`` alone never calls a tree core). For a process that compiles beside one running
    ``warm_up_info(algorithms, png=False)``."""
    for name in algorithms:
        planner_class(name)   # ValueError for an unknown name
    for objective, problem in _warm_up_problems():
        for repair in (False, True):
            params = PlannerParams(max_nodes=2000, objective=objective, png_repair=repair)
            for name in algorithms:
                if planner_class(name).uses_png:
                    make_planner(name, params).png_node(problem)


def _warm_up_problems() -> list[tuple[Objective, PlanningProblem]]:
    """The warm-up's tiny problems, one per objective: a 20 m square with a wall across it, from (2, 10) to
    (18, 10) m along a reference path, in still water (length) and in a uniform current (current)."""
    from planner.field import GridField
    from planner.gridmap import OccupancyGrid
    from planner.problem import PlanningProblem

    occ = np.zeros((40, 40), dtype=bool)
    occ[10:30, 19:21] = True
    grid = OccupancyGrid(occ, 0.5)
    ref = np.array([[2.0, 10.0], [18.0, 10.0]])
    cases: tuple[tuple[Objective, GridField | None], ...] = (("length", None),
                                                            ("current", GridField.uniform(0.3, 0.1)))
    return [(objective, PlanningProblem(grid, (2.0, 10.0), (18.0, 10.0), start_heading=0.0, field=field,
                                        reference_path=ref, domain_center=(10.0, 10.0), domain_radius=12.0))
            for objective, field in cases]


def warm_up() -> float:
    """:func:`warm_up_info`, returning the seconds it took."""
    return warm_up_info().seconds
