"""What a planner returns."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np


@dataclass
class PlannerResult:
    """Outcome of one ``solve``.

    ``status``: "exact" (the path ends exactly at the goal), "approximate" (ends at the tree node
    closest to the goal) or "none" (no path; ``reason`` says why).
    """

    status: str
    path: np.ndarray               # (N, 2) waypoints, start first; (0, 2) for "none"
    cost: float                    # sum of eq. (12) (== length for objective "length" / no field)
    length: float                  # m
    iterations: int                # samples drawn
    time_to_first_solution_s: float | None
    planning_time_s: float
    reason: str
    tree_nodes: np.ndarray         # (n, 2)
    tree_parents: np.ndarray       # (n,) int, -1 for the root
    samples_rejected: int          # DDRRT* ESD rejections (lines 10-11 of Figure 6)
    diagnostics: dict = field(default_factory=dict)

    @property
    def solved(self) -> bool:
        return self.status == "exact"
