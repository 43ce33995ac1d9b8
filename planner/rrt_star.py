"""RRT* (Karaman and Frazzoli 2011) on the shared tree core.

Nearest-node extension by at most ``step``, choose-parent and rewiring over the near ball of
radius min(rewire_gamma * gamma*_RRT * (log n / n)^(1/2), step) with
gamma*_RRT = 2 (1 + 1/d)^(1/d) (mu(X_free) / zeta_d)^(1/d), d = 2 (the radius version of the
paper; ``rewire_gamma`` plays OMPL's rewire factor). Goal bias sampling; costs are eq. (12)
(or length).
"""

from __future__ import annotations

from planner import _tree
from planner.core import TreePlanner


class RRTStar(TreePlanner):
    algorithm_code = _tree.RRT_STAR
    name = "rrt-star"
