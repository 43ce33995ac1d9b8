"""DDRRT* (Wen et al. 2019, section 3.5, Figure 6).

Per sample q_s (the PGNode with probability P, else the goal with probability goal_bias, else
uniform in the perceptual domain): of the k nearest nodes, q_i is extendable if q_s lies in its
dynamic domain (Euclidean distance <= DD(q_i), Yershova et al. 2005) and D_C(q_i, q_s) of eq. (12)
is at most the current term of eq. (11) (one alpha_y, the current at q_i); when none is, the
sample is dropped (lines 10-11). q_new is one step from the extendable node of least D_C towards
q_s; the extendable nodes are tried as parents in order of c(q_i) + D_C(q_i, q_new); a collision
bounds DD(q_i) (DR = 10 v sigma_t at the first failure) and, with the adaptive domain (Jaillet et
al. 2005), shrinks it at later failures and grows it at successes; DD starts at infinity.
Rewiring (lines 18-21) tries the other extendable nodes through q_new. docs/planner.md explains
why this reading of eq. (11) (taken literally, DD never acts at D_alpha = 1).

The PGNode comes from :func:`planner.png.pg_node`: the virtual target is the reference waypoint
nearest the start, moving along the reference path; the USV covers twice the target's distance
per step, and the step is chosen so that the USV covers its straight-line distance to the goal
(s_t = |goal - start| / 2): the PGNode is never farther than the (sub)goal. Without a reference
path the straight start-goal line is the reference.
"""

from __future__ import annotations

import math

import numpy as np

from planner import _png, _tree
from planner.core import TreePlanner, free_regions
from planner.problem import PlanningProblem


class DDRRTStar(TreePlanner):
    algorithm_code = _tree.DDRRT_STAR
    name = "ddrrt-star"
    uses_png = True

    def png_node(self, problem: PlanningProblem) -> tuple[float, float] | None:
        """The PGNode (compiled, :mod:`planner._png`); with ``png_repair`` moved into usable free
        space (None where the start's free region has no cell in the sampling domain)."""
        p = self.params
        sx, sy = map(float, problem.start)
        gx, gy = map(float, problem.goal)
        ref = _png.reference(problem.reference_path, (sx, sy), (gx, gy))
        heading = math.nan if problem.start_heading is None else float(problem.start_heading)
        box = np.array(problem.sampling_box(), dtype=np.float64)
        x, y = _png.raw_target(sx, sy, heading, gx, gy, ref, float(p.png_nav_ratio), float(p.png_tolerance),
                               int(p.png_max_iterations), box)
        if not p.png_repair:
            return x, y
        grid = problem.grid
        labels = free_regions(grid)
        region = int(labels[grid.cell_of(sx, sy)])
        cx, cy, radius = 0.0, 0.0, 0.0
        if problem.domain_center is not None and problem.domain_radius is not None:
            cx, cy = map(float, problem.domain_center)
            radius = float(problem.domain_radius)
        x, y = _png.repair(x, y, grid._u8, labels, float(grid.resolution), region, box, cx, cy, radius)
        return None if math.isnan(x) else (x, y)
