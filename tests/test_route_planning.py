"""autopilot_bridge.route_planning: the mission check and the route re-planned round sensed obstacles."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from pymavlink.dialects.v20 import common as M

from autopilot_bridge.route_planning import RouteKeeper, check_mission, check_mission_items
from planner.gridmap import OccupancyGrid


def pond_chart() -> OccupancyGrid:
    """As tests/test_sparse_routes.py: a wall at x = 50-52 m (y < 60 m), a closed ring round (80, 60)."""
    y, x = (np.mgrid[0:160, 0:200] + 0.5) * 0.5
    occ = (x >= 50) & (x < 52) & (y < 60)
    r = np.hypot(x - 80, y - 60)
    return OccupancyGrid(occ | ((r >= 8) & (r < 10)), 0.5)


def test_check_mission_results():
    chart = pond_chart()
    here = (20.0, 10.0)                                  # NED: 20 m north, 10 m east
    assert check_mission(chart, [(20.0, 30.0), (20.0, 90.0)], 2.0, here) is None
    assert check_mission(chart, [(20.0, 30.0), (30.0, 51.0)], 2.0, here) == (1, M.MAV_MISSION_INVALID,
                                                                              "in obstacle or 2 m margin")
    assert check_mission(chart, [(60.0, 80.0)], 2.0, here) == (0, M.MAV_MISSION_INVALID, "unreachable by water")
    assert check_mission(chart, [(20.0, 30.0), (95.0, 30.0)], 2.0, here)[:2] == (1, M.MAV_MISSION_INVALID_PARAM5_X)
    assert check_mission(chart, [(20.0, 30.0), (30.0, -1.0)], 2.0, here)[:2] == (1, M.MAV_MISSION_INVALID_PARAM6_Y)
    # Without a position the items must still reach one another.
    assert check_mission(chart, [(20.0, 30.0), (60.0, 80.0)], 2.0, None)[:2] == (1, M.MAV_MISSION_INVALID)
    assert check_mission(chart, [(60.0, 80.0)], 2.0, None) is None        # alone, in the pond: nothing to reach


@dataclass(frozen=True)
class Item:
    command: int
    x: int
    y: int

    @property
    def lat(self) -> float:
        return self.x * 1e-7

    @property
    def lon(self) -> float:
        return self.y * 1e-7


def test_item_numbers_count_every_item_and_skip_the_ones_without_a_position():
    def to_ned(lat, lon):
        return (lat * 1e7, lon * 1e7)
    items = [Item(M.MAV_CMD_NAV_WAYPOINT, 20, 30), Item(M.MAV_CMD_DO_CHANGE_SPEED, 0, 0),
             Item(M.MAV_CMD_NAV_LOITER_TIME, 0, 0), Item(M.MAV_CMD_NAV_WAYPOINT, 30, 51)]
    assert check_mission_items(items, to_ned, pond_chart(), 2.0, (20.0, 10.0)) == (3, M.MAV_MISSION_INVALID,
                                                                                  "in obstacle or 2 m margin")
    assert check_mission_items(items[:3], to_ned, pond_chart(), 2.0, (20.0, 10.0)) is None


def test_route_is_planned_and_replanned_round_a_sensed_obstacle():
    chart = pond_chart()
    keeper = RouteKeeper(chart, 2.0)
    path = keeper.set_route([(20.0, 10.0), (20.0, 90.0)])      # NED; the wall lies across
    assert path[:, 0].max() > 60.0 and np.allclose(path[-1], (20.0, 90.0))
    keeper2 = RouteKeeper(pond_chart(), 2.0)
    straight = keeper2.set_route([(20.0, 10.0), (20.0, 45.0)])
    assert len(straight) == 5 and np.allclose(straight[:, 0], 20.0)       # free: straight, densified
    # A buoy sensed on the straight leg: marked on the keeper's grid, then reported.
    cells = np.array([[r, c] for r in range(38, 43) for c in range(58, 63)])   # ~ (20 N, 30 E)
    keeper2.grid.mark(cells)
    new = keeper2.on_sensed(cells, (20.0, 12.0))
    assert new is not None and np.allclose(new[0], (20.0, 12.0)) and np.allclose(new[-1], (20.0, 45.0))
    grid = keeper2.grid.inflate(2.0)
    assert all(grid.segment_free(a[1], a[0], b[1], b[0]) for a, b in zip(new[:-1], new[1:], strict=True))
    assert keeper2.on_sensed(np.array([[150, 10]]), (20.0, 12.0)) is None      # far from the route: kept
