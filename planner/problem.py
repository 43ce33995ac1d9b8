"""One planning query: map, start, goal and optional heading, current and reference path."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from planner.field import DisturbanceField
from planner.gridmap import OccupancyGrid


@dataclass(frozen=True)
class PlanningProblem:
    """A query in the map frame (x east, y north, metres; angles counter-clockwise from +x)."""

    grid: OccupancyGrid                 # already inflated as the caller wants
    start: tuple[float, float]
    goal: tuple[float, float]
    start_heading: float | None = None  # rad; enables the fan-shaped kinematic limit at the root
    field: DisturbanceField | None = None
    reference_path: np.ndarray | None = None   # (M, 2) global reference path (PNG, subgoals)
    bounds: tuple[float, float, float, float] | None = None   # xmin, xmax, ymin, ymax sampling box
    domain_center: tuple[float, float] | None = None          # perceptual domain centre
    domain_radius: float | None = None                        # perceptual domain radius (m)
    # the vessel's steady drift under the wave moment (m/s, map frame), added to the current where
    # alpha_y is measured against their resultant (PlannerParams.alpha_y = "resultant")
    wave_drift: tuple[float, float] | None = None
    # a tree to start from (section 3.5, line 3): (nodes (m, 2), parents (m,)), nodes[0] at the
    # start, each parent index smaller than its node's (-1 for the root); the search keeps the
    # nodes that are still valid on this query's map and domain (planner._tree.seed_tree)
    initial_tree: tuple[np.ndarray, np.ndarray] | None = None

    def sampling_box(self) -> tuple[float, float, float, float]:
        """The sampling box clipped to the map (and to the perceptual domain's bounding box)."""
        xmin, xmax, ymin, ymax = 0.0, self.grid.width, 0.0, self.grid.height
        if self.bounds is not None:
            bx0, bx1, by0, by1 = self.bounds
            xmin, xmax, ymin, ymax = max(xmin, bx0), min(xmax, bx1), max(ymin, by0), min(ymax, by1)
        if self.domain_center is not None and self.domain_radius is not None:
            cx, cy = self.domain_center
            r = self.domain_radius
            xmin, xmax = max(xmin, cx - r), min(xmax, cx + r)
            ymin, ymax = max(ymin, cy - r), min(ymax, cy + r)
        return xmin, xmax, ymin, ymax
