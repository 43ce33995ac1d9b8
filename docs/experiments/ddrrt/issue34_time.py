"""Thread CPU time of 20,000 iterations of RRT* and DDRRT* (eq. (12)) on the inflated labyrinth,
best of 5: `python docs/experiments/ddrrt/issue34_time.py LABEL`. For an A/B against an older
commit C: `git archive C planner hil common simulator autopilot_bridge configs | tar -x -C /tmp/old`,
then `cd /tmp/old && PYTHONPATH=/tmp/old python <this file> old`, alternating with this tree."""
import sys
import time

from hil import scenario as scenarios
from planner import PlannerParams, make_planner, warm_up
from planner.gridmap import OccupancyGrid
from planner.problem import PlanningProblem
from planner.termination import Termination

warm_up()
sc = scenarios.instance(scenarios.load_spec("labyrinth"), None)
grid = OccupancyGrid(sc.occ, sc.resolution).inflate(2.0)
pr = PlanningProblem(grid, tuple(sc.start), tuple(sc.goal), field=sc.planning_field())
out = []
for alg in ("rrt-star", "ddrrt-star"):
    best = 1e9
    for _ in range(5):
        t = time.thread_time()
        make_planner(alg, PlannerParams(objective="current"), seed=1).solve(pr, Termination.iterations(20000))
        best = min(best, time.thread_time() - t)
    out.append(f"{alg} {best*1e3:.1f} ms")
print(sys.argv[1], "; ".join(out))
