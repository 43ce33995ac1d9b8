"""The least eq. (12) cost between two points on an occupancy grid in a current: the judge of the
planners' ``objective = "current"`` (issue 34 point 3).

Written independently of ``planner/`` (it shares only :func:`hil.optimum.segment_clear`, the
judge of length's collision check). The cost of a path is the integral along it of

    f(alpha_y) = min{1, D_alpha / (1 + exp(cos alpha_y - gamma_alpha sin alpha_y))}

per metre, alpha_y in [0, pi] the angle between the direction of motion and the current at that
point (f = 1 where the current is below 1e-9 m/s): eq. (12) with Ed -> ds. :func:`path_cost`
integrates it with the midpoint rule on pieces of at most ``PIECE`` metres, the current
interpolated bilinearly from a grid sampled here.

:func:`flow_optimum`:

1. Dijkstra on a directed lattice: the free cell centres of the grid, each joined to its 16
   neighbours ((1, 0), (1, 1), (2, 1) and their mirror images: headings every 26.6 deg at most),
   an edge where :func:`hil.optimum.segment_clear` holds, costed by :func:`path_cost`. Start and
   goal join the lattice nodes within two cells that they see.
2. Refinement of the lattice path (an upper bound of the optimum): shortcuts wherever a straight
   segment is clear and cheaper, then rounds of vertex relaxation (each vertex moved along eight
   directions with a shrinking step while the cost of its two edges falls and they stay clear)
   and subdivision (midpoints added, so the path can bend where the current turns).

Without a current f = 1 and the result is the shortest path; ``tests/test_flow_optimum.py``
checks it against :func:`hil.optimum.shortest_path` (exact) on the repository's maps.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numba
import numpy as np
import numpy.typing as npt
from scipy.sparse import csr_matrix
from scipy.sparse.csgraph import dijkstra

from hil.optimum import segment_clear

if TYPE_CHECKING:
    # A current in the map frame, vectorised: (x east, y north) m -> (v_east, v_north) m/s.
    from hil.plots import MapField as MapCurrent

PIECE = 0.25          # m, integration step of the cost
ZERO_CURRENT = 1e-9   # m/s
STENCIL = np.array([(1, 0), (1, 1), (0, 1), (-1, 1), (-1, 0), (-1, -1), (0, -1), (1, -1),
                    (2, 1), (1, 2), (-1, 2), (-2, 1), (-2, -1), (-1, -2), (1, -2), (2, -1)], dtype=np.int64)


@dataclass(frozen=True)
class FlowField:
    """A current sampled on a regular grid: ``vx[row, col]``, ``vy`` (m/s, map frame) at
    x = col * spacing, y = row * spacing; zero arrays of shape (1, 1) for no current."""

    vx: np.ndarray
    vy: np.ndarray
    spacing: float

    @classmethod
    def sample(cls, current: MapCurrent | None, width: float, height: float, spacing: float = 0.5) -> FlowField:
        """Sample ``current(x, y) -> (vx, vy)`` (vectorised, map frame) over the map; None = still water."""
        if current is None:
            return cls(np.zeros((1, 1)), np.zeros((1, 1)), spacing)
        xs = np.arange(int(math.ceil(width / spacing)) + 1) * spacing
        ys = np.arange(int(math.ceil(height / spacing)) + 1) * spacing
        X, Y = np.meshgrid(xs, ys)
        vx, vy = current(X, Y)
        return cls(np.ascontiguousarray(np.broadcast_to(vx, X.shape), dtype=np.float64),
                   np.ascontiguousarray(np.broadcast_to(vy, X.shape), dtype=np.float64), float(spacing))


@numba.njit(cache=True)
def _flow(vx: np.ndarray, vy: np.ndarray, h: float, x: float, y: float) -> tuple[float, float]:
    rows, cols = vx.shape
    gx = min(max(x / h, 0.0), cols - 1.0)
    gy = min(max(y / h, 0.0), rows - 1.0)
    c0 = min(int(gx), max(cols - 2, 0))
    r0 = min(int(gy), max(rows - 2, 0))
    c1 = min(c0 + 1, cols - 1)
    r1 = min(r0 + 1, rows - 1)
    fx = gx - c0
    fy = gy - r0
    a = (vx[r0, c0] * (1 - fx) * (1 - fy) + vx[r0, c1] * fx * (1 - fy)
         + vx[r1, c0] * (1 - fx) * fy + vx[r1, c1] * fx * fy)
    b = (vy[r0, c0] * (1 - fx) * (1 - fy) + vy[r0, c1] * fx * (1 - fy)
         + vy[r1, c0] * (1 - fx) * fy + vy[r1, c1] * fx * fy)
    return a, b


@numba.njit(cache=True)
def _seg_cost(vx: np.ndarray, vy: np.ndarray, h: float, d_alpha: float, gamma: float, x0: float, y0: float,
              x1: float, y1: float) -> float:
    dx = x1 - x0
    dy = y1 - y0
    length = math.sqrt(dx * dx + dy * dy)
    if length == 0.0:
        return 0.0
    ux = dx / length
    uy = dy / length
    n = max(1, int(math.ceil(length / PIECE)))
    total = 0.0
    for i in range(n):
        t = (i + 0.5) / n
        a, b = _flow(vx, vy, h, x0 + t * dx, y0 + t * dy)
        v = math.sqrt(a * a + b * b)
        f = 1.0
        if v >= ZERO_CURRENT:
            c = min(1.0, max(-1.0, (a * ux + b * uy) / v))
            s = math.sqrt(max(0.0, 1.0 - c * c))  # sin alpha_y, alpha_y in [0, pi]
            f = min(1.0, d_alpha / (1.0 + math.exp(c - gamma * s)))
        total += f
    return total * length / n


@numba.njit(cache=True)
def _lattice_edges(occ: np.ndarray, res: float, vx: np.ndarray, vy: np.ndarray, h: float, d_alpha: float,
                   gamma: float, stencil: np.ndarray, node_of: np.ndarray
                   ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    rows, cols = occ.shape
    src = []
    dst = []
    w = []
    for r in range(rows):
        for c in range(cols):
            i = node_of[r, c]
            if i < 0:
                continue
            x0 = (c + 0.5) * res
            y0 = (r + 0.5) * res
            for k in range(stencil.shape[0]):
                c2 = c + stencil[k, 0]
                r2 = r + stencil[k, 1]
                if r2 < 0 or c2 < 0 or r2 >= rows or c2 >= cols or node_of[r2, c2] < 0:
                    continue
                x1 = (c2 + 0.5) * res
                y1 = (r2 + 0.5) * res
                if segment_clear(occ, res, x0, y0, x1, y1):
                    src.append(i)
                    dst.append(node_of[r2, c2])
                    w.append(_seg_cost(vx, vy, h, d_alpha, gamma, x0, y0, x1, y1))
    return np.array(src, dtype=np.int64), np.array(dst, dtype=np.int64), np.array(w, dtype=np.float64)


@numba.njit(cache=True)
def _path_cost(vx: np.ndarray, vy: np.ndarray, h: float, d_alpha: float, gamma: float, path: np.ndarray) -> float:
    total = 0.0
    for k in range(path.shape[0] - 1):
        total += _seg_cost(vx, vy, h, d_alpha, gamma, path[k, 0], path[k, 1], path[k + 1, 0], path[k + 1, 1])
    return total


@numba.njit(cache=True)
def _relax(occ: np.ndarray, res: float, vx: np.ndarray, vy: np.ndarray, h: float, d_alpha: float, gamma: float,
           path: np.ndarray, step0: float, rounds: int) -> np.ndarray:
    """Move each inner vertex along 8 directions while the cost of its two edges falls and both stay
    clear; the step halves when no move helps, down to step0 / 2^rounds."""
    n = path.shape[0]
    for v in range(1, n - 1):
        step = step0
        for _ in range(rounds):
            improved = True
            while improved:
                improved = False
                ax = path[v - 1, 0]
                ay = path[v - 1, 1]
                bx = path[v + 1, 0]
                by = path[v + 1, 1]
                x = path[v, 0]
                y = path[v, 1]
                best = _seg_cost(vx, vy, h, d_alpha, gamma, ax, ay, x, y) + _seg_cost(vx, vy, h, d_alpha, gamma,
                                                                                      x, y, bx, by)
                for k in range(8):
                    t = k * math.pi / 4.0
                    nx = x + step * math.cos(t)
                    ny = y + step * math.sin(t)
                    c = _seg_cost(vx, vy, h, d_alpha, gamma, ax, ay, nx, ny) + _seg_cost(vx, vy, h, d_alpha, gamma,
                                                                                         nx, ny, bx, by)
                    if c < best - 1e-12 and segment_clear(occ, res, ax, ay, nx, ny) \
                            and segment_clear(occ, res, nx, ny, bx, by):
                        best = c
                        path[v, 0] = nx
                        path[v, 1] = ny
                        improved = True
            step *= 0.5
    return path


@dataclass(frozen=True)
class FlowOptimum:
    """The least eq. (12) cost found: ``cost`` (inf when the goal is unreachable), the refined
    ``path`` (N, 2) and the lattice's cost before refinement, both upper bounds of the optimum."""

    cost: float
    path: np.ndarray
    lattice_cost: float


class FlowJudge:
    """Eq. (12) costs and optima on one map and current (parameters D_alpha, gamma_alpha of eq. (12))."""

    def __init__(self, occ: np.ndarray, resolution: float, current: MapCurrent | None = None, d_alpha: float = 1.0,
                 gamma_alpha: float = 0.1, spacing: float = 0.5) -> None:
        self.occ = np.ascontiguousarray(occ, dtype=np.bool_)
        self.res = float(resolution)
        rows, cols = self.occ.shape
        self.flow = FlowField.sample(current, cols * self.res, rows * self.res, spacing)
        self.d_alpha, self.gamma = float(d_alpha), float(gamma_alpha)

    def _args(self) -> tuple[np.ndarray, np.ndarray, float, float, float]:
        return self.flow.vx, self.flow.vy, self.flow.spacing, self.d_alpha, self.gamma

    def path_cost(self, path: npt.ArrayLike) -> float:
        """Eq. (12) integrated along the polyline ``path`` (N, 2), metres."""
        p = np.ascontiguousarray(path, dtype=np.float64)
        return float(_path_cost(*self._args(), p)) if len(p) >= 2 else 0.0

    def clear(self, a: Sequence[float], b: Sequence[float]) -> bool:
        return bool(segment_clear(self.occ, self.res, float(a[0]), float(a[1]), float(b[0]), float(b[1])))

    def optimum(self, start: tuple[float, float], goal: tuple[float, float], rounds: int = 3) -> FlowOptimum:
        occ, res = self.occ, self.res
        rows, cols = occ.shape
        node_of = -np.ones((rows, cols), dtype=np.int64)
        free = np.argwhere(~occ)
        node_of[free[:, 0], free[:, 1]] = np.arange(len(free))
        n = len(free)
        src, dst, w = _lattice_edges(occ, res, *self._args(), STENCIL, node_of)
        pts = np.column_stack([(free[:, 1] + 0.5) * res, (free[:, 0] + 0.5) * res])
        s_id, g_id = n, n + 1
        pts = np.vstack([pts, [start, goal]])
        extra_s, extra_d, extra_w = [], [], []
        for end, ident, outgoing in ((start, s_id, True), (goal, g_id, False)):
            c0, r0 = int(end[0] / res), int(end[1] / res)
            for r in range(max(r0 - 2, 0), min(r0 + 3, rows)):
                for c in range(max(c0 - 2, 0), min(c0 + 3, cols)):
                    j = node_of[r, c]
                    if j < 0 or not self.clear(end, pts[j]):
                        continue
                    a, b = (end, pts[j]) if outgoing else (pts[j], end)
                    extra_s.append(ident if outgoing else j)
                    extra_d.append(j if outgoing else ident)
                    extra_w.append(max(self.path_cost(np.array([a, b])), 1e-12))
        if self.clear(start, goal):
            extra_s.append(s_id)
            extra_d.append(g_id)
            extra_w.append(max(self.path_cost(np.array([start, goal])), 1e-12))
        src = np.concatenate([src, extra_s]).astype(np.int64)
        dst = np.concatenate([dst, extra_d]).astype(np.int64)
        w = np.maximum(np.concatenate([w, extra_w]), 1e-12)  # scipy drops explicit zeros
        graph = csr_matrix((w, (src, dst)), shape=(n + 2, n + 2))
        dist, pred = dijkstra(graph, directed=True, indices=s_id, return_predecessors=True)
        if not np.isfinite(dist[g_id]):
            return FlowOptimum(math.inf, np.zeros((0, 2)), math.inf)
        order = [g_id]
        while order[-1] != s_id:
            order.append(int(pred[order[-1]]))
        path = pts[order[::-1]].copy()
        lattice = self.path_cost(path)
        path = self._shortcut(path)
        for _ in range(rounds):
            path = _relax(occ, res, *self._args(), np.ascontiguousarray(path), res, 6)
            path = self._shortcut(path)
            mids = 0.5 * (path[:-1] + path[1:])
            dense = np.empty((2 * len(path) - 1, 2))
            dense[0::2] = path
            dense[1::2] = mids
            path = _relax(occ, res, *self._args(), dense, 0.5 * res, 6)
        path = self._shortcut(path)
        return FlowOptimum(self.path_cost(path), path, lattice)

    def _shortcut(self, path: np.ndarray) -> np.ndarray:
        """Greedy: from each kept vertex, the farthest later vertex reached by a clear straight
        segment that costs no more than the path between them."""
        out = [path[0]]
        i = 0
        seg = np.array([self.path_cost(path[k:k + 2]) for k in range(len(path) - 1)])
        cum = np.concatenate([[0.0], np.cumsum(seg)])
        while i < len(path) - 1:
            j = len(path) - 1
            while j > i + 1:
                if self.clear(path[i], path[j]) and \
                        self.path_cost(np.array([path[i], path[j]])) <= cum[j] - cum[i] + 1e-12:
                    break
                j -= 1
            out.append(path[j])
            i = j
        return np.array(out)
