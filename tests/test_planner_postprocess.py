"""Section 2.4: pruning, Dubins curves (closed-form cases), smoothing and the re-check."""

import math

import numpy as np
import pytest

from planner import PlannerParams, PlanningProblem, Termination, make_planner
from planner.cost import path_cost
from planner.field import GridField
from planner.gridmap import OccupancyGrid
from planner.postprocess import WORDS, check_and_replan, dubins_path, prune, smooth


def cluttered(seed: int) -> OccupancyGrid:
    rng = np.random.default_rng(seed)
    occ = np.zeros((100, 100), bool)
    for _ in range(12):
        r, c = rng.integers(5, 90, 2)
        h, w = rng.integers(2, 12, 2)
        occ[r:r + h, c:c + w] = True
    occ[:6, :6] = False
    occ[-6:, -6:] = False
    return OccupancyGrid(occ, 0.5)


@pytest.mark.parametrize("seed", range(6))
def test_prune_never_increases_cost_nor_collides(seed):
    grid = cluttered(seed)
    field = GridField.sample(lambda x, y: (0.4 * np.sin(y / 8), 0.3 * np.cos(x / 9)), 50, 50, 1.0)
    params = PlannerParams(objective="current" if seed % 2 else "length")
    res = make_planner("rrt-star", params, seed=seed).solve(
        PlanningProblem(grid, (1.0, 1.0), (48.0, 48.0), field=field), Termination.iterations(3000))
    assert res.status != "none"
    def cost_fn(p):
        return path_cost(p, field, params)
    pruned = prune(res.path, grid, cost_fn)
    assert cost_fn(pruned) <= cost_fn(res.path) + 1e-9
    assert grid.path_free(pruned)
    assert np.array_equal(pruned[0], res.path[0]) and np.array_equal(pruned[-1], res.path[-1])
    assert len(pruned) <= len(res.path)


def test_prune_zigzag_in_free_space_and_keeps_needed_corner():
    free = OccupancyGrid(np.zeros((40, 40), bool), 0.5)
    zig = np.array([[1, 1], [3, 2], [5, 1], [7, 2], [9, 1]], float)
    out = prune(zig, free, lambda p: path_cost(p, None, PlannerParams()))
    assert np.array_equal(out, [[1, 1], [9, 1]])
    occ = np.zeros((40, 40), bool)
    occ[0:30, 18:20] = True  # wall x in [9, 10), y < 15
    g = OccupancyGrid(occ, 0.5)
    path = np.array([[2, 2], [5, 16], [9.5, 16], [14, 16], [17, 2]], float)
    out = prune(path, g, lambda p: path_cost(p, None, PlannerParams()))
    assert g.path_free(out) and len(out) >= 3


R = 2.0


def test_dubins_straight_line_and_half_circle():
    d = dubins_path((0, 0, 0), (10, 0, 0), R)
    assert d.length == pytest.approx(10.0)
    d = dubins_path((0, 0, 0), (0, 2 * R, math.pi), R)
    assert d.length == pytest.approx(math.pi * R)
    assert d.word == "LSL" and d.segments[1] == pytest.approx(0.0)


L = 5.0
# (end pose, optimal word, length): quarter turn, straight L, quarter turn -> pi R + L
CLOSED_FORM = [
    ((0.0, L + 2 * R, math.pi), "LSL", math.pi * R + L),
    ((0.0, -(L + 2 * R), math.pi), "RSR", math.pi * R + L),
    ((2 * R, 2 * R + L, 0.0), "LSR", math.pi * R + L),
    ((2 * R, -(2 * R + L), 0.0), "RSL", math.pi * R + L),
    # right pi/6, left 4 pi/3, right pi/6 ends at (0, (2 sqrt 3 - 2) R, pi): length 5 pi R / 3
    ((0.0, (2 * math.sqrt(3) - 2) * R, math.pi), "RLR", 5 * math.pi * R / 3),
    ((0.0, -(2 * math.sqrt(3) - 2) * R, math.pi), "LRL", 5 * math.pi * R / 3),
]


@pytest.mark.parametrize("end,word,length", CLOSED_FORM)
def test_dubins_closed_form_words(end, word, length):
    d = dubins_path((0.0, 0.0, 0.0), end, R)
    assert d.word == word
    assert d.length == pytest.approx(length, abs=1e-9)
    x, y, th = d.end()
    assert (x, y) == pytest.approx(end[:2], abs=1e-9)
    assert math.cos(th - end[2]) == pytest.approx(1.0)


def test_every_word_reaches_its_end_pose():
    rng = np.random.default_rng(7)
    for _ in range(300):
        q0 = (*rng.uniform(-10, 10, 2), rng.uniform(-4, 4))
        q1 = (*rng.uniform(-10, 10, 2), rng.uniform(-4, 4))
        best = dubins_path(q0, q1, 1.5)
        for w in WORDS:
            try:
                d = dubins_path(q0, q1, 1.5, word=w)
            except ValueError:
                continue
            x, y, th = d.end()
            assert (x, y) == pytest.approx(q1[:2], abs=1e-7)
            assert math.cos(th - q1[2]) == pytest.approx(1.0, abs=1e-9)
            assert best.length <= d.length + 1e-9
        pts = best.sample(0.1)
        steps = np.hypot(*np.diff(pts[:, :2], axis=0).T)
        assert steps.max() <= 0.1 + 1e-9


def test_smooth_keeps_turning_radius_and_endpoints():
    path = np.array([[0, 0], [20, 0], [20, 20], [40, 20]], float)
    dense = smooth(path, 3.0, start_heading=0.0, step=0.1)
    assert np.allclose(dense[0], path[0]) and np.allclose(dense[-1], path[-1], atol=1e-7)
    h = np.arctan2(*np.diff(dense, axis=0).T[::-1])
    dth = np.abs((np.diff(h) + math.pi) % (2 * math.pi) - math.pi)
    assert dth.max() <= 0.1 / 3.0 + 1e-3  # curvature <= 1 / R


def test_check_and_replan_fixes_a_corner_by_choosing_waypoint_headings():
    occ = np.zeros((80, 80), bool)
    occ[25:40, 15:19] = True  # x in [7.5, 9.5), y in [12.5, 20): beside the first leg (x = 10)
    grid = OccupancyGrid(occ, 0.5)
    path = np.array([[10.0, 10.0], [10.0, 30.0], [30.0, 30.0]])
    assert grid.path_free(path)
    # the Dubins curve arriving at (10, 30) with the bisector heading (45 deg) swings out to
    # x = 10 - 6 (1 - cos 45 deg) = 8.2 m along the first leg: through the obstacle
    assert not grid.path_free(smooth(path, 6.0, start_heading=math.pi / 2, step=0.1))
    out = check_and_replan(path, grid, radius=6.0, start_heading=math.pi / 2, step=0.1)
    assert out.ok, out.reason
    assert out.replanned == 0  # arriving heading north at the corner clears it
    assert all(grid.segment_free(*out.dense[k], *out.dense[k + 1]) for k in range(len(out.dense) - 1))
    h = np.arctan2(*np.diff(out.dense, axis=0).T[::-1])
    assert np.abs((np.diff(h) + math.pi) % (2 * math.pi) - math.pi).max() <= 0.1 / 6.0 + 1e-3


def test_check_and_replan_calls_the_planner_for_an_infeasible_leg_and_reports_failure():
    occ = np.zeros((80, 80), bool)
    occ[24:28, 30:34] = True  # x in [15, 17), y in [12, 14): where the left turn from east swings
    grid = OccupancyGrid(occ, 0.5)
    path = np.array([[10.0, 10.0], [10.0, 30.0]])
    calls = []

    def replan(p, q, heading):
        calls.append((p, q, heading))
        return None  # the planner gives up: the leg is split instead

    out = check_and_replan(path, grid, radius=6.0, start_heading=0.0, step=0.1, replan=replan, max_rounds=2)
    assert calls[0] == ((10.0, 10.0), (10.0, 30.0), 0.0)
    assert not out.ok and "still violate" in out.reason
    assert out.replanned >= 2
