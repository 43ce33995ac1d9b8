"""DDRRT*'s PGNode, compiled: the target on the reference path, eqs. (7)-(8), and its repair.

:func:`png_target` is what :meth:`planner.ddrrt_star.DDRRTStar.png_node` computed in Python
(about 0.1 ms a cycle, inside the timed search); compiled it costs a few microseconds and gives
the same point bit for bit (tests/test_planner_png_repair.py). With ``repair`` the point is moved
to the nearest free cell centre inside the sampling domain that lies in the start's free region
(issue 34: in Table 3's cycles the raw PGNode lay inside an inflated obstacle in 49 % of cycles,
where every PNG sample was wasted).
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from planner.png import hypot, pg_node


@njit(cache=True)
def _nearest_index(ref: np.ndarray, x: float, y: float) -> int:
    """Index of the first reference point nearest (x, y)."""
    best = 0
    bd = hypot(ref[0, 0] - x, ref[0, 1] - y)
    for i in range(1, ref.shape[0]):
        d = hypot(ref[i, 0] - x, ref[i, 1] - y)
        if d < bd:
            bd = d
            best = i
    return best


@njit(cache=True)
def raw_target(sx: float, sy: float, heading: float, gx: float, gy: float, ref: np.ndarray, nav_ratio: float,
               tol: float, max_iter: int, box: np.ndarray) -> tuple[float, float]:
    """The PGNode of eqs. (7)-(8), clipped to ``box`` (xmin, xmax, ymin, ymax); ``heading`` nan =
    none (the heading towards the reference point nearest the start). The USV covers its
    straight-line distance to the goal in one guidance step (s_t = |goal - start| / 2), so the
    PGNode is never farther than the (sub)goal."""
    j = _nearest_index(ref, sx, sy)
    k = _nearest_index(ref, gx, gy)
    n = ref.shape[0]
    if k <= j:
        k = min(j + 1, n - 1)
    if j == n - 1:
        j = max(0, j - 1)
    t_head = math.atan2(ref[j + 1, 1] - ref[j, 1], ref[j + 1, 0] - ref[j, 0])
    if math.isnan(heading):
        dx = ref[j, 0] - sx
        dy = ref[j, 1] - sy
        heading = math.atan2(dy, dx) if hypot(dx, dy) > 1e-9 else t_head
    s_t = 0.5 * hypot(gx - sx, gy - sy)
    x, y = pg_node((sx, sy), heading, (ref[j, 0], ref[j, 1]), t_head, s_t, nav_ratio, tol, max_iter)
    return min(max(x, box[0]), box[1]), min(max(y, box[2]), box[3])


@njit(cache=True)
def _usable(occ: np.ndarray, labels: np.ndarray, res: float, x: float, y: float, region: int, box: np.ndarray,
            cx: float, cy: float, radius: float) -> bool:
    c = int(math.floor(x / res))
    r = int(math.floor(y / res))
    if r < 0 or c < 0 or r >= occ.shape[0] or c >= occ.shape[1] or occ[r, c] != 0:
        return False
    if labels[r, c] != region:
        return False
    if x < box[0] or x > box[1] or y < box[2] or y > box[3]:
        return False
    return radius <= 0.0 or hypot(x - cx, y - cy) <= radius


@njit(cache=True)
def repair(x: float, y: float, occ: np.ndarray, labels: np.ndarray, res: float, region: int, box: np.ndarray,
           cx: float, cy: float, radius: float) -> tuple[float, float]:
    """(x, y) itself if it is free, in the start's free region (label ``region``) and in the
    sampling domain (``box``, and the disc of ``radius`` about (cx, cy) when radius > 0); else the
    nearest cell centre that is; else (nan, nan). Rings of cells outwards from (x, y)'s cell: a
    cell in ring q has its centre at least (q - 0.5) res away, so the search stops once the best
    found is nearer than the next ring can be."""
    if _usable(occ, labels, res, x, y, region, box, cx, cy, radius):
        return x, y
    rows, cols = occ.shape
    c0 = min(max(int(math.floor(x / res)), 0), cols - 1)
    r0 = min(max(int(math.floor(y / res)), 0), rows - 1)
    bx = math.nan
    by = math.nan
    bd = math.inf
    for q in range(max(rows, cols) + 1):
        if bd <= (q - 0.5) * res:
            break
        for r in range(r0 - q, r0 + q + 1):
            if r < 0 or r >= rows:
                continue
            edge_row = r == r0 - q or r == r0 + q
            c = c0 - q
            while c <= c0 + q:
                if 0 <= c < cols:
                    px = (c + 0.5) * res
                    py = (r + 0.5) * res
                    d = hypot(px - x, py - y)
                    if d < bd and _usable(occ, labels, res, px, py, region, box, cx, cy, radius):
                        bd = d
                        bx = px
                        by = py
                if edge_row or q == 0:
                    c += 1
                else:
                    c += 2 * q
    return bx, by


def reference(ref: np.ndarray | None, start: tuple[float, float], goal: tuple[float, float]) -> np.ndarray:
    """The reference polyline as a float64 (M >= 2, 2) array: the straight start-goal line when
    there is none."""
    if ref is None or len(ref) < 2:
        return np.array([[float(start[0]), float(start[1])], [float(goal[0]), float(goal[1])]])
    return np.ascontiguousarray(ref, dtype=np.float64)
