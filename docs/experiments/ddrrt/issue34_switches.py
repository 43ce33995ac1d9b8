"""Issue 34 switches on labyrinth (global goal outside a 33 m domain, heading 0.3 rad, P = 0.7, fixed k,
1,500 iterations, 8 seeds): samples dropped, failed extensions (and the fan's), tree size, wasted PNG
samples per tree. `python docs/experiments/ddrrt/issue34_switches.py`."""
from dataclasses import replace

from hil import scenario as scenarios
from planner import PlannerParams, make_planner
from planner.gridmap import OccupancyGrid
from planner.problem import PlanningProblem
from planner.termination import Termination

sc = scenarios.instance(scenarios.load_spec("labyrinth"), None)
grid = OccupancyGrid(sc.occ, sc.resolution).inflate(2.0)
s, g = tuple(sc.start), tuple(sc.goal)
pr = PlanningProblem(grid, s, g, field=sc.planning_field(), domain_center=s, domain_radius=33.0,
                     reference_path=sc.reference_path, start_heading=0.3)
base = PlannerParams(png_probability=0.7, k_growth=0.0)
cases = (("off", replace(base, dynamic_domain="off")),
         ("constant DR=40", replace(base, dynamic_domain="constant")),
         ("constant 8 m", replace(base, dynamic_domain="constant", dd_radius=8.0)),
         ("fan failures", replace(base, dynamic_domain="constant", failed_extension="collision+turn")),
         ("png_repair", replace(base, dynamic_domain="constant", png_repair=True)))
for name, p in cases:
    rej = fail = turns = nodes = wasted = 0
    for seed in range(1, 9):
        r = make_planner("ddrrt-star", p, seed=seed).solve(pr, Termination.iterations(1500))
        rej += r.samples_rejected
        fail += r.diagnostics["failed_extensions"]
        turns += r.diagnostics["failed_turns"]
        nodes += len(r.tree_nodes)
        wasted += r.diagnostics["png_wasted"]
    print(f"{name:16s} rejected {rej / 8:7.1f} failed {fail / 8:7.1f} (fan {turns / 8:6.1f}) "
          f"nodes {nodes / 8:7.1f} png_wasted {wasted / 8:7.1f}")
