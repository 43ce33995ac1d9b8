"""The exact shortest collision-free path on an occupancy grid (the benchmark's reference optimum).

Written independently of ``planner/`` so it can judge it. The free space is the open complement
of the union of occupied cells (and of everything outside the map). A shortest path in such a
polygonal domain is a polyline that bends only at convex obstacle corners, so a visibility graph
over those corners plus Dijkstra gives the optimum (Lozano-Perez & Wesley 1979).

* Vertices: a lattice point (cell corner) is a convex corner seen from a free cell ``c`` when the
  cell diagonally opposite ``c`` around that point is occupied and the two cells sharing an edge
  with ``c`` around it are free. The vertex is placed a tiny ``eps`` into ``c`` (along the
  diagonal), so straight edges between vertices never touch an obstacle corner exactly and
  pass a collision check that counts corner touches as collisions (as ``planner.gridmap`` does).
* Edges: pairs of vertices whose straight segment only crosses free cells, checked by an exact
  grid traversal (Amanatides & Woo 1987) compiled with numba; a segment through a lattice point
  is blocked if either diagonal neighbour there is occupied.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numba
import numpy as np
from scipy.sparse import csr_matrix
from scipy.sparse.csgraph import dijkstra


@numba.njit(cache=True)
def _occupied(occ: np.ndarray, r: int, c: int) -> bool:
    if r < 0 or c < 0 or r >= occ.shape[0] or c >= occ.shape[1]:
        return True
    return occ[r, c]


@numba.njit(cache=True)
def segment_clear(occ: np.ndarray, res: float, x0: float, y0: float, x1: float, y1: float) -> bool:
    """True when the closed segment (x0, y0)-(x1, y1) (m) only touches free cells."""
    gx0, gy0, gx1, gy1 = x0 / res, y0 / res, x1 / res, y1 / res
    c, r = int(math.floor(gx0)), int(math.floor(gy0))
    c_end, r_end = int(math.floor(gx1)), int(math.floor(gy1))
    if _occupied(occ, r, c) or _occupied(occ, r_end, c_end):
        return False
    dx, dy = gx1 - gx0, gy1 - gy0
    step_c = 1 if dx > 0 else -1
    step_r = 1 if dy > 0 else -1
    inf = 1e300
    if dx != 0.0:
        t_max_c = ((c + 1 - gx0) if dx > 0 else (gx0 - c)) / abs(dx)
        t_delta_c = 1.0 / abs(dx)
    else:
        t_max_c, t_delta_c = inf, inf
    if dy != 0.0:
        t_max_r = ((r + 1 - gy0) if dy > 0 else (gy0 - r)) / abs(dy)
        t_delta_r = 1.0 / abs(dy)
    else:
        t_max_r, t_delta_r = inf, inf
    n = abs(c_end - c) + abs(r_end - r) + 2
    for _ in range(n):
        if c == c_end and r == r_end:
            return True
        if abs(t_max_c - t_max_r) < 1e-12:
            # Through a lattice point: both diagonal neighbours count (corner touch = collision).
            if t_max_c > 1.0:
                return True
            if _occupied(occ, r, c + step_c) or _occupied(occ, r + step_r, c):
                return False
            c += step_c
            r += step_r
            t_max_c += t_delta_c
            t_max_r += t_delta_r
        elif t_max_c < t_max_r:
            if t_max_c > 1.0:
                return True
            c += step_c
            t_max_c += t_delta_c
        else:
            if t_max_r > 1.0:
                return True
            r += step_r
            t_max_r += t_delta_r
        if _occupied(occ, r, c):
            return False
    return True


@numba.njit(cache=True)
def _visibility_edges(occ: np.ndarray, res: float, pts: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    n = pts.shape[0]
    src = []
    dst = []
    w = []
    for i in range(n):
        for j in range(i + 1, n):
            if segment_clear(occ, res, pts[i, 0], pts[i, 1], pts[j, 0], pts[j, 1]):
                src.append(i)
                dst.append(j)
                w.append(math.hypot(pts[i, 0] - pts[j, 0], pts[i, 1] - pts[j, 1]))
    return np.array(src, dtype=np.int64), np.array(dst, dtype=np.int64), np.array(w, dtype=np.float64)


def convex_corners(occ: np.ndarray, resolution: float, eps: float = 1e-6) -> np.ndarray:
    """(K, 2) metric points just off every convex obstacle corner (see the module docstring)."""
    occ = np.asarray(occ, dtype=bool)
    rows, cols = occ.shape
    pad = np.ones((rows + 2, cols + 2), dtype=bool)   # outside the map is occupied
    pad[1:-1, 1:-1] = occ
    # Lattice point (i, j) (i = row line 0..rows, j = col line 0..cols) is surrounded by the
    # padded cells sw = pad[i, j], se = pad[i, j+1], nw = pad[i+1, j], ne = pad[i+1, j+1].
    sw, se, nw, ne = pad[:-1, :-1], pad[:-1, 1:], pad[1:, :-1], pad[1:, 1:]
    out = []
    # (free cell, its opposite, its two edge neighbours, diagonal direction into the free cell)
    for free, opp, a, b, d in ((ne, sw, nw, se, (1, 1)), (nw, se, ne, sw, (-1, 1)),
                               (se, nw, ne, sw, (1, -1)), (sw, ne, nw, se, (-1, -1))):
        mask = ~free & opp & ~a & ~b
        i, j = np.nonzero(mask)
        x = j * resolution + d[0] * eps * resolution
        y = i * resolution + d[1] * eps * resolution
        out.append(np.column_stack([x, y]))
    return np.concatenate(out) if out else np.zeros((0, 2))


@dataclass(frozen=True)
class Optimum:
    """The shortest path: ``length`` (m, inf when none) and its ``path`` (N, 2), start first."""

    length: float
    path: np.ndarray
    vertices: int
    edges: int


def shortest_path(occ: np.ndarray, resolution: float, start: tuple[float, float], goal: tuple[float, float]) -> Optimum:
    """Euclidean shortest path from ``start`` to ``goal`` (m, map frame) among the occupied cells."""
    occ = np.ascontiguousarray(occ, dtype=np.bool_)
    corners = convex_corners(occ, resolution)
    pts = np.vstack([np.asarray(start, float)[None], np.asarray(goal, float)[None], corners])
    src, dst, w = _visibility_edges(occ, float(resolution), pts)
    n = len(pts)
    graph = csr_matrix((np.concatenate([w, w]), (np.concatenate([src, dst]), np.concatenate([dst, src]))), shape=(n, n))
    dist, pred = dijkstra(graph, directed=False, indices=0, return_predecessors=True)
    if not np.isfinite(dist[1]):
        return Optimum(math.inf, np.zeros((0, 2)), n, len(w))
    order = [1]
    while order[-1] != 0:
        order.append(int(pred[order[-1]]))
    return Optimum(float(dist[1]), pts[order[::-1]], n, len(w))
