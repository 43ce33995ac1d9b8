"""The global route of a fixed scenario, planned apart from loading it.

Loading a scenario (:mod:`hil.scenario`) reads and checks files and positions only. The route
through its waypoints is planned here, on the chart inflated by the planner's safety radius
(``planner.global_route``), the first time something needs the reference path: the vessel
computer's world, the run's judge, `hil geo`, the campaigns. A waypoint that is off the chart,
inside an obstacle or its margin, or not reachable by water is a one-line ConfigError naming it.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from hil.errors import ConfigError


@dataclass(frozen=True)
class RouteRequest:
    """What a global route is planned from.

    ``occ``: the chart, bool [rows, cols], True = obstacle (map frame); ``resolution``: m per cell;
    ``waypoints``: (K, 2) m, map frame, start first and goal last; ``safety_radius``: m of inflation;
    ``spacing``: the largest gap between the route's points, m; ``source`` and ``names``: the file and
    the waypoints' names in error messages."""

    occ: np.ndarray
    resolution: float
    waypoints: np.ndarray
    safety_radius: float
    spacing: float
    source: str
    names: tuple[str, ...]


def route_waypoints(start: tuple[float, float], goal: tuple[float, float],
                    given: tuple[tuple[float, float], ...] | np.ndarray) -> np.ndarray:
    """start, the given waypoints (their first/last dropped where they repeat start/goal), goal."""
    pts = [(float(p[0]), float(p[1])) for p in given]
    if pts and math.dist(pts[0], start) < 1e-9:
        pts = pts[1:]
    if pts and math.dist(pts[-1], goal) < 1e-9:
        pts = pts[:-1]
    return np.array([(float(start[0]), float(start[1])), *pts, (float(goal[0]), float(goal[1]))], dtype=float)


def plan_route(req: RouteRequest) -> np.ndarray:
    """The global reference path (M, 2) through ``req.waypoints``, m, map frame; ConfigError naming
    the waypoint that is off the chart, in an obstacle or unreachable."""
    from planner.global_route import plan_chart_route
    from planner.gridmap import OccupancyGrid

    route = plan_chart_route(OccupancyGrid(req.occ, req.resolution), req.waypoints, req.safety_radius, req.spacing)
    if not route.ok:
        i = route.failed_index or 0
        margin = f" (safety radius {req.safety_radius:g} m)" if route.status.value == "in_obstacle" else ""
        raise ConfigError(f"{req.source}: {req.names[i]}: {route.reason}{margin}")
    return np.asarray(route.path, dtype=float)
