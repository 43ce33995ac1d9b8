"""Sampling-based local path planning for USVs (Wen et al. 2019), a pure algorithm library.

Map frame: x east, y north (metres), angles counter-clockwise from +x (radians). Imports
nothing of the rest of the project (numpy, scipy, numba only).
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any, Protocol

from planner.params import ALGORITHM_NAMES, PlannerParams

# The one registry of algorithm names (hil's commands, experiments and benches use it). It is
# importable without numba: `import planner.params` only loads this light module.
ALGORITHMS = ALGORITHM_NAMES

if TYPE_CHECKING:
    from planner.problem import PlanningProblem
    from planner.result import PlannerResult
    from planner.termination import Termination

# Loaded on first use (PEP 562), so that `import planner.params` does not compile numba kernels.
_LAZY = {"PlanningProblem": "planner.problem", "PlannerResult": "planner.result", "Termination": "planner.termination"}


def __getattr__(name: str) -> Any:
    if name in _LAZY:
        import importlib

        return getattr(importlib.import_module(_LAZY[name]), name)
    raise AttributeError(f"module 'planner' has no attribute {name!r}")


class Planner(Protocol):
    def solve(self, problem: PlanningProblem, termination: Termination) -> PlannerResult: ...


def make_planner(name: str, params: PlannerParams, seed: int | None = None) -> Planner:
    """The planner called ``name`` (one of ALGORITHMS); ValueError for an unknown name."""
    if name == "rrt-star":
        from planner.rrt_star import RRTStar

        return RRTStar(params, seed)
    if name == "informed-rrt-star":
        from planner.informed_rrt_star import InformedRRTStar

        return InformedRRTStar(params, seed)
    if name == "ddrrt-star":
        from planner.ddrrt_star import DDRRTStar

        return DDRRTStar(params, seed)
    raise ValueError(f"unknown planner {name!r} (expected one of: {', '.join(ALGORITHMS)})")


def warm_up() -> float:
    """Load or compile the numba core before time-critical use (once per process: call it in
    every worker before its first timed solve); returns the seconds spent."""
    from planner.core import warm_up as _warm_up

    return _warm_up()


def warm_up_info():
    """:func:`warm_up`, returning ``planner.core.WarmUp(seconds, compiled)``: ``compiled`` is
    True when numba had to compile (a cold cache) rather than load machine code."""
    from planner.core import warm_up_info as _info

    return _info()


__all__ = ["warm_up", "warm_up_info", "ALGORITHMS", "Planner", "PlannerParams", "PlannerResult", "PlanningProblem",
           "Termination", "make_planner"]
