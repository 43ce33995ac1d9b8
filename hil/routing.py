"""The global route of a fixed scenario, planned apart from loading it.

Loading a scenario (:mod:`hil.scenario`) reads and checks files and positions only. The route
through its waypoints is planned here, on the chart inflated by the planner's safety radius
(``planner.global_route``), the first time something needs the reference path: the vessel
computer's world, the run's judge, `hil geo`, the campaigns. A waypoint that is off the chart,
inside an obstacle or its margin, or not reachable by water is a one-line ConfigError naming it.

A run plans the route once: `hil run` plans it before starting any process and hands it to its
vessel computer as a :class:`PlannedRoute` (``route.json`` in the run folder, `hil autopilot
--route FILE`), which :func:`take_route` accepts only for the route request it was planned from.
"""

from __future__ import annotations

import hashlib
import json
import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from hil.errors import ConfigError, UsageError


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


@dataclass(frozen=True)
class PlannedRoute:
    """A global route as `hil run` planned it, for its vessel computer: what it was planned from (the
    waypoints, m, map frame; the safety radius and the largest gap between points, m; the chart as a
    digest of its cells and its resolution, m per cell) and the route, (M, 2) m, map frame."""

    waypoints: tuple[tuple[float, float], ...]
    safety_radius: float
    spacing: float
    resolution: float
    chart_sha256: str
    path: tuple[tuple[float, float], ...]


def _chart_digest(occ: np.ndarray) -> str:
    cells = np.ascontiguousarray(occ, dtype=bool)
    return hashlib.sha256(repr(cells.shape).encode() + cells.tobytes()).hexdigest()


def planned_route(req: RouteRequest, path: np.ndarray) -> PlannedRoute:
    """``path``, planned from ``req``, with what it was planned from."""
    return PlannedRoute(waypoints=tuple((float(x), float(y)) for x, y in req.waypoints),
                        safety_radius=float(req.safety_radius), spacing=float(req.spacing),
                        resolution=float(req.resolution), chart_sha256=_chart_digest(req.occ),
                        path=tuple((float(x), float(y)) for x, y in path))


def write_route(file: Path, route: PlannedRoute) -> None:
    from hil.config import to_table
    from hil.files import write_json_atomic

    write_json_atomic(file, to_table(route))


def read_route(file: str | Path) -> PlannedRoute:
    """A :class:`PlannedRoute` from ``file`` (JSON), read strictly; UsageError in one line otherwise."""
    from hil.config import from_table

    where = f"--route {file}"
    try:
        table = json.loads(Path(file).read_text())
    except OSError as exc:
        raise UsageError(f"{where}: {exc.strerror or exc}") from None
    except (UnicodeDecodeError, ValueError) as exc:
        raise UsageError(f"{where}: not JSON ({exc})") from None
    if not isinstance(table, dict):
        raise UsageError(f"{where}: expected a JSON object, got {type(table).__name__}")
    try:
        return from_table(PlannedRoute, table, where)
    except ConfigError as exc:
        raise UsageError(str(exc)) from None


def take_route(req: RouteRequest, route: PlannedRoute, source: str) -> np.ndarray:
    """The route (M, 2) of ``route`` when it was planned from ``req`` (same waypoints, safety radius,
    spacing and chart), so that nothing plans it again; UsageError naming what differs otherwise."""
    def differs(what: str) -> UsageError:
        return UsageError(f"{source}: planned for another {what} than this scenario's (plan it again: leave "
                          f"--route out)")

    wps = np.asarray(route.waypoints, dtype=float).reshape(-1, 2)
    if wps.shape != req.waypoints.shape or not np.allclose(wps, req.waypoints, rtol=0.0, atol=1e-9):
        raise differs("route's waypoints")
    if (route.safety_radius, route.spacing) != (float(req.safety_radius), float(req.spacing)):
        raise differs("safety radius or spacing")
    if route.resolution != float(req.resolution) or route.chart_sha256 != _chart_digest(req.occ):
        raise differs("chart")
    path = np.asarray(route.path, dtype=float).reshape(-1, 2)
    rows, cols = req.occ.shape
    inside = (path[:, 0] >= 0) & (path[:, 0] <= cols * req.resolution) & (path[:, 1] >= 0) & \
        (path[:, 1] <= rows * req.resolution)
    if len(path) < 2 or not np.all(np.isfinite(path)) or not inside.all():
        raise UsageError(f"{source}: path: needs two or more finite points on the chart")
    if math.dist(path[0], wps[0]) > 1e-6 or math.dist(path[-1], wps[-1]) > 1e-6:
        raise UsageError(f"{source}: path: must run from the first waypoint to the last")
    return path
