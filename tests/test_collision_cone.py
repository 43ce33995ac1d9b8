"""Eqs. (9)-(10) on hand-solved geometry (planner.collision_cone)."""

from __future__ import annotations

import math

import pytest

from planner.collision_cone import assess, cone_components, cone_half_angle, cpa_series, on_collision_course


def test_head_on_on_the_line_of_sight_is_the_v_theta_zero_branch():
    # O at the origin at 2 m/s along +x; F 100 m ahead at 3 m/s along -x: theta = 0, alpha = 0, beta = pi.
    v_theta, v_r = cone_components(100.0, 0.0, 2.0, 0.0, 3.0, math.pi)
    assert v_theta == pytest.approx(0.0, abs=1e-12)
    assert v_r == pytest.approx(-5.0)
    assert on_collision_course(100.0, v_theta, v_r, radius=0.5)   # V_theta = 0 and V_r < 0
    a = assess((0, 0), (2, 0), (100, 0), (-3, 0), 5.0)
    assert a.collision and a.tcpa == pytest.approx(20.0) and a.dcpa == pytest.approx(0.0, abs=1e-9)


@pytest.mark.parametrize("v_f, expect", [(3.0, False), (2.0, False)])
def test_v_theta_zero_but_not_closing_is_safe(v_f, expect):
    # F ahead moving away faster (V_r = +1 > 0) or at the same velocity (V_r = 0): no collision.
    v_theta, v_r = cone_components(50.0, 0.0, 2.0, 0.0, v_f, 0.0)
    assert v_theta == pytest.approx(0.0, abs=1e-12)
    assert on_collision_course(50.0, v_theta, v_r, 10.0) is expect


def test_oblique_closing_inside_and_outside_the_cone():
    # O still; F at (10, 0) moving (-1, 1): V_theta = 1, V_r = -1, r = 10.
    # r^2 V_theta^2 = 100; R^2 (V_r^2 + V_theta^2) = 2 R^2: collision iff R >= sqrt(50).
    v_theta, v_r = cone_components(10.0, 0.0, 0.0, 0.0, math.sqrt(2.0), 3 * math.pi / 4)
    assert (v_theta, v_r) == (pytest.approx(1.0), pytest.approx(-1.0))
    assert on_collision_course(10.0, v_theta, v_r, math.sqrt(50.0) + 1e-9)
    assert not on_collision_course(10.0, v_theta, v_r, math.sqrt(50.0) - 1e-6)
    a = assess((0, 0), (0, 0), (10, 0), (-1, 1), 5.0)
    assert not a.collision and a.dcpa == pytest.approx(math.sqrt(50.0)) and a.tcpa == pytest.approx(5.0)


def test_own_velocity_enters_through_alpha():
    # O at 1 m/s along +x, F at (10, 10) at 1 m/s along -y: they meet at (10, 0) at t = 10 s.
    # theta = pi/4, alpha = 0, beta = -pi/2: V_theta = sin(-3pi/4) - sin(-pi/4) = 0,
    # V_r = cos(-3pi/4) - cos(-pi/4) = -sqrt(2).
    v_theta, v_r = cone_components(10 * math.sqrt(2), math.pi / 4, 1.0, 0.0, 1.0, -math.pi / 2)
    assert v_theta == pytest.approx(0.0, abs=1e-12) and v_r == pytest.approx(-math.sqrt(2))
    a = assess((0, 0), (1, 0), (10, 10), (0, -1), 1.0)
    assert a.collision and a.tcpa == pytest.approx(10.0) and a.dcpa == pytest.approx(0.0, abs=1e-9)
    # The same target passing 1 s later misses by ~0.71 m: inside R = 1, outside R = 0.5.
    late = assess((0, 0), (1, 0), (10, 11), (0, -1), 1.0)
    assert late.collision and late.dcpa == pytest.approx(1 / math.sqrt(2), rel=1e-6)
    assert not assess((0, 0), (1, 0), (10, 11), (0, -1), 0.5).collision


def test_frame_independence_ned_and_map():
    # The same encounter in NED (north, east) and in the map frame (east, north).
    ned = assess((0, 0), (1.5, 0), (40, 8), (-1.0, -0.4), 6.0)
    mp = assess((0, 0), (0, 1.5), (8, 40), (-0.4, -1.0), 6.0)
    assert ned.collision == mp.collision
    assert (ned.tcpa, ned.dcpa, abs(ned.v_theta), ned.v_r) == pytest.approx((mp.tcpa, mp.dcpa, abs(mp.v_theta), mp.v_r))


def test_half_angle_and_vectorised_cpa():
    assert cone_half_angle(10.0, 5.0) == pytest.approx(math.pi / 6)
    assert cone_half_angle(1.0, 5.0) == pytest.approx(math.pi / 2)
    t, d = cpa_series([[10, 0], [10, 0]], [[-1, 1], [1, 0]])
    assert t.tolist() == pytest.approx([5.0, 0.0]) and d.tolist() == pytest.approx([math.sqrt(50), 10.0])
