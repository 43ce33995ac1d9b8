"""COLREGs rules 13-15 encounter classification on the boundary cases (planner.colregs)."""

from __future__ import annotations

import math

import pytest

from planner import colregs as C

NORTH = 0.0


def at(bearing_deg: float, rng: float = 100.0) -> tuple[float, float]:
    """NED point at a true bearing from the origin."""
    b = math.radians(bearing_deg)
    return rng * math.cos(b), rng * math.sin(b)


def reciprocal_from(pos) -> float:
    """Course (rad) pointing from ``pos`` straight at the origin."""
    return math.atan2(-pos[1], -pos[0])


def test_relative_bearing_is_clockwise_from_the_course():
    assert C.relative_bearing((0, 0), NORTH, (0, 10)) == pytest.approx(90.0)      # east = starboard beam
    assert C.relative_bearing((0, 0), math.pi / 2, (0, 10)) == pytest.approx(0.0)  # heading east: dead ahead
    assert C.relative_bearing((0, 0), NORTH, (-10, 0)) == pytest.approx(180.0)


def test_head_on_reciprocal_courses():
    e = C.classify((0, 0), NORTH, 1.5, (100, 0), math.pi, 2.0)
    assert (e.type, e.role, e.bearing, e.aspect) == (C.HEAD_ON, C.GIVE_WAY, pytest.approx(0.0), pytest.approx(0.0))


@pytest.mark.parametrize("bearing, expect", [(6.0, C.HEAD_ON), (-6.0, C.HEAD_ON), (5.9, C.HEAD_ON),
                                             (6.1, C.CROSSING_GIVE_WAY), (-6.1, C.CROSSING_STAND_ON)])
def test_head_on_sector_boundary_6_degrees_is_inclusive(bearing, expect):
    pos = at(bearing)
    e = C.classify((0, 0), NORTH, 1.5, pos, reciprocal_from(pos), 2.0)
    assert e.type == expect, e


@pytest.mark.parametrize("bearing, expect", [(112.5, C.OVERTAKEN), (112.4, C.CROSSING_GIVE_WAY),
                                             (247.5, C.OVERTAKEN), (247.6, C.CROSSING_STAND_ON),
                                             (180.0, C.OVERTAKEN)])
def test_overtaken_sector_boundary_112_5_degrees_is_inclusive(bearing, expect):
    # A faster target on our course, coming up from `bearing` (22.5 deg abaft the beam = 112.5).
    e = C.classify((0, 0), NORTH, 1.0, at(bearing), NORTH, 2.5)
    assert e.type == expect, (bearing, e)


def test_we_overtake_from_her_stern_sector():
    # A slower target dead ahead on our course: we are at 180 deg from her bow -> we overtake, keep clear.
    e = C.classify((0, 0), NORTH, 2.0, (50, 0), NORTH, 0.8)
    assert (e.type, e.role, e.aspect) == (C.OVERTAKING, C.GIVE_WAY, pytest.approx(180.0))
    # At exactly 112.5 deg from her bow we are still overtaking (rule 13(c): in doubt, assume so).
    her = (50.0, 0.0)
    course = math.radians(180.0 - 112.5)  # her course such that we bear 112.5 deg from her bow
    e = C.classify((0, 0), NORTH, 2.0, her, course, 0.8)
    assert e.aspect == pytest.approx(112.5) and e.type == C.OVERTAKING


@pytest.mark.parametrize("bearing, course_deg, expect", [
    (45.0, 270.0, C.CROSSING_GIVE_WAY),    # on our starboard bow heading west: we give way
    (90.0, 270.0 + 20.0, C.CROSSING_GIVE_WAY),
    (315.0, 90.0, C.CROSSING_STAND_ON),    # on our port bow heading east: we stand on
    (270.0, 70.0, C.CROSSING_STAND_ON),
    (3.0, 270.0, C.CROSSING_GIVE_WAY),     # nearly dead ahead crossing from starboard to port
    (357.0, 90.0, C.CROSSING_STAND_ON),    # nearly dead ahead crossing from port to starboard
])
def test_crossing_sides(bearing, course_deg, expect):
    e = C.classify((0, 0), NORTH, 1.5, at(bearing), math.radians(course_deg), 2.0)
    assert e.type == expect, e


def test_slow_target_is_static_and_roles_and_zones():
    assert C.classify((0, 0), NORTH, 1.5, (30, 0), NORTH, 0.1).type == C.STATIC
    p = C.ColregsParams()
    assert C.needs_planning(C.HEAD_ON, False) and not C.needs_planning(C.CROSSING_STAND_ON, False)
    assert C.needs_planning(C.CROSSING_STAND_ON, True)
    (z,) = C.forbidden_zones(C.CROSSING_GIVE_WAY, 6.0, p)
    assert z.frame == "target" and z.along[0] == 0.0 and z.starboard == (-6.0, 6.0)
    (z,) = C.forbidden_zones(C.HEAD_ON, 6.0, p)
    assert z.starboard[1] > 0  # her starboard side is closed: we pass on her port side
    assert C.forbidden_zones(C.CROSSING_STAND_ON, 6.0, p) == ()
    (z,) = C.forbidden_zones(C.CROSSING_STAND_ON, 6.0, p, act_stand_on=True)
    assert z.frame == "own" and z.starboard[1] < 0  # rule 17(c): no turn to port
