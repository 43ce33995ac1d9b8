"""Reactive obstacle avoidance: the emergency behaviour when no valid local path exists.

Section 2.2: "If no available path exists, then the behaviour-based reactive obstacle avoidance
method will be used in an emergency." The behaviour here is a small vector-field-histogram: it
casts rays every ``step`` radians around the vessel over the obstacle map, measures the free
distance along each (up to ``max_range``, stopping ``min_clearance`` short of obstacles), and
picks the heading that best trades progress towards the target against free space and a
steady course. Its speed falls with the free distance ahead, to zero when boxed in.

Works in NED (x north, y east) on the planner's map (x east, y north) through the grid's
``is_free(x_map, y_map)``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from planner.gridmap import OccupancyGrid


@dataclass(frozen=True)
class AvoidanceCommand:
    heading: float      # rad, NED
    speed: float        # m/s
    free_ahead: float   # m, free distance along the chosen heading


class ReactiveAvoidance:
    """Heading and speed away from obstacles and towards a target (NED)."""

    def __init__(self, grid: OccupancyGrid, max_range: float, min_clearance: float, cruise_speed: float,
                 n_rays: int = 72, cone: float = math.radians(20.0)) -> None:
        self.grid = grid
        self.max_range = max_range
        self.min_clearance = min_clearance
        self.cruise_speed = cruise_speed
        self.angles = np.linspace(-math.pi, math.pi, n_rays, endpoint=False)
        self.sample = max(grid.resolution / 2.0, 0.1)
        # A heading is as free as the worst ray within +-cone of it: a course parallel to a wall
        # has a long free ray but no room beside it.
        self.cone_rays = int(round(cone / (2.0 * math.pi / n_rays)))

    def free_distances(self, north: float, east: float) -> np.ndarray:
        """Free distance (m) along every ray from (north, east), less the clearance (vectorised)."""
        occ, res = self.grid.occ, self.grid.resolution
        d = np.arange(1, int((self.max_range + self.min_clearance) / self.sample) + 1) * self.sample
        xs = east + np.sin(self.angles)[:, None] * d[None, :]    # map x = east
        ys = north + np.cos(self.angles)[:, None] * d[None, :]   # map y = north
        cols = np.floor(xs / res).astype(int)
        rows = np.floor(ys / res).astype(int)
        inside = (cols >= 0) & (rows >= 0) & (cols < occ.shape[1]) & (rows < occ.shape[0])
        blocked = ~inside  # outside the map counts as occupied
        blocked[inside] = occ[rows[inside], cols[inside]]
        first = np.where(blocked.any(axis=1), blocked.argmax(axis=1), len(d))
        free = np.where(first < len(d), first * self.sample - self.min_clearance, self.max_range)
        return np.clip(free, 0.0, self.max_range)

    def command(self, north: float, east: float, heading: float, target: tuple[float, float]) -> AvoidanceCommand:
        """Best heading and speed now, towards ``target`` (north, east)."""
        to_target = math.atan2(target[1] - east, target[0] - north)
        free = self.free_distances(north, east)
        free = np.min([np.roll(free, k) for k in range(-self.cone_rays, self.cone_rays + 1)], axis=0)
        progress = np.cos(self.angles - to_target)
        steady = np.cos(self.angles - heading)
        score = progress + 1.5 * (free / self.max_range) + 0.3 * steady - 10.0 * (free < 1.0)
        i = int(np.argmax(score))
        speed = self.cruise_speed * min(1.0, float(free[i]) / self.max_range)
        return AvoidanceCommand(heading=float(self.angles[i]), speed=speed, free_ahead=float(free[i]))
