"""RRT*'s thread CPU of a whole 1,500-iteration search a cycle in the campaign's `paper` cell (runs 0-19)."""
import statistics
from hil import experiment
from planner import core
import planner
planner.warm_up()
cpu = []
orig = core.TreePlanner.solve
def solve(self, problem, termination, seed=None):
    r = orig(self, problem, termination, seed)
    cpu.append(r.diagnostics.get("thread_cpu_s", 0.0) if r.diagnostics else 0.0)
    return r
core.TreePlanner.solve = solve
cfgo = ('planner.png_probability=0.7', 'planner.k_growth=0', 'planner.dynamic_domain="constant"')
for run in range(20):
    experiment.run_task(experiment.Task("labyrinth", run, "rrt-star", 1, config_overrides=cfgo, objective="length"))
print(len(cpu), "searches; median %.3f ms, mean %.3f ms, p10 %.3f, p90 %.3f" % (
    1e3 * statistics.median(cpu), 1e3 * statistics.mean(cpu),
    1e3 * statistics.quantiles(cpu, n=10)[0], 1e3 * statistics.quantiles(cpu, n=10)[-1]))
