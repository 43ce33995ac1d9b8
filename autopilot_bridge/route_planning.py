"""The vessel computer's global route: mission waypoints to the global reference path (NED).

A mission, an RTL or a GUIDED target gives waypoints [position, item, ...] with legs of any
length; :class:`RouteKeeper` turns them into the global reference path that the online planner
takes its subgoals from, with ``planner.global_route`` on the chart plus the obstacles sensed so
far, inflated by the planner's safety radius. When a newly sensed obstacle comes within the
safety radius of the route ahead, the route is planned again from the vessel's position through
the waypoints still ahead (a waypoint now inside a sensed obstacle is dropped, except the last).

:func:`check_mission` is the mission upload's chart test: the first item off the chart, inside an
obstacle or its safety margin, or not reachable by water, with the ``MAV_MISSION_RESULT`` a ground
station shows for it. Off the chart is the item's latitude (``MAV_MISSION_INVALID_PARAM5_X``) or
longitude (``MAV_MISSION_INVALID_PARAM6_Y``); inside an obstacle and unreachable concern the
position as a whole: ``MAV_MISSION_INVALID``.

Frames: NED (north, east) metres here; the planner's map frame is x = east, y = north.
"""

from __future__ import annotations

import logging
import math
from collections.abc import Callable, Sequence
from typing import TYPE_CHECKING

import numpy as np
import numpy.typing as npt
from pymavlink.dialects.v20 import common as M

from autopilot_bridge.obstacle_map import path_blocked

if TYPE_CHECKING:
    from autopilot_bridge.gcs.mission import MissionItem
    from planner.gridmap import OccupancyGrid

_logger = logging.getLogger(__name__)


def _to_map(ned: npt.ArrayLike) -> np.ndarray:
    return np.asarray(ned, dtype=float).reshape(-1, 2)[:, ::-1].copy()


def check_mission(grid: OccupancyGrid, waypoints_ned: npt.ArrayLike, safety_radius: float,
                  position_ned: tuple[float, float] | None = None) -> tuple[int, int, str] | None:
    """The first bad waypoint of a mission as ``(item index, MAV_MISSION_RESULT, reason)``, or None.

    ``grid``: the chart (``planner.gridmap.OccupancyGrid``, raw obstacles, plus what was sensed);
    ``waypoints_ned``: the items' positions (K, 2), m; ``position_ned``: the vessel, if known (the
    first item must be reachable from it)."""
    from planner.global_route import RouteStatus, plan_route

    wps = np.asarray(waypoints_ned, dtype=float).reshape(-1, 2)
    if len(wps) == 0:
        return None
    height, width = grid.height, grid.width
    for i, (n, e) in enumerate(wps):
        if not (math.isfinite(n) and 0.0 <= n < height):
            return i, M.MAV_MISSION_INVALID_PARAM5_X, f"{n:.0f} m north is off the chart (0-{height:.0f} m)"
        if not (math.isfinite(e) and 0.0 <= e < width):
            return i, M.MAV_MISSION_INVALID_PARAM6_Y, f"{e:.0f} m east is off the chart (0-{width:.0f} m)"
    inflated = grid.inflate(safety_radius) if safety_radius > 0 else grid
    offset = 1
    pts = _to_map(wps)
    if position_ned is not None and grid.contains(position_ned[1], position_ned[0]):
        pts = np.vstack([_to_map([position_ned]), pts])
    else:
        # No position: the items must at least reach one another (the first stands in for the start).
        offset = 0
        if not inflated.is_free(*pts[0]):
            return 0, M.MAV_MISSION_INVALID, _in_obstacle(safety_radius)
        if len(pts) == 1:
            return None
    route = plan_route(inflated, pts)
    if route.ok:
        return None
    item = (route.failed_index or 0) - offset
    if route.status is RouteStatus.IN_OBSTACLE:
        return item, M.MAV_MISSION_INVALID, _in_obstacle(safety_radius)
    if route.status is RouteStatus.UNREACHABLE:
        return item, M.MAV_MISSION_INVALID, "unreachable by water"
    return item, M.MAV_MISSION_INVALID_PARAM5_X, "off the chart"


def _in_obstacle(safety_radius: float) -> str:
    return f"in obstacle or {safety_radius:g} m margin"


class RouteKeeper:
    """The active global route (NED) and its waypoints; plans it and re-plans it round sensed obstacles.

    ``grid`` is the autopilot's chart-plus-sensed map (marked in place as obstacles are sensed)."""

    def __init__(self, grid: OccupancyGrid, safety_radius: float, spacing: float = 10.0,
                 log: Callable[[str], None] | None = None) -> None:
        self.grid, self.safety_radius, self.spacing = grid, float(safety_radius), float(spacing)
        self.log = log or _logger.info
        self.waypoints: np.ndarray = np.zeros((0, 2))     # NED, the route as given (first: where it began)
        self.path: np.ndarray = np.zeros((0, 2))          # NED, dense global route
        self.progress = 0                                  # index into path of the vessel's nearest point
        self.replans = 0

    def set_route(self, waypoints_ned: npt.ArrayLike) -> np.ndarray:
        """Plan the route through ``waypoints_ned`` (position first); returns the dense NED path.
        A route the chart does not allow (GUIDED or RTL into an obstacle, an unreachable point)
        is kept as given: the local planner and the reactive behaviour do what they can."""
        self.waypoints = np.asarray(waypoints_ned, dtype=float).reshape(-1, 2)
        self.progress = 0
        path = self._plan(self.waypoints)
        self.path = path if path is not None else self.waypoints.copy()
        return self.path

    def adopt(self, path_ned: npt.ArrayLike) -> None:
        """Take a route planned elsewhere (the scenario's global route) as the active one."""
        self.path = np.asarray(path_ned, dtype=float).reshape(-1, 2)
        self.waypoints = self.path.copy()
        self.progress = 0

    def _plan(self, waypoints_ned: np.ndarray) -> np.ndarray | None:
        from planner.global_route import plan_chart_route

        if len(waypoints_ned) < 2:
            return None
        route = plan_chart_route(self.grid, _to_map(waypoints_ned), self.safety_radius, self.spacing)
        if not route.ok:
            self.log(f"global route: waypoint {route.failed_index}: {route.reason}")
            return None
        return route.path[:, ::-1].copy()

    def _update_progress(self, position_ned: tuple[float, float]) -> None:
        if len(self.path) == 0:
            return
        lo = self.progress
        hi = min(len(self.path), lo + 40)       # 40 points (up to 400 m) ahead: no jump to a later pass
        d = np.hypot(self.path[lo:hi, 0] - position_ned[0], self.path[lo:hi, 1] - position_ned[1])
        self.progress = lo + int(np.argmin(d))

    def on_sensed(self, new_cells: np.ndarray, position_ned: tuple[float, float]) -> np.ndarray | None:
        """New sensed obstacle cells ([row, col], already marked on ``grid``): the re-planned dense
        NED route if they block the route ahead, else None."""
        if len(self.path) < 2 or len(new_cells) == 0:
            return None
        self._update_progress(position_ned)
        ahead = self.path[self.progress:]
        if len(ahead) < 2 or not path_blocked(ahead, new_cells, self.grid.resolution, self.safety_radius):
            return None
        # The waypoints still ahead: those after the vessel's nearest route point.
        remaining = [w for w in self.waypoints[1:] if self._index_of(w) > self.progress]
        if not remaining:
            remaining = [self.waypoints[-1]]
        inflated = self.grid.inflate(self.safety_radius)
        keep = [w for w in remaining[:-1] if inflated.is_free(w[1], w[0])] + [remaining[-1]]
        path = self._plan(np.vstack([[position_ned], keep]))
        if path is None:
            return None
        self.waypoints = np.vstack([[position_ned], keep])
        self.path, self.progress = path, 0
        self.replans += 1
        return path

    def _index_of(self, waypoint: np.ndarray) -> int:
        d = np.hypot(self.path[:, 0] - waypoint[0], self.path[:, 1] - waypoint[1])
        return int(np.argmin(d))


# Mission commands whose item carries a position the boat sails to (lat = lon = 0: "here", skipped).
POSITION_COMMANDS = frozenset({M.MAV_CMD_NAV_WAYPOINT, M.MAV_CMD_NAV_LOITER_UNLIM, M.MAV_CMD_NAV_LOITER_TURNS,
                               M.MAV_CMD_NAV_LOITER_TIME, M.MAV_CMD_NAV_LAND, M.MAV_CMD_NAV_SPLINE_WAYPOINT})


def check_mission_items(items: Sequence[MissionItem], to_ned: Callable[[float, float], tuple[float, float]],
                        grid: OccupancyGrid, safety_radius: float,
                        position_ned: tuple[float, float] | None) -> tuple[int, int, str] | None:
    """:func:`check_mission` on an upload's items (``gcs.mission.MissionItem``: ``command``, ``x``,
    ``y``, ``lat``, ``lon``): ``(seq, MAV_MISSION_RESULT, reason)`` of the first bad one, or None.
    ``to_ned(lat, lon)`` -> (north, east) m."""
    seqs, ned = [], []
    for seq, it in enumerate(items):
        if it.command in POSITION_COMMANDS and not (it.x == 0 and it.y == 0):
            seqs.append(seq)
            ned.append(to_ned(it.lat, it.lon))
    if not ned:
        return None
    bad = check_mission(grid, ned, safety_radius, position_ned)
    return None if bad is None else (seqs[bad[0]], bad[1], bad[2])
