"""The chart as ArduPilot exclusion fences: polygons a Rover user would upload as stay-out zones.

ArduRover's Dijkstra path planner (``OA_TYPE`` 2) plans round the polygon fence it holds, so a route
that crosses the chart (a mole, a breakwater) is flown round it once the chart is its fence. A scenario's
chart is an occupancy grid; each connected obstacle becomes one polygon: the union of its cells,
simplified (Douglas-Peucker, ``tolerance`` m) and then grown by the same ``tolerance`` with mitred
corners, so every obstacle cell lies inside its polygon (simplifying moves the outline by at most
``tolerance``) while a rectangle stays four vertices. Holes (water walled in) are filled: a boat cannot
reach them. Polygons that touch after growing are merged.

ArduPilot's limits (``libraries/AC_Avoidance/AP_OADijkstra.cpp``, read to learn them): fewer than 255
"safe" points in all, one per convex vertex (the Dijkstra fails with "too many fence points"
otherwise), and no polygon may cross itself. :func:`dijkstra_points` counts the first; shapely's
validity the second.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

if TYPE_CHECKING:
    from common.geodesy import LocalFrame

FENCE_VERTEX_EXCLUSION = 5002      # MAV_CMD_NAV_FENCE_POLYGON_VERTEX_EXCLUSION: param1 = the polygon's vertex count
MISSION_TYPE_FENCE = 1             # MAV_MISSION_TYPE_FENCE
DIJKSTRA_MAX_POINTS = 254          # AP_OADijkstra: total safe points must stay below 255
# The fence items the shipped ArduRover SITL stores: more are refused ("Only 84 items are supported").
FENCE_MAX_ITEMS = 84


@dataclass(frozen=True)
class FenceItem:
    """One fence mission item: a vertex of an exclusion polygon."""

    seq: int
    vertices: int          # the polygon's vertex count (param1)
    lat: float             # deg
    lon: float             # deg


def chart_polygons(occ: np.ndarray, resolution: float, tolerance: float = 0.5,
                   max_vertices: int = FENCE_MAX_ITEMS) -> list[np.ndarray]:
    """Exclusion polygons of the chart ``occ`` (rows north, columns east, True = obstacle; cells of
    ``resolution`` m): each an (N, 2) array of map x east, y north in m, counter-clockwise, not closed
    (the first vertex is not repeated), N >= 3; largest first. Where all of them have more than
    ``max_vertices`` vertices, each polygon's notches are filled (a morphological closing of the
    polygon alone, 1, 2, 3 ... m: a notch narrower than twice that fills; the water between two
    polygons stays open) until they fit; ValueError if nothing up to 20 m fits. Every obstacle cell
    lies inside a polygon (they are grown by up to 1 m more where filling shaved an outline)."""
    from shapely import Polygon, box, unary_union
    from shapely.geometry.base import BaseGeometry

    if not 0 < resolution < math.inf or not 0 <= tolerance < math.inf:
        raise ValueError("resolution must be > 0 and tolerance >= 0 (m)")
    occ = np.asarray(occ, dtype=bool)
    boxes = []
    for r in range(occ.shape[0]):
        row = np.concatenate(([False], occ[r], [False]))
        edges = np.flatnonzero(row[1:] != row[:-1])
        for c0, c1 in zip(edges[::2], edges[1::2], strict=True):
            boxes.append(box(c0 * resolution, r * resolution, c1 * resolution, (r + 1) * resolution))
    if not boxes:
        return []

    def parts(g: BaseGeometry) -> list[Polygon]:
        return [g] if isinstance(g, Polygon) else [p for p in getattr(g, "geoms", []) if isinstance(p, Polygon)]

    def merged(polys: list[Polygon]) -> list[Polygon]:
        return [Polygon(p.exterior).simplify(1e-3) for p in parts(unary_union(polys))]

    outlines = []
    for p in parts(unary_union(boxes)):
        filled = Polygon(p.exterior).simplify(0.0)    # the cells' outline less its collinear vertices
        if tolerance > 0:
            filled = filled.simplify(tolerance, preserve_topology=True).buffer(tolerance, join_style="mitre",
                                                                                mitre_limit=2.0)
        outlines.extend(parts(filled))
    base = merged(outlines)
    for close in range(21):
        polys = base if close == 0 else merged([
            Polygon(q.exterior) for p in base
            for q in parts(p.buffer(close, join_style="mitre", mitre_limit=2.0).buffer(-close, join_style="mitre",
                                                                                      mitre_limit=2.0))])
        if sum(len(p.exterior.coords) - 1 for p in polys) <= max_vertices:
            break
    else:
        raise ValueError(f"the chart needs more than {max_vertices} fence vertices")
    # Filling notches with mitred corners can shave a sliver off a rounded outline (a few cm on the
    # harbour's rock): grow the polygons until every obstacle cell is inside.
    cells = unary_union(boxes)
    for grow in (0.0, 0.1, 0.25, 0.5, 1.0):
        grown = polys if grow == 0 else merged([p.buffer(grow, join_style="mitre", mitre_limit=2.0) for p in polys])
        if unary_union(grown).buffer(1e-6).covers(cells):
            polys = grown
            break
    else:
        raise ValueError("the fence polygons do not cover the chart")
    out = []
    for p in sorted(polys, key=lambda q: -q.area):
        ring = np.asarray(p.exterior.coords, dtype=float)[:-1]
        if len(ring) < 3:
            continue
        x, y = ring[:, 0], ring[:, 1]
        if float(np.dot(x, np.roll(y, -1)) - np.dot(np.roll(x, -1), y)) < 0:   # clockwise: reverse
            ring = ring[::-1]
        out.append(ring)
    return out


def dijkstra_points(polygons: list[np.ndarray]) -> int:
    """The safe points ArduRover's Dijkstra makes round these exclusion polygons: one per convex vertex."""
    n = 0
    for ring in polygons:
        prev, nxt = np.roll(ring, 1, axis=0) - ring, np.roll(ring, -1, axis=0) - ring
        cross = nxt[:, 0] * prev[:, 1] - nxt[:, 1] * prev[:, 0]   # > 0: convex on a counter-clockwise ring
        n += int(np.sum(cross > 0))
    return n


def fence_items(polygons: list[np.ndarray], geo: LocalFrame) -> list[FenceItem]:
    """The fence mission: every polygon's vertices in order, as (lat, lon) from map x east, y north
    (``geo``: north, east m at sea level -> lat, lon deg)."""
    items: list[FenceItem] = []
    for ring in polygons:
        for x, y in ring:
            lat, lon = geo.sea_level_to_geodetic(float(y), float(x))
            items.append(FenceItem(len(items), len(ring), lat, lon))
    return items


def oa_params(margin: float, fence_margin: float) -> dict[str, float]:
    """The parameters a Rover user sets to plan round the fence (ArduPilot's "Object Avoidance with
    Dijkstra's" page): the polygon fence on (FENCE_ENABLE 1, FENCE_TYPE 4: polygons only, no circle
    about home), Dijkstra (OA_TYPE 2) keeping ``margin`` m from the fence (OA_MARGIN_MAX), and the
    fence's own margin ``fence_margin`` m (FENCE_MARGIN): ArduRover's simple avoidance stops the boat
    that close to the fence. Its default, 2 m, held the boat short of the harbour's second
    waypoint (1.5 m from the fence) for 257 s (docs/ardupilot.md)."""
    return {"FENCE_ENABLE": 1.0, "FENCE_TYPE": 4.0, "FENCE_MARGIN": float(fence_margin), "OA_TYPE": 2.0,
            "OA_MARGIN_MAX": float(margin)}
