"""Time per iteration of the compiled core (thread CPU time inside `_tree.grow`, so other processes'
load counts less), RRT* vs DDRRT*, on Table 3 cycles of the labyrinth: to the first solution and
over a whole 1500-iteration cycle. Minimum of 5 repetitions of 3 positions x 20 seeds.
Run: python docs/experiments/ddrrt/per_iteration.py"""

import time
from dataclasses import replace

import numpy as np

import planner
import planner.core as core
from hil import scenario as scenarios
from planner import PlannerParams, _tree, make_planner
from planner.gridmap import OccupancyGrid
from planner.problem import PlanningProblem
from planner.termination import Termination

planner.warm_up()
sc = scenarios.load("labyrinth")
base = scenarios.planner_params(PlannerParams(), sc.planner_overrides)
grid = OccupancyGrid(sc.occ, sc.resolution).inflate(base.safety_radius)
field = sc.planning_field()
ref = np.asarray(sc.reference_path)
_grow = _tree.grow
acc = [0.0]


class _Timed:
    def __getattr__(self, k):
        return getattr(_tree, k)

    def grow(self, *a):
        t = time.thread_time()
        r = _grow(*a)
        acc[0] += time.thread_time() - t
        return r


core._tree = _Timed()
POS = [(40.0, 62.0), (8.0, 8.0), (64.0, 45.0)]
for alg, obj in (("rrt-star", "length"), ("rrt-star", "current"), ("ddrrt-star", "current")):
    out = []
    for phase, term in (
        ("to first solution", lambda: Termination.any_of(Termination.iterations(3000), Termination.exact_solution())),
        ("1500-iteration cycle", lambda: Termination.iterations(1500)),
    ):
        p = replace(base, algorithm=alg, objective=obj)
        best = 1e9
        for _rep in range(5):
            n = 0
            acc[0] = 0.0
            for cx, cy in POS:
                d = np.hypot(ref[:, 0] - cx, ref[:, 1] - cy)
                k = int(np.argmin(d))
                while k < len(ref) - 1 and np.hypot(ref[k, 0] - cx, ref[k, 1] - cy) < 28:
                    k += 1
                prob = PlanningProblem(
                    grid, (cx, cy), tuple(ref[k]), 0.0, field, ref, None, (cx, cy), p.perceptual_radius
                )
                for s in range(1, 21):
                    n += make_planner(alg, p, s).solve(prob, term()).iterations
            best = min(best, acc[0] / n)
        out.append(f"{phase}: {best * 1e6:5.2f} us/iteration ({n / 60:5.0f} iterations/solve)")
    print(f"{alg:11} {obj:8}", "   ".join(out), flush=True)
