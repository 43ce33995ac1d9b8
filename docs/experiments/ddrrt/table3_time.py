"""Where a Table 3 run's time goes (issue 17): thread CPU time of each labyrinth run (the campaign's
task, `hil.experiment.run_task`, Table 3 setting: RRT*/IRRT* on length, DDRRT* on eq. (12)) and
of the compiled tree growth inside it, per algorithm, warmed up, in one process.
Run: python docs/experiments/ddrrt/table3_time.py FIRST_RUN NRUNS [cprofile]
Before/after: run it from a checkout of the older commit with PYTHONPATH pointing there."""
import cProfile
import pstats
import sys
import time

import planner.core as core
from hil import experiment as e
from planner import _tree

e.warm_up()
acc = {"grow": 0.0}
_grow = _tree.grow


class _Timed:
    def __getattr__(self, k):
        return getattr(_tree, k)

    def grow(self, *a):
        t = time.thread_time()
        r = _grow(*a)
        acc["grow"] += time.thread_time() - t
        return r


core._tree = _Timed()
first, nr = int(sys.argv[1]), int(sys.argv[2])
tasks = [t for t in e.make_tasks("labyrinth", first + nr, e.ALGORITHMS, 1, {}, None, (), 9, "length") if t.run >= first]
e.run_task(tasks[0])  # fills the per-process caches (context, inflation)
tot: dict[str, float] = {}
gr: dict[str, float] = {}
it: dict[str, int] = {}
prof = cProfile.Profile() if len(sys.argv) > 3 else None
for t in tasks:
    acc["grow"] = 0.0
    t0 = time.thread_time()
    if prof:
        prof.enable()
    row = e.run_task(t)
    if prof:
        prof.disable()
    tot[t.algorithm] = tot.get(t.algorithm, 0.0) + time.thread_time() - t0
    gr[t.algorithm] = gr.get(t.algorithm, 0.0) + acc["grow"]
    it[t.algorithm] = it.get(t.algorithm, 0) + row["iterations"]
T = sum(tot.values())
for a in tot:
    print(f"{a:18} total {tot[a] / nr:6.3f} s/run  grow {gr[a] / nr:6.3f} s/run "
          f"({100 * gr[a] / tot[a]:4.1f} % of its run)  {1e6 * gr[a] / it[a]:5.2f} us/iter  "
          f"{it[a] / nr:7.0f} iter/run  share of all {100 * tot[a] / T:4.1f} %")
print(f"all: {T / nr:.3f} s per run of the three; grow {100 * sum(gr.values()) / T:.1f} %")
if prof:
    pstats.Stats(prof).sort_stats("tottime").print_stats(25)
