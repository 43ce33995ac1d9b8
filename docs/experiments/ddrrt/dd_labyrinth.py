"""DDRRT*'s dynamic domain in Table 3 cycles of the labyrinth (current on, 33 m perceptual domain,
1500 iterations): failed extensions per node and the first-solution iteration, 8 seeds.
Run: python docs/experiments/ddrrt/dd_labyrinth.py"""

from dataclasses import replace

import numpy as np

from hil import scenario as scenarios
from planner import PlannerParams, make_planner
from planner.gridmap import OccupancyGrid
from planner.problem import PlanningProblem
from planner.termination import Termination

sc = scenarios.load("labyrinth")
base = scenarios.planner_params(PlannerParams(), sc.planner_overrides)
grid = OccupancyGrid(sc.occ, sc.resolution).inflate(base.safety_radius)
ref = np.asarray(sc.reference_path)
field = sc.planning_field()
for cx, cy in ((8.0, 8.0), (40.0, 62.0), (64.0, 45.0), (60.0, 20.0), (33, 71)):
    d = np.hypot(ref[:, 0] - cx, ref[:, 1] - cy)
    k = int(np.argmin(d))
    while k < len(ref) - 1 and np.hypot(ref[k, 0] - cx, ref[k, 1] - cy) < 28:
        k += 1
    prob = PlanningProblem(grid, (cx, cy), tuple(ref[k]), 0.0, field, ref, None, (cx, cy), 33.0)
    res = []
    for mode, extra in (
        ("off", {}),
        ("adaptive", {}),
        ("adaptive", {"dd_alpha": 0.3}),
        ("constant", {"dr_factor": 2.5}),
    ):
        p = replace(base, dynamic_domain=mode, **extra)
        F = N = 0
        FI = []
        for s in range(1, 9):
            r = make_planner("ddrrt-star", p, s).solve(prob, Termination.iterations(1500))
            F += r.diagnostics["failed_extensions"]
            N += len(r.tree_nodes) - 1
            FI.append(r.diagnostics["first_solution_iteration"] or 9999)
        res.append(f"{mode}{extra}: {F / N:.2f} first_it {np.median(FI):.0f}")
    print((cx, cy), " | ".join(res))
