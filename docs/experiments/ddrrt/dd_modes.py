"""DDRRT*'s dynamic domain modes on the bench maps (length objective, no fan, no inflation): failed
extensions per accepted node and the first solution, median over 10 seeds (docs/planner.md).
Run: python docs/experiments/ddrrt/dd_modes.py"""

import numpy as np

import planner
from hil import scenario as scenarios
from planner import PlannerParams, make_planner
from planner.gridmap import OccupancyGrid
from planner.problem import PlanningProblem
from planner.termination import Termination

planner.warm_up()
settings = None
for name in ("bench_bugtrap", "bench_maze", "bench_discs"):
    sc = scenarios.load(name, None)
    grid = OccupancyGrid(sc.occ, sc.resolution)
    prob = PlanningProblem(grid, sc.start, sc.goal)
    for alg, mode in (
        ("rrt-star", "off"),
        ("ddrrt-star", "off"),
        ("ddrrt-star", "constant"),
        ("ddrrt-star", "adaptive"),
    ):
        p = PlannerParams(
            algorithm=alg, objective="length", turn_radius_factor=0.0, safety_radius=0.0, dynamic_domain=mode
        )
        F = []
        A = []
        FI = []
        T = []
        R = []
        for s in range(1, 11):
            r = make_planner(alg, p, s).solve(
                prob, Termination.any_of(Termination.iterations(200000), Termination.exact_solution())
            )
            n = len(r.tree_nodes)
            F.append(r.diagnostics.get("failed_extensions", 0) / max(n - 1, 1))
            FI.append(r.diagnostics["first_solution_iteration"] or -1)
            T.append(r.time_to_first_solution_s or np.nan)
            R.append(r.samples_rejected / r.iterations)
        print(
            f"{name:14} {alg:10} {mode:9} failed/node {np.median(F):.3f}  first_it {np.median(FI):8.0f} "
            f"first_ms {np.nanmedian(T) * 1e3:7.2f} rej {np.median(R):.3f}"
        )
