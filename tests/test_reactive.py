"""The reactive obstacle-avoidance behaviour (the fallback when no local path exists)."""

from __future__ import annotations

import math

import numpy as np

from autopilot_bridge.angles import wrap_angle
from autopilot_bridge.reactive import ReactiveAvoidance
from planner.gridmap import OccupancyGrid

RES = 0.5


def grid_with(*boxes) -> OccupancyGrid:
    """A 60 m x 60 m map (x east, y north) with obstacle boxes (x0, x1, y0, y1) in metres."""
    occ = np.zeros((120, 120), dtype=bool)
    for x0, x1, y0, y1 in boxes:
        occ[int(y0 / RES):int(y1 / RES), int(x0 / RES):int(x1 / RES)] = True
    return OccupancyGrid(occ, RES)


def test_open_water_heads_for_the_target_at_cruise_speed():
    r = ReactiveAvoidance(grid_with(), max_range=15.0, min_clearance=1.5, cruise_speed=0.8)
    a = r.command(north=30.0, east=30.0, heading=0.0, target=(30.0, 50.0))  # target due east
    # towards the target, biased a little towards the present course (a steady turn)
    assert abs(wrap_angle(a.heading - math.pi / 2)) < math.radians(20)
    assert a.speed > 0.75


def test_a_wall_across_the_way_is_avoided_not_hit():
    # Wall east of the vessel, across the line to the target; the way round is north or south.
    r = ReactiveAvoidance(grid_with((36.0, 38.0, 20.0, 40.0)), 15.0, 1.5, 0.8)
    a = r.command(north=30.0, east=30.0, heading=math.pi / 2, target=(30.0, 50.0))
    assert abs(wrap_angle(a.heading - math.pi / 2)) > math.radians(20)  # not straight into it
    assert a.free_ahead > 3.0


def test_running_along_a_wall_keeps_away_from_it():
    # Wall just to starboard (east) of a northbound vessel, 1.5 m off: a course parallel to the
    # wall is not free (no room beside it); the behaviour edges away to port.
    r = ReactiveAvoidance(grid_with((31.5, 33.0, 0.0, 60.0)), 15.0, 1.5, 0.8)
    a = r.command(north=20.0, east=30.0, heading=0.0, target=(50.0, 30.0))
    assert wrap_angle(a.heading) < -math.radians(5)


def test_boxed_in_stops():
    # an 8 m x 8 m pen
    r = ReactiveAvoidance(grid_with((25.0, 35.0, 25.0, 26.0), (25.0, 35.0, 34.0, 35.0),
                                    (25.0, 26.0, 25.0, 35.0), (34.0, 35.0, 25.0, 35.0)), 15.0, 1.5, 0.8)
    a = r.command(north=30.0, east=30.0, heading=0.0, target=(55.0, 55.0))
    assert a.speed < 0.3
