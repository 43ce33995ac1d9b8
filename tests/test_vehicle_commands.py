"""The command API checks every target like a mission item (issue 36 point 6; issue 33's fence), in-process."""

from __future__ import annotations

import math

import numpy as np
from scipy.ndimage import distance_transform_edt
from support.vessel_harness import build_computer, frame

from autopilot_bridge.gcs.mission import MissionItem
from autopilot_bridge.modes import Mode
from common.geodesy import LocalFrame
from common.mavlink import MAV_TYPE as M
from planner.fence import Circle, Fence

GEO = LocalFrame(38.92, 121.65, 0.0)
START = (40.0, 22.0)    # NED m


def computer():
    ap, _, _ = build_computer()
    t = 0.0
    for _ in range(100):
        t += 0.01
        ap.on_frame(frame(t, *START), 0.0)
    return ap


def rock(ap) -> tuple[float, float]:
    """A point (NED m) 3 m inside an obstacle of the chart."""
    depth = distance_transform_edt(ap.world.occ) * ap.world.resolution
    row, col = np.argwhere(depth >= 3.0)[0]
    return (row + 0.5) * ap.world.resolution, (col + 0.5) * ap.world.resolution


def item(command: int, north: float, east: float, p1: float = 0.0) -> MissionItem:
    lat, lon = GEO.sea_level_to_geodetic(north, east)
    return MissionItem(M.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT, command, 1, p1, 0.0, 0.0, 0.0,
                       int(round(lat * 1e7)), int(round(lon * 1e7)), 0.0)


def test_guided_home_and_speed_targets_are_checked():
    ap = computer()
    c = ap.commands
    n, e = rock(ap)
    r = c.goto(n, e)
    assert not r.ok and "GUIDED target" in r.text and ap.vehicle.mode == Mode.HOLD
    assert not c.set_home(n, e).ok and ap.vehicle.home == START
    assert not c.goto(-50.0, 20.0).ok                                  # off the chart
    assert not c.goto(math.nan, 20.0).ok
    assert c.goto(50.0, 28.0).ok and ap.vehicle.mode == Mode.GUIDED
    for bad in (-50.0, math.inf, math.nan, 9.0):
        assert not c.set_speed(bad).ok, bad
    assert c.set_speed(1.0).ok and ap.vehicle.speed_setpoint() == 1.0


def test_a_mission_home_item_in_an_obstacle_is_refused_with_its_seq():
    ap = computer()
    n, e = rock(ap)
    items = (item(M.MAV_CMD_NAV_WAYPOINT, *START), item(M.MAV_CMD_NAV_WAYPOINT, 50.0, 28.0),
             item(M.MAV_CMD_DO_SET_HOME, n, e))
    bad = ap.commands.check_mission(items, GEO.geodetic_to_sea_level)
    assert bad is not None and bad[0] == 2 and bad[1] == M.MAV_MISSION_INVALID and "DO_SET_HOME" in bad[2]


def test_the_fence_refuses_targets_rally_points_and_mission_items_outside_it():
    ap = computer()
    c = ap.commands
    c.replace_fence(Fence(exclusion_circles=(Circle(28.0, 50.0, 4.0),)))      # map x east, y north
    assert not c.goto(50.0, 28.0).ok                                        # inside the exclusion circle
    assert c.check_rally(((50.0, 28.0),)) is not None
    assert c.check_rally(((30.0, 30.0),)) is None
    items = (item(M.MAV_CMD_NAV_WAYPOINT, *START), item(M.MAV_CMD_NAV_WAYPOINT, 50.0, 28.0))
    bad = c.check_mission(items, GEO.geodetic_to_sea_level)
    assert bad is not None and bad[0] == 1 and "geofence" in bad[2]
    c.replace_rally(((30.0, 30.0),))
    assert ap.keeper.geofence.rally_point((45.0, 25.0)) == (30.0, 30.0)
    assert c.set_mode(Mode.RTL).ok and tuple(ap.vehicle.route.path[-1]) == (30.0, 30.0)   # RTL to the rally point


def test_a_planner_that_keeps_failing_and_uncertain_navigation_hold_station():
    from autopilot_bridge.behaviour import Behaviour
    from autopilot_bridge.navigation import NavState
    from autopilot_bridge.onboard_failsafes import PLANNER_FAIL_S, POSITION_STD_LIMIT

    ap = computer()
    ap.commands.arm(True)
    assert ap.commands.set_mode(Mode.AUTO).ok
    fs = ap.failsafes
    s = NavState(t=10.0, x=40.0, y=22.0, psi=0.0, u=0.0, v=0.0, r=0.0, gyro_bias=0.0, position_std=0.5)
    fs.check(s, Behaviour.FALLBACK)
    fs.check(NavState(**{**s.__dict__, "t": 10.0 + PLANNER_FAIL_S - 1.0}), Behaviour.FALLBACK)
    assert ap.vehicle.mode == Mode.AUTO
    fs.check(NavState(**{**s.__dict__, "t": 10.0 + PLANNER_FAIL_S + 0.1}), Behaviour.FALLBACK)
    assert ap.vehicle.mode == Mode.LOITER and fs.events == 1
    assert any("planner failsafe" in e for _, e in ap.stats.events)
    assert ap.commands.set_mode(Mode.GUIDED).ok
    fs.check(NavState(**{**s.__dict__, "t": 60.0, "position_std": POSITION_STD_LIMIT + 1.0}), Behaviour.PLANNED)
    assert ap.vehicle.mode == Mode.LOITER and fs.events == 2
    assert any("navigation failsafe" in e for _, e in ap.stats.events)
