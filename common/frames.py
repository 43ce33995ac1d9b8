"""The two frames of the project and the one place that converts between them.

* **NED** (the simulator, the vessel computer, MAVLink): x north, y east (m); headings clockwise
  from north (rad).
* **Map** (charts, scenarios, the planner): x east, y north (m), the chart's south-west corner at
  the NED origin; headings counter-clockwise from east (rad).

A point swaps its coordinates; a heading psi (NED) is pi/2 - psi on the map, and back.
"""

from __future__ import annotations

import math

import numpy as np


def ned_to_map(north: float, east: float, psi: float | None = None) -> tuple[float, ...]:
    """NED position (and heading clockwise from north) to map x, y (and heading from east)."""
    if psi is None:
        return east, north
    return east, north, math.pi / 2.0 - psi


def map_to_ned(x: float, y: float, heading: float | None = None) -> tuple[float, ...]:
    """Map position x east, y north (and heading from east) to NED north, east (and heading from north)."""
    if heading is None:
        return y, x
    return y, x, math.pi / 2.0 - heading


def map_to_ned_path(path: np.ndarray) -> np.ndarray:
    """(N, 2) map points (x east, y north) to NED (north, east)."""
    path = np.asarray(path, dtype=float).reshape(-1, 2)
    return path[:, ::-1].copy()
