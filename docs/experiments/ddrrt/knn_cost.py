"""Where a k-nearest query's time goes (docs/planner.md, "Time per iteration"): on the tree of a
Table 3 DDRRT* cycle (labyrinth, 1500 iterations, seed 1), the compiled `_tree._knn` at k = 1, 5, 15
on 20,000 uniform samples of the sampling box, against a scan of the same samples' 5 x 5 and 7 x 7
bucket blocks that reads every node's squared distance without ordering anything. Wall time per
query, minimum of 5 repetitions. Run: python docs/experiments/ddrrt/knn_cost.py"""
import time

import numpy as np
from numba import njit

import planner
import planner.core as core
from hil import scenario as scenarios
from planner import PlannerParams, _tree, make_planner
from planner.gridmap import OccupancyGrid
from planner.problem import PlanningProblem
from planner.termination import Termination

planner.warm_up()
sc = scenarios.load("labyrinth")
params = scenarios.planner_params(PlannerParams(), sc.planner_overrides)
grid = OccupancyGrid(sc.occ, sc.resolution).inflate(params.safety_radius)
ref = np.asarray(sc.reference_path)
calls = []
_grow = _tree.grow


class _Capture:
    def __getattr__(self, k):
        return getattr(_tree, k)

    def grow(self, *a):
        calls.append(a)
        return _grow(*a)


core._tree = _Capture()
cx, cy = 40.0, 62.0
k = int(np.argmin(np.hypot(ref[:, 0] - cx, ref[:, 1] - cy)))
while k < len(ref) - 1 and np.hypot(ref[k, 0] - cx, ref[k, 1] - cy) < 28:
    k += 1
prob = PlanningProblem(grid, (cx, cy), tuple(ref[k]), 0.0, sc.planning_field(), ref, None, (cx, cy),
                       params.perceptual_radius)
make_planner("ddrrt-star", params, 1).solve(prob, Termination.iterations(1500))
occ, fvx, fvy, fc, ic, X, parent, cost, head, dd, first_child, next_sib, bucket_head, node_next, st = calls[-1][:15]
rng = np.random.default_rng(0)
Q = np.column_stack([rng.uniform(fc[_tree.C_BX0], fc[_tree.C_BX1], 20000),
                     rng.uniform(fc[_tree.C_BY0], fc[_tree.C_BY1], 20000)])


@njit
def _queries(Q, k, X, fc, ic, bucket_head, node_next):
    out_i = np.empty(_tree.K_CAP, np.int64)
    out_d = np.empty(_tree.K_CAP)
    s = 0.0
    for q in range(Q.shape[0]):
        m = _tree._knn(Q[q, 0], Q[q, 1], k, X, fc, ic, bucket_head, node_next, out_i, out_d)
        s += out_d[m - 1]
    return s


@njit
def _scans(Q, rings, X, fc, ic, bucket_head, node_next):
    nbx = ic[_tree.I_NBX]
    nby = ic[_tree.I_NBY]
    s = 0.0
    for q in range(Q.shape[0]):
        qx = Q[q, 0]
        qy = Q[q, 1]
        bx0, by0 = _tree._bucket(qx, qy, fc, ic)
        for by in range(max(by0 - rings, 0), min(by0 + rings, nby - 1) + 1):
            for bx in range(max(bx0 - rings, 0), min(bx0 + rings, nbx - 1) + 1):
                j = bucket_head[by * nbx + bx]
                while j >= 0:
                    ex = X[j, 0] - qx
                    ey = X[j, 1] - qy
                    s += ex * ex + ey * ey
                    j = node_next[j]
    return s


def per_query(f, *a):
    f(*a)
    best = 1e9
    for _ in range(5):
        t = time.perf_counter()
        f(*a)
        best = min(best, time.perf_counter() - t)
    return best / len(Q) * 1e9


tree = (X, fc, ic, bucket_head, node_next)
print(f"tree: {st[_tree.S_N]} nodes, buckets of {fc[_tree.C_BUCKET]:g} m")
for k in (1, 5, 15):
    print(f"k-nearest, k = {k:2d}: {per_query(_queries, Q, k, *tree):6.0f} ns/query")
for rings in (2, 3):
    t = per_query(_scans, Q, rings, *tree)
    print(f"scan of the {2 * rings + 1} x {2 * rings + 1} block, no ordering: {t:6.0f} ns/query")
