"""planner.fence: inclusion and exclusion zones as planning geometry."""

from __future__ import annotations

import math

import numpy as np
import pytest

from planner.fence import Circle, Fence, points_in_polygon

SQUARE = np.array([[10.0, 10.0], [90.0, 10.0], [90.0, 60.0], [10.0, 60.0]])


def test_inclusion_polygon_and_exclusion_circle():
    f = Fence(inclusion_polygons=(SQUARE,), exclusion_circles=(Circle(50.0, 35.0, 8.0),))
    assert f.contains(20.0, 20.0) and not f.contains(5.0, 20.0) and not f.contains(50.0, 35.0)
    assert not f.contains(50.0, 42.9) and f.contains(50.0, 43.1)
    assert f.distance_inside(20.0, 20.0) == pytest.approx(10.0)
    assert f.distance_inside(5.0, 20.0) == pytest.approx(-5.0)
    assert f.distance_inside(50.0, 30.0) == pytest.approx(-3.0)


def test_forbidden_cells_match_the_point_test_at_cell_centres():
    f = Fence(inclusion_polygons=(SQUARE,), exclusion_polygons=(np.array([[30, 20], [40, 20], [35, 30]]),))
    mask = f.forbidden((70, 100), 1.0)
    rng = np.random.default_rng(3)
    for r, c in rng.integers(0, (70, 100), size=(300, 2)):
        assert mask[r, c] == (not f.contains(c + 0.5, r + 0.5))
    assert mask[5, 50] and not mask[15, 50] and mask[22, 35]


def test_even_odd_rule_agrees_with_a_concave_polygon_by_hand():
    l_shape = np.array([[0, 0], [4, 0], [4, 1], [1, 1], [1, 3], [0, 3]], dtype=float)
    px = np.array([0.5, 2.0, 2.0, 0.5, 3.5])
    py = np.array([2.0, 0.5, 2.0, 0.5, 0.9])
    assert points_in_polygon(px, py, l_shape).tolist() == [True, True, False, True, True]


def test_bad_geometry_is_refused():
    with pytest.raises(ValueError):
        Fence(inclusion_polygons=(np.array([[0.0, 0.0], [1.0, 1.0]]),))
    with pytest.raises(ValueError):
        Fence(exclusion_circles=(Circle(0.0, 0.0, math.nan),))
    assert Fence().empty and Fence().forbidden((3, 4), 1.0).sum() == 0
