"""A 2-D scanning range sensor on the true world map, binned as MAVLink OBSTACLE_DISTANCE.

The simulator owns the truth, including obstacles the vessel's chart does not show. Each scan
casts ``sectors x rays_per_sector`` rays from the true position, marches them through the true
occupancy grid and reports, per sector, the nearest return (plus noise) in centimetres, the way
PX4 and ArduPilot bin a scanning lidar into OBSTACLE_DISTANCE. Sector 0 is centred on the bow
and sectors advance clockwise (``MAV_FRAME_BODY_FRD``); a sector with no return within
``max_range`` reports ``max_distance + 1`` ("no obstacle", per the MAVLink spec).

World frame: the planner's map grid, row = north / resolution, column = east / resolution (the
map's south-west corner is the NED origin). Outside the map there is open water: no return.
"""

from __future__ import annotations

import numpy as np

from simulator.config import RangefinderParams
from simulator.raycast import first_returns, skip_map

NO_OBSTACLE_MARGIN_CM = 1   # MAVLink: max_distance + 1 = nothing within range


class WorldMap:
    """The true obstacle map the sensor sees: bool [rows, cols] (True = obstacle), metres per cell."""

    def __init__(self, occ: np.ndarray, resolution: float) -> None:
        self.occ = np.asarray(occ, dtype=bool)
        self.resolution = float(resolution)

    @classmethod
    def load(cls, path: str) -> WorldMap:
        """A ``.npz`` with ``occ`` (bool rows x cols) and ``resolution`` (m), as `hil run` writes."""
        with np.load(path) as z:
            return cls(z["occ"], float(z["resolution"]))


class Rangefinder:
    def __init__(self, params: RangefinderParams, world: WorldMap, rng: np.random.Generator) -> None:
        self.p, self.world, self.rng = params, world, rng
        self.increment_deg = 360.0 / params.sectors
        k = params.rays_per_sector
        # Ray bearings relative to the bow (rad, clockwise), sector-major, spread across each sector.
        offsets = (np.arange(k) + 0.5) / k - 0.5
        centres = np.arange(params.sectors) * self.increment_deg
        self.bearings = np.deg2rad((centres[:, None] + offsets[None, :] * self.increment_deg).ravel())
        step = world.resolution / 2.0
        self.ranges = np.arange(params.min_range, params.max_range + step, step)
        self.max_cm = int(round(params.max_range * 100))
        self.min_cm = int(round(params.min_range * 100))

        self._skips = skip_map(world.occ, world.resolution, step)
        self._first = np.empty(len(self.bearings))
        self.true_ranges(0.0, 0.0, 0.0)  # compiles (or loads) the ray march now, not in the first scan

    def true_ranges(self, north: float, east: float, psi: float) -> np.ndarray:
        """Nearest obstacle per sector (m), ``inf`` where none within range (no noise)."""
        ang = psi + self.bearings                                   # clockwise from north
        first_returns(north, east, np.cos(ang), np.sin(ang), self.ranges, self.world.occ,
                      self._skips, self.world.resolution, self._first)
        return self._first.reshape(self.p.sectors, self.p.rays_per_sector).min(axis=1)

    def true_ranges_numpy(self, north: float, east: float, psi: float) -> np.ndarray:
        """:meth:`true_ranges` as one numpy evaluation of every sample of every ray (the reference
        the compiled march is tested against)."""
        occ, res = self.world.occ, self.world.resolution
        ang = psi + self.bearings                                   # clockwise from north
        n = north + np.outer(np.cos(ang), self.ranges)
        e = east + np.outer(np.sin(ang), self.ranges)
        rows = np.floor(n / res).astype(np.int64)
        cols = np.floor(e / res).astype(np.int64)
        inside = (rows >= 0) & (rows < occ.shape[0]) & (cols >= 0) & (cols < occ.shape[1])
        hit = np.zeros(rows.shape, dtype=bool)
        hit[inside] = occ[rows[inside], cols[inside]]
        first = np.where(hit.any(axis=1), hit.argmax(axis=1), -1)
        d = np.where(first >= 0, self.ranges[np.maximum(first, 0)], np.inf)
        return d.reshape(self.p.sectors, self.p.rays_per_sector).min(axis=1)

    def scan(self, north: float, east: float, psi: float) -> list[int]:
        """One scan as OBSTACLE_DISTANCE ``distances`` (cm, 72 entries; unused sectors UINT16_MAX)."""
        d = self.true_ranges(north, east, psi)
        noisy = d + self.p.range_std * self.rng.standard_normal(d.shape)
        missed = self.rng.random(d.shape) < self.p.miss_probability
        # np.round halves to even, as round() does; a sector with no return is clipped, then replaced.
        cm = np.clip(np.round(np.where(np.isfinite(noisy), noisy, 0.0) * 100.0), self.min_cm, self.max_cm)
        out = np.where(missed | ~np.isfinite(d), self.max_cm + NO_OBSTACLE_MARGIN_CM, cm).astype(np.int64)
        return out.tolist() + [65535] * (72 - len(out))
