"""Section 3.1 subgoal rules and the section 3.2 PGNode."""

import math

import numpy as np
import pytest

from planner.png import pg_node
from planner.subgoal import select_subgoal

REF = np.array([[10.0 * i, 0.0] for i in range(11)])  # 0 .. 100 m along x


def test_rule1_goal_in_domain():
    s = select_subgoal(REF, (90.0, 0.0), 33.0)
    assert (s.rule, s.index, s.point) == (1, 10, (100.0, 0.0))


def test_rule2_only_the_nearest_waypoint_is_left():
    s = select_subgoal(REF, (150.0, 0.0), 33.0)  # past the goal, goal outside the domain
    assert (s.rule, s.index) == (2, 10)


def test_rule3_last_consecutive_waypoint_inside():
    s = select_subgoal(REF, (0.0, 5.0), 33.0)  # inside while sqrt(x^2 + 25) <= 33: x <= 32.6
    assert (s.rule, s.index) == (3, 3)


def test_rule4_nearest_outside_next_inside():
    # domain centred at the vessel (40, 0); the local planning starts at (0, -5), nearest q_0
    s = select_subgoal(REF, (40.0, 0.0), 33.0, start=(0.0, -5.0))
    assert (s.rule, s.index) == (4, 7)  # waypoints 10 .. 70 m are inside, 70 m is the outermost


def test_rule5_drifted_off_the_path():
    s = select_subgoal(REF, (50.0, 50.0), 33.0)
    assert (s.rule, s.index) == (5, 5)


def test_goal_index_and_bad_input():
    s = select_subgoal(REF, (50.0, 0.0), 33.0, goal_index=6)
    assert (s.rule, s.index) == (1, 6)
    with pytest.raises(ValueError):
        select_subgoal(np.zeros((0, 2)), (0, 0), 10.0)


def test_png_target_straight_ahead_running_away():
    # target ahead on the vessel's course, moving the same way: no sight-line rotation
    x, y = pg_node((0.0, 0.0), 0.0, (10.0, 0.0), 0.0, 1.0)
    assert (x, y) == pytest.approx((2.0, 0.0))  # u_t = 2 s_t straight ahead


def test_png_crossing_target_hand_solved():
    """Vessel at the origin heading east, target 10 m east moving north, s_t = 1 m, N = 3.

    Eq. (7), first pass: c_k = sqrt(101), dq = arccos(200 / (2 sqrt(101) 10)) = atan(0.1)
    = 0.0996687 rad; theta = 3 dq = 0.299006; alpha = theta; beta = pi / 2 (the target moves at
    right angles to the sight line); c1 = 10 / cos(alpha) = 10.4652, c2 = 10 tan(alpha) = 3.0835,
    u_c = c1 - 2, s_c = c2 - 1; eq. (8) gives dq = alpha - angle(U_k C, U_k P_k) = 0.0504 ...
    At convergence dq is the true rotation of the sight line from U0 P0 to U1 P1 with
    U1 = 2 (cos 3 dq, sin 3 dq), i.e. the root of
        f(dq) = atan2(1 - 2 sin 3dq, 10 - 2 cos 3dq) - dq,
    solved below by bisection (independently of eqs. (7)-(8)).
    """
    lo, hi = 0.0, 0.1
    def f(d):
        return math.atan2(1 - 2 * math.sin(3 * d), 10 - 2 * math.cos(3 * d)) - d
    for _ in range(200):
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if f(mid) > 0 else (lo, mid)
    dq = 0.5 * (lo + hi)
    expect = (2 * math.cos(3 * dq), 2 * math.sin(3 * dq))
    got = pg_node((0.0, 0.0), 0.0, (10.0, 0.0), math.pi / 2, 1.0, nav_ratio=3.0, tol=1e-13, max_iter=200)
    assert got == pytest.approx(expect, abs=1e-9)
    # first pass numbers of the docstring
    assert math.acos(200 / (2 * math.sqrt(101) * 10)) == pytest.approx(math.atan(0.1))
    # one pass of eqs. (7)-(8) ends with the corrected dq = 0.0504: heading 3 dq
    one = pg_node((0.0, 0.0), 0.0, (10.0, 0.0), math.pi / 2, 1.0, max_iter=1, tol=10.0)
    assert math.atan2(one[1], one[0]) == pytest.approx(3 * 0.0504, abs=0.01)


def test_png_mirror_symmetry():
    a = pg_node((0.0, 0.0), 0.0, (10.0, 0.0), math.pi / 2, 1.0)
    b = pg_node((0.0, 0.0), 0.0, (10.0, 0.0), -math.pi / 2, 1.0)
    assert a[0] == pytest.approx(b[0]) and a[1] == pytest.approx(-b[1])
    assert math.hypot(*a) == pytest.approx(2.0)


def test_png_fixed_point_on_random_geometries():
    """At convergence the heading change is N times the true sight-line rotation between
    U_{k-1} P_{k-1} and U_k P_k (what eqs. (7)-(8) iterate towards)."""
    rng = np.random.default_rng(11)
    checked = 0
    for _ in range(200):
        u = rng.uniform(-5, 5, 2)
        heading = rng.uniform(-math.pi, math.pi)
        rng_dist = rng.uniform(20, 40)
        bearing = heading + rng.uniform(-0.6, 0.6)
        p = u + rng_dist * np.array([math.cos(bearing), math.sin(bearing)])
        t_head = rng.uniform(-math.pi, math.pi)
        s_t = rng.uniform(0.5, 2.0)
        node = np.array(pg_node(u, heading, p, t_head, s_t, nav_ratio=3.0, tol=1e-12, max_iter=500))
        assert np.hypot(*(node - u)) == pytest.approx(2 * s_t)
        dq = ((math.atan2(*(node - u)[::-1]) - heading + math.pi) % (2 * math.pi) - math.pi) / 3.0
        p1 = p + s_t * np.array([math.cos(t_head), math.sin(t_head)])
        q0 = math.atan2(*(p - u)[::-1])
        true = (math.atan2(*(p1 - node)[::-1]) - q0 + math.pi) % (2 * math.pi) - math.pi
        if abs(3 * true) < math.pi / 2:  # heading changes beyond 90 deg leave the triangle case
            assert dq == pytest.approx(true, abs=1e-6)
            checked += 1
    assert checked > 100


def test_ddrrt_png_node_is_no_farther_than_the_subgoal_and_in_the_domain():
    from planner import PlannerParams, PlanningProblem
    from planner.ddrrt_star import DDRRTStar
    from planner.gridmap import OccupancyGrid

    grid = OccupancyGrid(np.zeros((200, 200), bool), 0.5)
    ref = np.array([[10.0, 10.0], [40.0, 10.0], [40.0, 60.0], [90.0, 60.0]])
    for pos, heading in (((10.0, 12.0), 0.0), ((35.0, 12.0), 1.0), ((42.0, 30.0), 1.6)):
        sg = select_subgoal(ref, pos, 33.0)
        prob = PlanningProblem(grid, pos, sg.point, start_heading=heading, reference_path=ref,
                               domain_center=pos, domain_radius=33.0)
        node = DDRRTStar(PlannerParams()).png_node(prob)
        d_goal = math.hypot(sg.point[0] - pos[0], sg.point[1] - pos[1])
        assert math.hypot(node[0] - pos[0], node[1] - pos[1]) <= d_goal + 1e-9
        x0, x1, y0, y1 = prob.sampling_box()
        assert x0 <= node[0] <= x1 and y0 <= node[1] <= y1
