"""Time per iteration of the compiled tree core, before/after, interleaved in one process (issues
13 and 17): planner/_tree.py of BASE (git show) and of the working tree, compiled side by side
(numba cache off), run on the same grow() calls captured from labyrinth run 0 of each algorithm in
the Table 3 setting (RRT*/IRRT* on length, DDRRT* on eq. (12)), same RNG seed; thread CPU time,
minimum of 5 interleaved rounds. Also checks that both cores grow the same trees (state counters,
node coordinates, parents, costs). Assumes planner/_kernels.py is unchanged since BASE.
Run: python docs/experiments/ddrrt/core_before_after.py BASE_COMMIT"""
import subprocess
import sys
import time
import types

import numpy as np

import planner.core as core
from hil import experiment as e
from planner import _tree

base = sys.argv[1]
srcs = {"before": subprocess.run(["git", "show", f"{base}:planner/_tree.py"], check=True, capture_output=True,
                                 text=True).stdout,
        "after": open(_tree.__file__).read()}
algs = ("rrt-star", "informed-rrt-star", "ddrrt-star")
e.warm_up()
calls = []
_grow = _tree.grow


class _Capture:
    def __getattr__(self, k):
        return getattr(_tree, k)

    def grow(self, *a):
        calls.append([x.copy() if isinstance(x, np.ndarray) else x for x in a])
        return _grow(*a)


core._tree = _Capture()
caps = {}
for alg in algs:
    calls = []
    e.run_task(e.make_tasks("labyrinth", 1, [alg], 1, {}, None, (), 0, "length")[0])
    caps[alg] = calls
core._tree = _tree
mods = {}
for name, s in srcs.items():
    m = types.ModuleType("tree_" + name)
    exec(compile(s.replace("cache=True", "cache=False"), "tree_" + name, "exec"), m.__dict__)
    mods[name] = m
res = {}
sig = {}
for _rep in range(5):
    for alg in algs:
        for name, m in mods.items():
            tot = 0.0
            it = 0
            h = []
            for a in caps[alg]:
                b = [x.copy() if isinstance(x, np.ndarray) else x for x in a]
                m.seed_rng(11)
                t = time.thread_time()
                m.grow(*b)
                tot += time.thread_time() - t
                st = b[14]
                n = st[m.S_N]
                it += st[m.S_ITER]
                h.append((tuple(st.tolist()), b[5][:n].tobytes(), b[6][:n].tobytes(), b[7][:n].tobytes()))
            res[(name, alg)] = min(res.get((name, alg), 1e9), tot / it * 1e6)
            sig[(name, alg)] = hash(tuple(h))
for alg in algs:
    b, a = res[("before", alg)], res[("after", alg)]
    print(f"{alg:18} before {b:6.3f} us/it  after {a:6.3f} us/it  before/after {b / a:5.2f}x  "
          f"same trees: {sig[('before', alg)] == sig[('after', alg)]}")
for name in mods:
    print(f"{name}: DDRRT*/RRT* per iteration {res[(name, 'ddrrt-star')] / res[(name, 'rrt-star')]:.2f}, "
          f"IRRT*/RRT* {res[(name, 'informed-rrt-star')] / res[(name, 'rrt-star')]:.2f}")
