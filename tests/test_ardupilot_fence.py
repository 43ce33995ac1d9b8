"""The chart as ArduPilot exclusion-fence polygons (hil/ardupilot_fence.py), within ArduRover's limits."""

from __future__ import annotations

import numpy as np
import pytest
from shapely import Point, Polygon, box, unary_union

from common.geodesy import LocalFrame
from hil import scenario as scenarios
from hil.ardupilot_fence import (
    DIJKSTRA_MAX_POINTS,
    FENCE_MAX_ITEMS,
    chart_polygons,
    dijkstra_points,
    fence_items,
    oa_params,
)


def _cells(occ: np.ndarray, res: float) -> list[Polygon]:
    rows, cols = np.nonzero(occ)
    return [box(c * res, r * res, (c + 1) * res, (r + 1) * res) for r, c in zip(rows, cols, strict=True)]


def test_the_harbour_chart_fits_arduRovers_fence_and_dijkstra_and_covers_every_obstacle() -> None:
    scen = scenarios.load("harbour")
    wps = scen.waypoints
    assert wps is not None
    polys = chart_polygons(scen.occ, scen.resolution)
    shapes = [Polygon(p) for p in polys]
    assert all(s.is_valid and len(p) >= 3 for s, p in zip(shapes, polys, strict=True))
    assert all(s.exterior.is_ccw for s in shapes)
    assert sum(len(p) for p in polys) <= FENCE_MAX_ITEMS
    assert dijkstra_points(polys) <= DIJKSTRA_MAX_POINTS
    fence = unary_union(shapes)
    assert fence.buffer(1e-6).covers(unary_union(_cells(scen.occ, scen.resolution)))   # no obstacle left out
    # The route's waypoints as given lie in open water, outside every polygon...
    for x, y in wps:
        assert not fence.contains(Point(x, y)), (x, y)
    # ...and the 7 m channel between the breakwater's end and the outer mole stays open, with room for
    # the Dijkstra's 2 m margin on both sides.
    assert fence.distance(Point(150.0, 116.5)) >= 2.5
    # But the straight legs cross the chart: the route as given needs the fence to be flown.
    assert any(fence.intersects(box(*np.minimum(a, b), *np.maximum(a, b)).boundary)
               for a, b in zip(wps[:-1], wps[1:], strict=True))


def test_a_rectangle_is_four_vertices_grown_by_the_tolerance() -> None:
    occ = np.zeros((40, 40), dtype=bool)
    occ[10:20, 4:30] = True                    # x 2-15 m, y 5-10 m at 0.5 m
    (ring,) = chart_polygons(occ, 0.5, tolerance=0.5)
    assert len(ring) == 4
    assert np.allclose(sorted(map(tuple, ring)), sorted([(1.5, 4.5), (15.5, 4.5), (15.5, 10.5), (1.5, 10.5)]))
    assert chart_polygons(np.zeros((5, 5), dtype=bool), 0.5) == []


def test_notches_fill_to_fit_but_separate_obstacles_never_merge() -> None:
    # A comb: a spine with 12 teeth 2 m apart (52 vertices) fits a budget of 8 once its notches fill.
    occ = np.zeros((60, 120), dtype=bool)
    occ[4:8, 4:100] = True
    for k in range(12):
        occ[8:30, 4 + 8 * k:8 + 8 * k] = True
    assert sum(len(p) for p in chart_polygons(occ, 0.5)) > 8
    (ring,) = chart_polygons(occ, 0.5, max_vertices=8)
    assert len(ring) <= 8
    # Thirty separate squares 3 m apart cannot be merged into fewer vertices: a one-line error.
    occ = np.zeros((40, 320), dtype=bool)
    for k in range(30):
        occ[10:14, 4 + 10 * k:8 + 10 * k] = True
    with pytest.raises(ValueError, match="more than 84 fence vertices"):
        chart_polygons(occ, 0.5)


def test_dijkstra_counts_a_safe_point_per_convex_corner() -> None:
    ell = np.array([[0, 0], [4, 0], [4, 1], [1, 1], [1, 4], [0, 4]], dtype=float)   # one concave corner
    assert dijkstra_points([ell]) == 5
    assert dijkstra_points([ell, ell[::-1][[0, 5, 4, 3, 2, 1]]]) == 10


def test_fence_items_are_each_vertex_in_order_with_its_polygons_count() -> None:
    geo = LocalFrame(59.4, 10.5, 0.0)
    polys = [np.array([[0.0, 0.0], [10.0, 0.0], [10.0, 5.0]]), np.array([[20, 20], [30, 20], [30, 30], [20, 30.0]])]
    items = fence_items(polys, geo)
    assert [i.seq for i in items] == list(range(7))
    assert [i.vertices for i in items] == [3, 3, 3, 4, 4, 4, 4]
    for item, (x, y) in zip(items, np.vstack(polys), strict=True):
        n, e = geo.geodetic_to_sea_level(item.lat, item.lon)
        assert (n, e) == pytest.approx((y, x), abs=1e-6)


def test_the_parameters_a_rover_user_sets() -> None:
    p = oa_params(2.0, 1.0)
    assert p == {"FENCE_ENABLE": 1.0, "FENCE_TYPE": 4.0, "FENCE_MARGIN": 1.0, "OA_TYPE": 2.0, "OA_MARGIN_MAX": 2.0}
