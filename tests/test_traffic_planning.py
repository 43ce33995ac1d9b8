"""Time-aware traffic in the planner (planner.traffic_map, planner.online) and the autopilot's
encounter monitor (autopilot_bridge.traffic_awareness)."""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest

from autopilot_bridge.ais_tracking import AisReport, TrackerParams
from autopilot_bridge.traffic_awareness import TrafficAwareness
from common.geodesy import LocalFrame
from planner import colregs as C
from planner.gridmap import OccupancyGrid
from planner.online import OnlineParams, VesselState, make_context, plan_cycle
from planner.params import PlannerParams
from planner.traffic_map import MovingObstacle, TrafficSnapshot, first_conflict, occupied, paint

P = C.ColregsParams()
R = 2.0 + math.hypot(5.0, 2.0) + 3.0


def test_occupancy_moves_with_the_ship_and_zones_are_in_her_frame():
    # A ship at (50, 0) sailing north at 2 m/s (map frame), R = 5: at tau = 10 s she is at (50, 20).
    ship = MovingObstacle(1, 50.0, 0.0, 0.0, 2.0, 5.0, C.forbidden_zones(C.CROSSING_GIVE_WAY, 5.0, P))
    snap = TrafficSnapshot((ship,), 1.0, 0.0, (0.0, 0.0))
    disc = TrafficSnapshot((replace(ship, zones=()),), 1.0, 0.0, (0.0, 0.0))
    assert occupied(50.0, 20.0, 10.0, disc) and not occupied(50.0, 20.0, 0.0, disc)
    assert not occupied(50.0, 40.0, 10.0, disc)
    assert occupied(50.0, 40.0, 10.0, snap)        # 20 m ahead of her bow: give-way zone
    assert not occupied(50.0, 12.0, 10.0, snap)    # 8 m astern of her: free
    assert not occupied(60.0, 40.0, 10.0, snap)    # beside the zone (|starboard| > R)


def test_first_conflict_uses_the_arrival_time_along_the_path():
    ship = MovingObstacle(1, 50.0, -30.0, 0.0, 1.0, 5.0)        # crosses y = 0 at x = 50 at tau = 30 s
    snap = TrafficSnapshot((ship,), 1.0, 0.0, (0.0, 0.0), time_slack_s=0.0)
    straight = np.array([[0.0, 0.0], [100.0, 0.0]])
    assert first_conflict(straight, snap) is None                  # at 1 m/s we are there at 50 s: she has passed
    # At 5/3 m/s we meet her at tau = 30 s; within R = 5 from 30 - 5 / sqrt(1 + 25/9) = 27.43 s (0.5 m samples).
    assert first_conflict(straight, replace(snap, speed=50.0 / 30.0)) == pytest.approx(27.43, abs=0.31)


def _ctx():
    grid = OccupancyGrid(np.zeros((240, 400), bool), 0.5)
    ref = np.column_stack([np.arange(20.0, 181.0, 10.0), np.full(17, 60.0)])
    return make_context(grid, (180.0, 60.0), ref, PlannerParams(), OnlineParams(local_iterations=1500), "ddrrt-star")


@pytest.mark.parametrize("seed", [1, 2, 3])
def test_head_on_plan_keeps_to_starboard_and_is_conflict_free(seed):
    ctx = _ctx()
    ship = MovingObstacle(1, 75.0, 60.0, -1.5, 0.0, R, C.forbidden_zones(C.HEAD_ON, R, P))
    snap = TrafficSnapshot((ship,), 1.5, 0.0, (30.0, 60.0))
    rec = plan_cycle(ctx, VesselState(30.0, 60.0, 0.0), 1, seed, traffic=snap)
    assert rec.status == "exact" and len(rec.smooth_path) >= 2, rec.reason
    path = rec.smooth_path
    assert first_conflict(path, replace(snap, speed=1.5 * rec.speed_factor), ignore_within=1.0) is None
    # Heading east, starboard is south (y < 60): the path never goes north of the track by more than noise.
    assert path[:, 1].max() <= 60.5 and path[:, 1].min() <= 60.0 - 5.0


@pytest.mark.parametrize("seed", [1, 2, 3])
def test_crossing_give_way_plan_never_crosses_ahead_of_her(seed):
    ctx = _ctx()
    ship = MovingObstacle(2, 55.0, 35.0, 0.0, 1.2, R, C.forbidden_zones(C.CROSSING_GIVE_WAY, R, P))
    snap = TrafficSnapshot((ship,), 1.5, 0.0, (30.0, 60.0))
    rec = plan_cycle(ctx, VesselState(30.0, 60.0, 0.0), 1, seed, traffic=snap)
    assert len(rec.smooth_path) >= 2, rec.reason
    fast = replace(snap, speed=1.5 * rec.speed_factor, time_slack_s=0.0)
    assert first_conflict(rec.smooth_path, fast, ignore_within=1.0) is None
    # Where our path crosses her track (x = 55), she is already past: we are astern of her.
    path = rec.smooth_path
    s = np.concatenate([[0.0], np.cumsum(np.hypot(*np.diff(path, axis=0).T))])
    i = int(np.argmin(np.abs(path[:, 0] - 55.0)))
    if abs(path[i, 0] - 55.0) < 1.0:
        her_y = 35.0 + 1.2 * s[i] / fast.speed
        assert path[i, 1] < her_y


def test_painted_grid_keeps_the_vessel_cell_free():
    g = OccupancyGrid(np.zeros((100, 100), bool), 0.5)
    ship = MovingObstacle(1, 25.0, 25.0, 0.0, 0.0, 4.0)
    snap = TrafficSnapshot((ship,), 1.0, 0.0, (24.0, 25.0))
    painted = paint(g, snap, (24.0, 25.0), 20.0, keep_free=(24.0, 25.0), keep_radius=0.5)
    assert painted.is_free(24.0, 25.0) and not painted.is_free(27.0, 25.0) and painted.is_free(35.0, 25.0)


class _Nav:
    def __init__(self, x, y, psi, u):
        self.x, self.y, self.psi, self.u, self.v, self.r = x, y, psi, u, 0.0, 0.0


GEO = LocalFrame(38.92, 121.65, 0.0)


def _rep(t, mmsi, north, east, course_deg, speed):
    lat, lon = GEO.sea_level_to_geodetic(north, east)
    return AisReport(t, mmsi, lat, lon, math.radians(course_deg), speed, 5.0, 5.0, 2.0, 2.0)


class _Telemetry:
    def __init__(self):
        self.sent = []

    def forward(self, name, *fields):
        self.sent.append((name, fields))


def test_stand_on_is_left_out_of_planning_until_the_give_way_ship_clearly_fails():
    ta = TrafficAwareness(TrackerParams(), P, GEO)
    tel = _Telemetry()
    # We sail north at 1.5 m/s from the origin; she comes from our port side (west) heading east,
    # on a collision course: both at (90, 0) at t = 60 s.
    events_all = []
    for k in range(0, 61):
        t = float(k)
        reports = [_rep(t, 412000104, 90.0, -60.0 + 1.0 * t, 90.0, 1.0)] if k % 10 == 0 else []
        events, replan = ta.on_frame(t, _Nav(1.5 * t, 0.0, 0.0, 1.5), reports, tel)
        events_all += [(t, e) for e in events]
        snap = ta.snapshot(t, 0.0, 1.5 * t, math.pi / 2, 1.5)
        if t < 35.0:
            assert snap is None or all(ob.ident != 412000104 for ob in snap.obstacles)
    texts = [e for _, e in events_all]
    assert texts[0] == "COLREG 412000104 crossing-stand-on: stand on" and events_all[0][0] == 10.0
    (t17,) = [t for t, e in events_all if "rule 17" in e]
    assert t17 == pytest.approx(60.0 - P.rule17_tcpa, abs=1.0)
    snap = ta.snapshot(40.0, 0.0, 60.0, math.pi / 2, 1.5)
    (ob,) = snap.obstacles
    assert ob.zones and ob.zones[0].frame == "own"            # rule 17(c): no turn to port
    assert len(tel.sent) == 7 and tel.sent[0][0] == "ais_vessel"  # every accepted report forwarded
