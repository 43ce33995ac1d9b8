"""planner.global_route on maps it never saw: random discs, a bug trap, a maze; failure statuses."""

from __future__ import annotations

import math

import numpy as np
import pytest

from planner.global_route import RouteStatus, densify, plan_chart_route, plan_route
from planner.gridmap import OccupancyGrid

RES = 0.5


def _grid(width: float, height: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    rows, cols = int(height / RES), int(width / RES)
    y, x = (np.mgrid[0:rows, 0:cols] + 0.5) * RES
    return np.zeros((rows, cols), dtype=bool), x, y


def random_discs(seed: int) -> OccupancyGrid:
    rng = np.random.default_rng(seed)
    occ, x, y = _grid(120.0, 90.0)
    for _ in range(25):
        cx, cy, r = rng.uniform(15, 105), rng.uniform(10, 80), rng.uniform(2, 8)
        occ |= (x - cx) ** 2 + (y - cy) ** 2 <= r * r
    occ &= (x - 5) ** 2 + (y - 45) ** 2 > 16     # start and goal areas open
    occ &= (x - 115) ** 2 + (y - 45) ** 2 > 16
    return OccupancyGrid(occ, RES)


def bug_trap() -> OccupancyGrid:
    """A U open to the east, the start inside it, the goal west of it."""
    occ, x, y = _grid(80.0, 60.0)
    occ |= (abs(x - 30) < 1) & (abs(y - 30) < 15)            # back wall
    occ |= (abs(y - 15) < 1) & (x > 30) & (x < 55)           # lower arm
    occ |= (abs(y - 45) < 1) & (x > 30) & (x < 55)           # upper arm
    return OccupancyGrid(occ, RES)


def maze() -> OccupancyGrid:
    """Walls alternating gaps at the top and the bottom: the route must snake."""
    occ, x, y = _grid(100.0, 50.0)
    for k, wx in enumerate((20, 40, 60, 80)):
        gap_low = k % 2 == 0
        occ |= (abs(x - wx) < 1) & ((y > 10) if gap_low else (y < 40))
    return OccupancyGrid(occ, RES)


def _cell(grid, p):
    return grid.cell_of(float(p[0]), float(p[1]))


def assert_free(grid: OccupancyGrid, path: np.ndarray) -> None:
    """Every segment free by the planner's exact traversal, except a piece inside one free cell
    (a waypoint to its cell's centre), which is free by definition."""
    for a, b in zip(path[:-1], path[1:], strict=True):
        if _cell(grid, a) == _cell(grid, b):
            assert grid.is_free(*a)
            continue
        assert grid.segment_free(*a, *b), (a, b)


def astar8_length(grid: OccupancyGrid, a, b) -> float:
    """Length (m) of the shortest 8-connected path between the cells of a and b (no corner cutting)."""
    import heapq

    occ = grid.occ
    rows, cols = occ.shape
    s, g = _cell(grid, a), _cell(grid, b)
    dist = {s: 0.0}
    heap = [(0.0, s)]
    while heap:
        d, (r, c) = heapq.heappop(heap)
        if (r, c) == g:
            return d * grid.resolution
        if d > dist[(r, c)]:
            continue
        for dr in (-1, 0, 1):
            for dc in (-1, 0, 1):
                nr, nc = r + dr, c + dc
                if (dr, dc) == (0, 0) or not (0 <= nr < rows and 0 <= nc < cols) or occ[nr, nc]:
                    continue
                if dr and dc and (occ[r, nc] or occ[nr, c]):
                    continue
                nd = d + math.hypot(dr, dc)
                if nd < dist.get((nr, nc), math.inf):
                    dist[(nr, nc)] = nd
                    heapq.heappush(heap, (nd, (nr, nc)))
    return math.inf


@pytest.mark.parametrize("seed", [3, 11, 29])
def test_random_discs_route_is_free_and_shorter_than_8_connected_astar(seed):
    grid = random_discs(seed).inflate(2.0)
    a, b = (5.0, 45.0), (115.0, 45.0)
    route = plan_route(grid, [a, b])
    assert route.ok, route.reason
    assert np.allclose(route.path[0], a) and np.allclose(route.path[-1], b)
    assert_free(grid, route.path)
    assert route.length < astar8_length(grid, a, b) - 1e-6
    assert np.max(np.hypot(*np.diff(route.path, axis=0).T)) <= 10.0 + 1e-9


def test_bug_trap_escapes_the_u_and_keeps_free_legs_straight():
    grid = bug_trap().inflate(2.0)
    start, goal = (42.0, 30.0), (10.0, 30.0)
    route = plan_route(grid, [start, goal, (10.0, 55.0)], spacing=5.0)
    assert route.ok, route.reason
    assert_free(grid, route.path)
    first, second = route.legs
    assert not first.straight and first.vertices[:, 0].max() > 55.0   # out through the open side
    assert second.straight and len(second.vertices) == 2
    assert route.length < astar8_length(grid, start, goal) + 25.0 + 1e-6
    assert first.length < astar8_length(grid, start, goal)
    assert np.max(np.hypot(*np.diff(route.path, axis=0).T)) <= 5.0 + 1e-9


def test_maze_route_snakes_through_every_gap():
    grid = maze().inflate(1.5)
    a, b = (5.0, 25.0), (95.0, 25.0)
    route = plan_route(grid, [a, b])
    assert route.ok
    assert_free(grid, route.path)
    assert route.length < astar8_length(grid, a, b)
    for k, wx in enumerate((20, 40, 60, 80)):       # each wall is passed through its gap
        i = int(np.searchsorted(route.path[:, 0], wx))
        y = np.interp(wx, route.path[i - 1:i + 1, 0], route.path[i - 1:i + 1, 1])
        assert (y < 10.0) if k % 2 == 0 else (y > 40.0), (wx, y)


def test_preferred_margin_is_used_where_there_is_room():
    chart = random_discs(3)
    wide = plan_chart_route(chart, [(5.0, 45.0), (115.0, 45.0)], 2.0)
    assert wide.ok
    clear = chart.clearance()
    rows, cols = (np.asarray([chart.cell_of(*p) for p in wide.path]).T)
    assert clear[rows, cols].min() >= 2.0


def test_failures_name_the_waypoint_and_the_reason():
    grid = bug_trap().inflate(2.0)
    r = plan_route(grid, [(42.0, 30.0), (30.0, 30.0)])
    assert r.status is RouteStatus.IN_OBSTACLE and r.failed_index == 1 and len(r.path) == 0
    r = plan_route(grid, [(42.0, 30.0), (10.0, 30.0), (90.0, 30.0)])
    assert r.status is RouteStatus.OFF_MAP and r.failed_index == 2
    r = plan_route(grid, [(42.0, 30.0), (math.nan, 3.0)])
    assert r.status is RouteStatus.OFF_MAP and r.failed_index == 1
    occ = bug_trap().occ.copy()
    occ[:, 130:134] = True                            # a wall across the whole chart at x = 65-67 m
    walled = OccupancyGrid(occ, RES).inflate(2.0)
    r = plan_route(walled, [(42.0, 30.0), (10.0, 30.0), (75.0, 30.0)])
    assert r.status is RouteStatus.UNREACHABLE and r.failed_index == 2 and "reached" in r.reason


def test_start_inside_the_margin_leaves_by_the_nearest_free_cell():
    grid = bug_trap().inflate(2.0)
    start = (32.5, 30.0)                               # 1.5 m from the back wall
    assert not grid.is_free(*start)
    r = plan_route(grid, [start, (42.0, 30.0)])
    assert r.ok and np.allclose(r.path[0], start)
    assert_free(grid, r.path[1:])
    assert plan_route(grid, [start, (42.0, 30.0)], start_may_be_blocked=False).status is RouteStatus.IN_OBSTACLE


def test_densify_keeps_vertices_and_bounds_gaps():
    v = np.array([[0.0, 0.0], [25.0, 0.0], [25.0, 3.0]])
    d = densify(v, 10.0)
    assert all(any(np.allclose(p, q) for q in d) for p in v)
    assert np.max(np.hypot(*np.diff(d, axis=0).T)) <= 10.0
