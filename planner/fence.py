"""Geofences as planning geometry: inclusion and exclusion polygons and circles (map frame, metres).

A fence enters planning as obstacles on the occupancy grid (:meth:`Fence.forbidden`): the cells outside
any inclusion zone or inside any exclusion zone are marked occupied, and the planners' inflation by
their safety radius then keeps the same margin from a fence as from the chart. As ArduPilot's
AC_PolyFence treats them, every inclusion zone must hold (the boat stays inside all of them) and no
exclusion zone may be entered. Points are (x east, y north) in metres, as everywhere in ``planner``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class Circle:
    x: float
    y: float
    radius: float    # m


def _as_polygon(p: np.ndarray | list[tuple[float, float]]) -> np.ndarray:
    a = np.asarray(p, dtype=float).reshape(-1, 2)
    if len(a) < 3:
        raise ValueError("a fence polygon needs at least 3 vertices")
    if not np.all(np.isfinite(a)):
        raise ValueError("a fence polygon's vertices must be finite")
    return a


def points_in_polygon(px: np.ndarray, py: np.ndarray, poly: np.ndarray) -> np.ndarray:
    """Even-odd rule for many points at once (arrays of any shape), a boolean array of that shape."""
    inside = np.zeros(np.shape(px), dtype=bool)
    xs, ys = poly[:, 0], poly[:, 1]
    n = len(poly)
    for i in range(n):
        x0, y0, x1, y1 = xs[i], ys[i], xs[(i + 1) % n], ys[(i + 1) % n]
        if y0 == y1:
            continue
        crosses = (py >= min(y0, y1)) & (py < max(y0, y1))
        x_at = x0 + (py - y0) * (x1 - x0) / (y1 - y0)
        inside ^= crosses & (px < x_at)
    return inside


@dataclass(frozen=True, eq=False)
class Fence:
    """``version``: the uploader's number for this fence (compared instead of the arrays)."""

    inclusion_polygons: tuple[np.ndarray, ...] = ()
    exclusion_polygons: tuple[np.ndarray, ...] = ()
    inclusion_circles: tuple[Circle, ...] = ()
    exclusion_circles: tuple[Circle, ...] = ()
    version: int = 0

    def __post_init__(self) -> None:
        object.__setattr__(self, "inclusion_polygons", tuple(_as_polygon(p) for p in self.inclusion_polygons))
        object.__setattr__(self, "exclusion_polygons", tuple(_as_polygon(p) for p in self.exclusion_polygons))
        for c in (*self.inclusion_circles, *self.exclusion_circles):
            if not (math.isfinite(c.x) and math.isfinite(c.y) and math.isfinite(c.radius) and c.radius > 0):
                raise ValueError("a fence circle needs a finite centre and a radius > 0")

    @property
    def empty(self) -> bool:
        return not (self.inclusion_polygons or self.exclusion_polygons or self.inclusion_circles
                    or self.exclusion_circles)

    def allowed(self, x: np.ndarray | float, y: np.ndarray | float) -> np.ndarray:
        """Whether each point lies inside every inclusion zone and outside every exclusion zone."""
        px, py = np.asarray(x, dtype=float), np.asarray(y, dtype=float)
        ok = np.ones(np.broadcast(px, py).shape, dtype=bool)
        for poly in self.inclusion_polygons:
            ok &= points_in_polygon(px, py, poly)
        for poly in self.exclusion_polygons:
            ok &= ~points_in_polygon(px, py, poly)
        for c in self.inclusion_circles:
            ok &= np.hypot(px - c.x, py - c.y) <= c.radius
        for c in self.exclusion_circles:
            ok &= np.hypot(px - c.x, py - c.y) > c.radius
        return ok

    def contains(self, x: float, y: float) -> bool:
        return bool(self.allowed(x, y))

    def forbidden(self, shape: tuple[int, int], resolution: float) -> np.ndarray:
        """The cells (rows: y, cols: x) whose centre the fence forbids, as a grid mask of ``shape``."""
        if self.empty:
            return np.zeros(shape, dtype=bool)
        rows, cols = shape
        ys = (np.arange(rows) + 0.5) * resolution
        xs = (np.arange(cols) + 0.5) * resolution
        X, Y = np.meshgrid(xs, ys)
        return ~self.allowed(X, Y)

    def distance_inside(self, x: float, y: float) -> float:
        """Distance (m) from (x, y) to the nearest fence boundary: positive inside the allowed region,
        negative outside (breached). ``inf`` for an empty fence."""
        best = math.inf
        inside = self.contains(x, y)
        for poly in (*self.inclusion_polygons, *self.exclusion_polygons):
            best = min(best, _distance_to_edges(x, y, poly))
        for c in (*self.inclusion_circles, *self.exclusion_circles):
            best = min(best, abs(math.hypot(x - c.x, y - c.y) - c.radius))
        return best if inside else -best


def _distance_to_edges(x: float, y: float, poly: np.ndarray) -> float:
    a = poly
    b = np.roll(poly, -1, axis=0)
    d = b - a
    L2 = np.maximum((d ** 2).sum(axis=1), 1e-12)
    t = np.clip(((x - a[:, 0]) * d[:, 0] + (y - a[:, 1]) * d[:, 1]) / L2, 0.0, 1.0)
    px, py = a[:, 0] + t * d[:, 0], a[:, 1] + t * d[:, 1]
    return float(np.min(np.hypot(px - x, py - y)))
