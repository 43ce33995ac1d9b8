"""Table 3 indicators and the termination conditions."""

import math

import numpy as np
import pytest
from scipy.special import gammainc

from planner import PlannerParams
from planner.field import GridField
from planner.gridmap import OccupancyGrid
from planner.metrics import collision_free_probability, path_metrics, waypoint_alpha_sums
from planner.online import sailed_waypoints
from planner.postprocess import dubins_path
from planner.termination import Termination


def test_cf_is_the_product_of_regularised_gamma():
    # n = 2: P(1, x) = 1 - exp(-x); c = clearance / sigma
    clear = np.array([1.0, 2.0])
    expect = (1 - math.exp(-0.5 * 2.0 ** 2)) * (1 - math.exp(-0.5 * 4.0 ** 2))
    assert collision_free_probability(clear, 0.5) == pytest.approx(expect)
    assert gammainc(1.0, 2.0) == pytest.approx(1 - math.exp(-2.0))


def test_metrics_of_a_right_angle_path():
    occ = np.zeros((40, 40), bool)
    occ[:, 0] = True  # wall along x in [0, 0.5)
    grid = OccupancyGrid(occ, 0.5)
    path = np.array([[2.25, 2.25], [12.25, 2.25], [12.25, 12.25]])
    east = GridField.uniform(1.0, 0.0)
    m = path_metrics(path, east, grid, PlannerParams(objective="current"), clearance_sigma=0.5)
    assert m["length"] == pytest.approx(20.0)
    assert m["cost"] == pytest.approx(10 / (1 + math.e) + 10 / (1 + math.exp(-0.1)))  # alpha 0 and pi/2
    assert m["sum_cos"] == pytest.approx(1.0) and m["sum_sin"] == pytest.approx(1.0)
    assert m["turns"] == 1
    assert m["total_curvature"] == pytest.approx(math.pi / 2)
    assert m["bending_energy"] == pytest.approx((math.pi / 2) ** 2 / 10.0)
    # clearances: 2 m (wall centre at x = 0.25), 12 m, 12 m
    expect = (1 - math.exp(-0.5 * 4.0 ** 2)) * (1 - math.exp(-0.5 * 24.0 ** 2)) ** 2
    assert m["cf"] == pytest.approx(expect)


def test_alpha_sums_at_waypoints_count_each_waypoint_once_whatever_the_spacing():
    # The right angle path: two waypoints leave downstream and across (the last waypoint leaves
    # nothing); per 2 m the same path gives 5 + 5 legs, at waypoints 1 + 1.
    east = GridField.uniform(1.0, 0.0)
    path = np.array([[2.0, 2.0], [12.0, 2.0], [12.0, 12.0]])
    wp, wd = sailed_waypoints(path, sailed=math.inf)
    assert wp.tolist() == [[2.0, 2.0], [12.0, 2.0]] and wd.tolist() == [[1.0, 0.0], [0.0, 1.0]]
    assert waypoint_alpha_sums(wp, wd, east) == pytest.approx((1.0, 1.0))
    dense = np.column_stack([np.r_[np.arange(2.0, 12.0, 2.0), np.full(6, 12.0)], np.r_[np.full(5, 2.0),
                                                                                      np.arange(2.0, 13.0, 2.0)]])
    m = path_metrics(dense, east, None, PlannerParams(objective="current"))
    assert m["sum_cos"] == pytest.approx(5.0) and m["sum_sin"] == pytest.approx(5.0)
    # upstream: cos = -1, sin = 0; no field or no current: nothing counted
    assert waypoint_alpha_sums([[0, 0]], [[-3.0, 0.0]], east) == pytest.approx((-1.0, 0.0))
    assert waypoint_alpha_sums(wp, wd, None) == (0.0, 0.0)
    assert waypoint_alpha_sums(wp, wd, GridField.uniform(0.0, 0.0)) == (0.0, 0.0)


def test_sailed_waypoints_stop_where_the_vessel_stopped():
    path = np.array([[0.0, 0.0], [5.0, 0.0], [5.0, 5.0], [10.0, 5.0]])
    wp, _ = sailed_waypoints(path, 7.0)          # passed the waypoint at 5 m, not the one at 10 m
    assert wp.tolist() == [[0.0, 0.0], [5.0, 0.0]]
    wp, _ = sailed_waypoints(path, 0.5)
    assert wp.tolist() == [[0.0, 0.0]]
    assert len(sailed_waypoints(path[:1], 10.0)[0]) == 0


def test_curvature_of_a_sampled_arc():
    arc = dubins_path((0, 0, 0), (0, 6, math.pi), 3.0).sample(0.01)[:, :2]
    m = path_metrics(arc, None, None, PlannerParams())
    assert m["total_curvature"] == pytest.approx(math.pi, rel=3e-3)  # chords miss half a step per end
    assert m["bending_energy"] == pytest.approx(math.pi / 3.0, rel=3e-3)  # int kappa^2 ds = pi R / R^2
    assert m["turns"] == 0  # no vertex turns more than 10 degrees


def test_termination_conditions():
    t = Termination.iterations(5)
    t.notify(4, False)
    assert not t()
    t.notify(5, False)
    assert t()
    now = [0.0]
    d = Termination.deadline(1.0, clock=lambda: now[0])
    assert not d()
    now[0] = 1.0
    assert d()
    e = Termination.exact_solution()
    assert not e.is_bounded()
    both = Termination.any_of(e, Termination.iterations(100))
    assert both.is_bounded()
    both.notify(3, True)
    assert both()
    b = both.bounds()
    assert b.max_iterations == 100 and b.stop_on_exact and not b.poll_python
    assert Termination.any_of(d).bounds().poll_python  # an injected clock is polled from Python
    with pytest.raises(ValueError):
        Termination.iterations(-1)
