"""Informed RRT* (Gammell, Srinivasa and Barfoot 2014): RRT* whose samples, once a solution of
cost c_best exists, are drawn directly and uniformly from the informed set
{x : h(start, x) + h(x, goal) <= c_best}, an ellipse with foci start and goal,
transverse diameter c_best and conjugate diameter sqrt(c_best^2 - c_min^2), rotated to the
world frame by the start-goal direction (the 2-D case of their prolate hyperspheroid).

With the current objective the admissible heuristic is h = f_min * Ed with
f_min = min(1, D_alpha / (1 + e)) (the smallest value of D_C / Ed, see ``cost.min_cost_factor``),
so the ellipse uses c_best / f_min. When the ellipse is larger than the sampling box the box is
sampled and points outside the ellipse are rejected (as OMPL does). No tree pruning.
"""

from __future__ import annotations

from planner import _tree
from planner.core import TreePlanner


class InformedRRTStar(TreePlanner):
    algorithm_code = _tree.INFORMED_RRT_STAR
    name = "informed-rrt-star"
