"""Time per iteration inside whole Table 3 runs (labyrinth runs 0-5, RRT* on length vs DDRRT* on
eq. (12)): thread CPU time in the compiled `grow`, in `TreePlanner.solve` and over the whole run,
each algorithm twice (interleaved). Run: python docs/experiments/ddrrt/in_runs.py [RUNS]"""
import sys
import time

import planner.core as core
from hil import experiment as e
from planner import _tree

e.warm_up()
acc = {"grow": 0.0, "solve": 0.0}
_grow = _tree.grow
_solve = core.TreePlanner.solve


class _Timed:
    def __getattr__(self, k):
        return getattr(_tree, k)

    def grow(self, *a):
        t = time.thread_time()
        r = _grow(*a)
        acc["grow"] += time.thread_time() - t
        return r


def _timed_solve(self, *a, **k):
    t = time.thread_time()
    r = _solve(self, *a, **k)
    acc["solve"] += time.thread_time() - t
    return r


core._tree = _Timed()
core.TreePlanner.solve = _timed_solve
runs = int(sys.argv[1]) if len(sys.argv) > 1 else 6
for alg in ("rrt-star", "ddrrt-star", "rrt-star", "ddrrt-star"):
    acc.update(grow=0.0, solve=0.0)
    it = 0
    t0 = time.thread_time()
    for task in e.make_tasks("labyrinth", runs, [alg], 1, {}, None, (), 0, "length"):
        it += e.run_task(task)["iterations"]
    whole = time.thread_time() - t0
    print(f"{alg:11} grow {acc['grow'] / it * 1e6:.2f} us/it  solve {acc['solve'] / it * 1e6:.2f} us/it  "
          f"whole run {whole / it * 1e6:.2f} us/it", flush=True)
