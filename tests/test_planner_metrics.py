"""Table 3 indicators and the termination conditions."""

import math

import numpy as np
import pytest
from scipy.special import gammainc

from planner import PlannerParams
from planner.field import GridField
from planner.gridmap import OccupancyGrid
from planner.metrics import collision_free_probability, path_metrics
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
