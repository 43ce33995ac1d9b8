"""Sampling-based local path planning for USVs (Wen et al. 2019), a pure algorithm library.

Map frame: x east, y north (metres), angles counter-clockwise from +x (radians). Imports
nothing of the rest of the project (numpy, scipy, numba only).
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Protocol

from planner.params import ALGORITHM_NAMES, REGISTRY, PlannerParams

# The one registry of planners (planner.params.REGISTRY: name, label, colour, class; hil's commands,
# experiments, figures and benches read it). Importable without numba: `import planner.params` only
# loads that light module.
ALGORITHMS = ALGORITHM_NAMES

if TYPE_CHECKING:
    from planner.problem import PlanningProblem
    from planner.registry import WarmUp
    from planner.result import PlannerResult
    from planner.termination import Termination

# Loaded on first use (PEP 562), so that `import planner.params` does not compile numba kernels.
_LAZY = {"PlanningProblem": "planner.problem", "PlannerResult": "planner.result", "Termination": "planner.termination"}


def __getattr__(name: str) -> type:
    if name in _LAZY:
        import importlib

        return getattr(importlib.import_module(_LAZY[name]), name)
    raise AttributeError(f"module 'planner' has no attribute {name!r}")


class Planner(Protocol):
    def solve(self, problem: PlanningProblem, termination: Termination) -> PlannerResult: ...


def make_planner(name: str, params: PlannerParams, seed: int | None = None) -> Planner:
    """The planner called ``name`` (one of ALGORITHMS, the table ``planner.params.REGISTRY``);
    ValueError for an unknown name."""
    from planner.registry import make_planner as _make

    return _make(name, params, seed)


def warm_up() -> float:
    """Load or compile the numba core before time-critical use (once per process: call it in
    every worker before its first timed solve); returns the seconds spent."""
    from planner.registry import warm_up as _warm_up

    return _warm_up()


def warm_up_info(algorithms: tuple[str, ...] | None = None, tree_reuse: bool = True, png: bool = True) -> WarmUp:
    """:func:`warm_up`, returning ``planner.registry.WarmUp(seconds, compiled)``: ``compiled`` is
    True when numba had to compile (a cold cache) rather than load machine code. ``algorithms``:
    only these planners' kernels (default: every registered planner's); ``tree_reuse`` False:
    without the searches from a reused tree, ``png`` False: without the PGNode
    (see ``planner.registry.warm_up_info``)."""
    from planner.registry import warm_up_info as _info

    return _info(algorithms, tree_reuse, png)


def warm_up_tree_reuse(algorithms: tuple[str, ...]) -> None:
    """Compile only what a search from a reused tree adds (``planner.registry.warm_up_tree_reuse``)."""
    from planner.registry import warm_up_tree_reuse as _reuse

    _reuse(algorithms)


def warm_up_png(algorithms: tuple[str, ...]) -> None:
    """Compile only the PGNode's kernels (``planner.registry.warm_up_png``)."""
    from planner.registry import warm_up_png as _png

    _png(algorithms)


__all__ = ["warm_up", "warm_up_info", "warm_up_tree_reuse", "warm_up_png", "ALGORITHMS", "REGISTRY",
           "Planner", "PlannerParams", "PlannerResult", "PlanningProblem", "Termination", "make_planner"]
