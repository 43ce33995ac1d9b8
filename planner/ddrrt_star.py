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

from planner import _tree
from planner.core import TreePlanner
from planner.png import pg_node
from planner.problem import PlanningProblem


class DDRRTStar(TreePlanner):
    algorithm_code = _tree.DDRRT_STAR
    name = "ddrrt-star"
    uses_png = True

    def png_node(self, problem: PlanningProblem) -> tuple[float, float] | None:
        sx, sy = map(float, problem.start)
        gx, gy = map(float, problem.goal)
        ref = problem.reference_path
        if ref is None or len(ref) < 2:
            ref = np.array([[sx, sy], [gx, gy]])
        ref = np.asarray(ref, dtype=np.float64)
        j = int(np.argmin(np.hypot(ref[:, 0] - sx, ref[:, 1] - sy)))
        k = int(np.argmin(np.hypot(ref[:, 0] - gx, ref[:, 1] - gy)))
        if k <= j:
            k = min(j + 1, len(ref) - 1)
        if j == len(ref) - 1:
            j = max(0, j - 1)
        seg = np.diff(ref[j:k + 1], axis=0)
        arc = float(np.sum(np.hypot(seg[:, 0], seg[:, 1]))) if len(seg) else 0.0
        arc = max(arc, math.hypot(gx - sx, gy - sy))
        t_head = math.atan2(ref[j + 1, 1] - ref[j, 1], ref[j + 1, 0] - ref[j, 0])
        heading = problem.start_heading
        if heading is None:
            dx, dy = ref[j, 0] - sx, ref[j, 1] - sy
            heading = math.atan2(dy, dx) if math.hypot(dx, dy) > 1e-9 else t_head
        p = self.params
        # the USV (twice the target's speed) covers its straight-line distance to the goal in one
        # guidance step: the PGNode is never farther away than the (sub)goal
        s_t = 0.5 * min(arc, math.hypot(gx - sx, gy - sy))
        x, y = pg_node((sx, sy), heading, ref[j], t_head, s_t, p.png_nav_ratio, p.png_tolerance,
                       p.png_max_iterations)
        bx0, bx1, by0, by1 = problem.sampling_box()
        return min(max(x, bx0), bx1), min(max(y, by0), by1)
