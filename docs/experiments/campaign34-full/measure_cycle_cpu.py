"""RRT*'s thread CPU of a whole 1,500-iteration search a cycle in the campaign's `paper` cell (runs 0-19).

    python docs/experiments/campaign34-full/measure_cycle_cpu.py
"""

import statistics

import planner
from hil import experiment
from planner import core

planner.warm_up()
cpu: list[float] = []
_solve = core.TreePlanner.solve


def solve(self, problem, termination, seed=None):
    r = _solve(self, problem, termination, seed)
    cpu.append(r.diagnostics.get("thread_cpu_s", 0.0) if r.diagnostics else 0.0)
    return r


core.TreePlanner.solve = solve  # type: ignore[method-assign]
PAPER = ('planner.png_probability=0.7', 'planner.k_growth=0', 'planner.dynamic_domain="constant"')
for run in range(20):
    experiment.run_task(experiment.Task("labyrinth", run, "rrt-star", 1, config_overrides=PAPER, objective="length"))
dec = statistics.quantiles(cpu, n=10)
print(f"{len(cpu)} searches; median {1e3 * statistics.median(cpu):.3f} ms, mean {1e3 * statistics.mean(cpu):.3f} ms, "
      f"p10 {1e3 * dec[0]:.3f}, p90 {1e3 * dec[-1]:.3f}")
