"""The global route: ordered waypoints to a collision-free reference path on the inflated chart.

The paper (section 2.2) takes a global reference path as given and plans locally along it; users
give waypoints, as a ground station writes them, with legs of any length that may cross the
chart's obstacles. :func:`plan_route` turns them into the reference path the online planner
takes its subgoals from (section 3.1):

* every leg whose straight line is free on the grid stays straight;
* every other leg is routed by **Lazy Theta*** (Nash, Koenig and Tovey 2010) on the grid's cells:
  A* over the 8-connected cell graph whose nodes may take any earlier-expanded node in line of
  sight as parent, so the path's vertices are obstacle corners and its segments run at any angle
  (no 45-degree zig-zags). The line-of-sight test is the planner's exact cell traversal
  (:func:`planner._kernels.segment_free`), the one every local path is checked with;
* the vertices are densified to points at most ``spacing`` metres apart (existing vertices kept),
  so that the subgoal rules of section 3.1 always find a waypoint inside the perceptual domain.

Reachability is decided first on the 4-connected components of the free cells (the traversal
never slips between two cells that share only a corner, so 4-connectivity is the right notion):
an unreachable waypoint fails without any search. A waypoint off the grid or on an occupied cell
fails as well; the result then names the first failing waypoint and why, and carries no path.

Pure: numpy, scipy and numba only. Map frame: x east, y north (metres); the grid is the chart
inflated by the safety radius (obstacles and the map edge).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from enum import Enum

import numpy as np
import numpy.typing as npt
from numba import njit
from scipy import ndimage

from planner._kernels import segment_free
from planner.gridmap import OccupancyGrid

DEFAULT_SPACING = 10.0  # m: a third of the paper's 33 m perceptual radius (the hand-drawn routes' spacing)


class RouteStatus(str, Enum):  # noqa: UP042  (StrEnum would change str() of the members, which reports print)
    """Outcome of :func:`plan_route` (the string is what reports print)."""

    OK = "ok"
    IN_OBSTACLE = "in_obstacle"      # a waypoint lies on an occupied cell of the (inflated) grid
    OFF_MAP = "off_map"              # a waypoint lies outside the grid
    UNREACHABLE = "unreachable"      # no free path from the previous waypoint


@dataclass(frozen=True)
class RouteLeg:
    """One leg, waypoint ``index - 1`` to waypoint ``index``.

    ``first``/``last`` index the route's dense ``path`` (inclusive), ``vertices`` are the leg's
    polyline corners (m), ``length`` its length (m); ``straight`` when the leg's straight line
    was free and kept."""

    index: int
    first: int
    last: int
    vertices: np.ndarray
    length: float
    straight: bool


@dataclass(frozen=True)
class GlobalRoute:
    """A planned route: ``path`` (N, 2) densified polyline from the first waypoint to the last
    (map frame, m); ``legs`` one per consecutive waypoint pair. On failure ``path`` is empty,
    ``failed_index`` is the index of the offending waypoint in the input and ``reason`` says why."""

    status: RouteStatus
    path: np.ndarray
    legs: tuple[RouteLeg, ...]
    failed_index: int | None = None
    reason: str = ""

    @property
    def ok(self) -> bool:
        return self.status is RouteStatus.OK

    @property
    def length(self) -> float:
        return float(sum(leg.length for leg in self.legs))

    def leg_at(self, path_index: int) -> int:
        """The index (in the input waypoints) of the waypoint the dense point ``path_index`` leads to."""
        for leg in self.legs:
            if path_index < leg.last:
                return leg.index
        return self.legs[-1].index if self.legs else 0


def _fail(status: RouteStatus, index: int, reason: str) -> GlobalRoute:
    return GlobalRoute(status, np.zeros((0, 2)), (), index, reason)


def plan_chart_route(chart: OccupancyGrid, waypoints: npt.ArrayLike, safety_radius: float,
                     spacing: float = DEFAULT_SPACING, margin_factor: float = 2.0) -> GlobalRoute:
    """:func:`plan_route` on ``chart`` (raw obstacles) inflated by ``safety_radius`` (m), routing the
    legs that need it with ``margin_factor`` times that clearance where the wider margin leaves a
    way (see ``preferred``)."""
    grid = chart.inflate(safety_radius) if safety_radius > 0 else chart
    preferred = chart.inflate(margin_factor * safety_radius) if margin_factor > 1 and safety_radius > 0 else None
    return plan_route(grid, waypoints, spacing, preferred=preferred)


def plan_route(grid: OccupancyGrid, waypoints: npt.ArrayLike, spacing: float = DEFAULT_SPACING,
               start_may_be_blocked: bool = True, preferred: OccupancyGrid | None = None) -> GlobalRoute:
    """The global route through ``waypoints`` ((M, 2), start first, metres) on ``grid``.

    ``start_may_be_blocked``: the vessel may begin inside the inflation (moored at a quay, pushed
    there by the current); the route then leaves it by the straight line to the nearest free
    cell (the local planner's recovery map does the same). Later waypoints must be free.
    ``spacing`` (m, > 0): the dense path's largest gap between points. ``preferred``: a more
    inflated copy of ``grid`` (same shape); a leg that must be routed is routed on it when both
    its ends are free there and connected, so that the route keeps a wider berth than the
    safety radius where there is room (a route along the inflation's very edge leaves the
    local planner's subgoals on it). Waypoints are judged on ``grid`` alone."""
    wps = np.asarray(waypoints, dtype=float).reshape(-1, 2)
    if len(wps) < 2:
        raise ValueError("plan_route needs at least two waypoints (start and goal)")
    if not spacing > 0:
        raise ValueError("spacing must be > 0")
    occ = np.ascontiguousarray(grid.occ.astype(np.uint8))
    res = float(grid.resolution)
    for i, (x, y) in enumerate(wps):
        if not (math.isfinite(x) and math.isfinite(y)) or not grid.contains(x, y):
            return _fail(RouteStatus.OFF_MAP, i, f"({x:.1f}, {y:.1f}) m is off the {grid.width:g} m x "
                                                 f"{grid.height:g} m chart")
        if i > 0 and not grid.is_free(x, y):
            return _fail(RouteStatus.IN_OBSTACLE, i, f"({x:.1f}, {y:.1f}) m is inside an obstacle or its "
                                                     "safety margin")
    if grid.occ.all():
        return _fail(RouteStatus.UNREACHABLE, 1, "the chart has no free water")
    escape = None
    if not grid.is_free(*wps[0]):
        if not start_may_be_blocked:
            return _fail(RouteStatus.IN_OBSTACLE, 0, f"({wps[0][0]:.1f}, {wps[0][1]:.1f}) m is inside an obstacle "
                                                     "or its safety margin")
        escape = _nearest_free(grid, wps[0])
    labels, _ = ndimage.label(~grid.occ)
    start_cell = _cell(grid, escape if escape is not None else wps[0])
    component = labels[start_cell]
    for i in range(1, len(wps)):
        if labels[_cell(grid, wps[i])] != component:
            return _fail(RouteStatus.UNREACHABLE, i, f"({wps[i][0]:.1f}, {wps[i][1]:.1f}) m cannot be reached by "
                                                     "water from the previous waypoint")
    wide = wide_labels = None
    if preferred is not None:
        if preferred.occ.shape != grid.occ.shape:
            raise ValueError("preferred must have the grid's shape")
        wide = np.ascontiguousarray(preferred.occ.astype(np.uint8))
        wide_labels, _ = ndimage.label(~preferred.occ)
    legs_vertices: list[tuple[np.ndarray, bool]] = []
    verts: np.ndarray | None
    for i in range(1, len(wps)):
        a = escape if (i == 1 and escape is not None) else wps[i - 1]
        b = wps[i]
        if segment_free(occ, res, a[0], a[1], b[0], b[1]):
            verts, straight = np.array([a, b]), True
        else:
            on = occ
            if wide is not None and wide_labels is not None and preferred is not None:
                la, lb = wide_labels[_cell(grid, a)], wide_labels[_cell(grid, b)]
                if la != 0 and la == lb and preferred.is_free(*a) and preferred.is_free(*b):
                    on = wide
            verts, straight = _theta_star(grid, on, a, b), False
            if verts is None:   # cannot happen after the component test; kept as a guard
                return _fail(RouteStatus.UNREACHABLE, i, f"({b[0]:.1f}, {b[1]:.1f}) m: no path found")
        if i == 1 and escape is not None:
            verts = np.vstack([wps[0], verts])
            straight = False
        legs_vertices.append((verts, straight))
    return _assemble(legs_vertices, spacing)


def _cell(grid: OccupancyGrid, p: np.ndarray) -> tuple[int, int]:
    r, c = grid.cell_of(float(p[0]), float(p[1]))
    return min(max(r, 0), grid.rows - 1), min(max(c, 0), grid.cols - 1)


def _nearest_free(grid: OccupancyGrid, p: np.ndarray) -> np.ndarray:
    _, idx = ndimage.distance_transform_edt(grid.occ, return_indices=True)
    r, c = _cell(grid, p)
    rr, cc = idx[0][r, c], idx[1][r, c]
    return np.array([(cc + 0.5) * grid.resolution, (rr + 0.5) * grid.resolution])


def _assemble(legs_vertices: list[tuple[np.ndarray, bool]], spacing: float) -> GlobalRoute:
    out: list[np.ndarray] = []
    legs: list[RouteLeg] = []
    for k, (verts, straight) in enumerate(legs_vertices):
        dense = densify(verts, spacing)
        first = 0 if not out else sum(len(o) for o in out) - 1
        out.append(dense if not out else dense[1:])
        last = first + len(dense) - 1
        seg = np.hypot(*np.diff(verts, axis=0).T)
        legs.append(RouteLeg(k + 1, first, last, verts, float(seg.sum()), straight))
    return GlobalRoute(RouteStatus.OK, np.concatenate(out), tuple(legs))


def densify(vertices: npt.ArrayLike, spacing: float) -> np.ndarray:
    """The polyline with points inserted so that consecutive points are at most ``spacing`` m
    apart; every vertex is kept (evenly spaced inside each segment)."""
    v = np.asarray(vertices, dtype=float).reshape(-1, 2)
    if len(v) < 2:
        return v.copy()
    out = [v[:1]]
    for a, b in zip(v[:-1], v[1:], strict=True):
        n = max(int(math.ceil(math.hypot(*(b - a)) / spacing - 1e-9)), 1)
        out.append(a + (b - a) * (np.arange(1, n + 1) / n)[:, None])
    return np.concatenate(out)


def _theta_star(grid: OccupancyGrid, occ: np.ndarray, a: np.ndarray, b: np.ndarray) -> np.ndarray | None:
    """Lazy Theta* from point ``a`` to point ``b`` (both on free cells): the polyline's vertices,
    the exact points at both ends, or None."""
    res = grid.resolution
    sr, sc = _cell(grid, a)
    gr, gc = _cell(grid, b)
    cells = _lazy_theta_star(occ, sr, sc, gr, gc)
    if cells.shape[0] == 0:
        return None
    verts = (cells[:, ::-1].astype(float) + 0.5) * res          # (row, col) -> (x, y) cell centres
    verts[0], verts[-1] = a, b
    # The exact end points lie in the end cells, not necessarily at their centres: keep the
    # centre as an extra vertex where the exact point does not see the next vertex.
    out = [np.asarray(a, dtype=float)]
    if len(verts) > 2 and not segment_free(occ, res, a[0], a[1], verts[1][0], verts[1][1]):
        out.append((np.array([sc, sr], dtype=float) + 0.5) * res)
    out.extend(verts[1:-1])
    if len(verts) > 2 and not segment_free(occ, res, verts[-2][0], verts[-2][1], b[0], b[1]):
        out.append((np.array([gc, gr], dtype=float) + 0.5) * res)
    out.append(np.asarray(b, dtype=float))
    return _shortcut(occ, res, np.array(out))


def _shortcut(occ: np.ndarray, res: float, verts: np.ndarray) -> np.ndarray:
    """Drop vertices the previous kept vertex sees past (removes the extra end-cell centres
    where unnecessary; Theta*'s own vertices are already in mutual line of sight)."""
    keep = [0]
    i = 0
    while i < len(verts) - 1:
        j = len(verts) - 1
        while j > i + 1 and not segment_free(occ, res, verts[i][0], verts[i][1], verts[j][0], verts[j][1]):
            j -= 1
        keep.append(j)
        i = j
    return verts[keep]


@njit(cache=True)
def _heap_push(keys: np.ndarray, items: np.ndarray, size: int, key: float, item: int) -> int:
    i = size
    keys[i] = key
    items[i] = item
    while i > 0:
        p = (i - 1) >> 1
        if keys[p] <= keys[i]:
            break
        keys[p], keys[i] = keys[i], keys[p]
        items[p], items[i] = items[i], items[p]
        i = p
    return size + 1


@njit(cache=True)
def _heap_pop(keys: np.ndarray, items: np.ndarray, size: int) -> tuple[int, int]:
    item = items[0]
    size -= 1
    keys[0] = keys[size]
    items[0] = items[size]
    i = 0
    while True:
        left = 2 * i + 1
        if left >= size:
            break
        m = left
        if left + 1 < size and keys[left + 1] < keys[left]:
            m = left + 1
        if keys[i] <= keys[m]:
            break
        keys[m], keys[i] = keys[i], keys[m]
        items[m], items[i] = items[i], items[m]
        i = m
    return item, size


@njit(cache=True)
def _los(occ: np.ndarray, r0: int, c0: int, r1: int, c1: int) -> bool:
    """Line of sight between two cell centres (exact traversal, in cell units)."""
    return segment_free(occ, 1.0, c0 + 0.5, r0 + 0.5, c1 + 0.5, r1 + 0.5)


@njit(cache=True)
def _lazy_theta_star(occ: np.ndarray, sr: int, sc: int, gr: int, gc: int) -> np.ndarray:
    """Lazy Theta* (Nash, Koenig, Tovey 2010) on the 8-connected cell graph, costs in cell units.
    A diagonal move needs both side cells free (no corner cutting). Returns the (K, 2) [row, col]
    vertices from start to goal, or an empty array."""
    rows, cols = occ.shape
    n = rows * cols
    g = np.full(n, np.inf)
    parent = np.full(n, -1, dtype=np.int64)
    closed = np.zeros(n, dtype=np.bool_)
    cap = 2 * n + 16
    keys = np.empty(cap)
    items = np.empty(cap, dtype=np.int64)
    size = 0
    start = sr * cols + sc
    goal = gr * cols + gc
    g[start] = 0.0
    parent[start] = start
    size = _heap_push(keys, items, np.int64(size), math.hypot(gr - sr, gc - sc), start)
    dr = np.array([-1, -1, -1, 0, 0, 1, 1, 1])
    dc = np.array([-1, 0, 1, -1, 1, -1, 0, 1])
    found = False
    while size > 0:
        s, size = _heap_pop(keys, items, size)
        if closed[s]:
            continue
        r, c = s // cols, s % cols
        p = parent[s]
        pr, pc = p // cols, p % cols
        if p != s and not _los(occ, pr, pc, r, c):
            # Lazy: the assumed parent is not visible; take the best expanded neighbour instead.
            best = np.inf
            bp = -1
            for k in range(8):
                nr, nc = r + dr[k], c + dc[k]
                if nr < 0 or nc < 0 or nr >= rows or nc >= cols:
                    continue
                q = nr * cols + nc
                if not closed[q] or occ[nr, nc]:
                    continue
                if dr[k] != 0 and dc[k] != 0 and (occ[r, nc] or occ[nr, c]):
                    continue
                cost = g[q] + math.hypot(dr[k], dc[k])
                if cost < best:
                    best = cost
                    bp = q
            g[s] = best
            parent[s] = bp
        closed[s] = True
        if s == goal:
            found = True
            break
        par = parent[s]
        ppr, ppc = par // cols, par % cols
        for k in range(8):
            nr, nc = r + dr[k], c + dc[k]
            if nr < 0 or nc < 0 or nr >= rows or nc >= cols or occ[nr, nc]:
                continue
            if dr[k] != 0 and dc[k] != 0 and (occ[r, nc] or occ[nr, c]):
                continue
            q = nr * cols + nc
            if closed[q]:
                continue
            # Path 2 of Theta*: straight from s's parent (line of sight checked lazily on expansion).
            cost = g[par] + math.hypot(nr - ppr, nc - ppc)
            if cost < g[q] - 1e-12:
                g[q] = cost
                parent[q] = par
                if size >= keys.shape[0]:
                    keys2 = np.empty(2 * keys.shape[0])
                    items2 = np.empty(2 * keys.shape[0], dtype=np.int64)
                    for h in range(size):   # a loop, not a slice copy: numba's slice assignment brings
                        keys2[h] = keys[h]      # its shape-mismatch error message, ~2.5 s of cold compile
                        items2[h] = items[h]
                    keys, items = keys2, items2
                size = _heap_push(keys, items, size, cost + math.hypot(gr - nr, gc - nc), q)
    if not found:
        return np.zeros((0, 2), dtype=np.int64)
    count = 1
    s = goal
    while parent[s] != s:
        s = parent[s]
        count += 1
        if count > n:
            return np.zeros((0, 2), dtype=np.int64)
    out = np.empty((count, 2), dtype=np.int64)
    s = goal
    for i in range(count - 1, -1, -1):
        out[i, 0] = s // cols
        out[i, 1] = s % cols
        s = parent[s]
    return out
