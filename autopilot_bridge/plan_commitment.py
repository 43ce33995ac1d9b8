"""Commitment to the local path being followed: do not flip to the other side of an obstacle.

Every planning cycle runs a fresh, differently seeded RRT* from where the vessel is, so two
consecutive local paths may pass the same obstacle on opposite sides when both ways cost about
the same. Following each new path at once then swings the vessel across the gap between them,
towards the obstacle in the middle, once a second - the lockstep labyrinth runs hit the first
island right after the start that way. A new path that passes some obstacle on the other side
than the current one (their *homotopy classes* differ over the stretch compared) replaces it only
when the current path is nearly used up or the new one is clearly shorter; a path that merely
varies the current one (same way round every obstacle) is taken at once.

Frames: NED (north, east) in metres; the occupancy grid is the planner's map frame (x east,
y north), rows along north.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from matplotlib.path import Path

from planner.cost import path_length


@dataclass(frozen=True)
class CommitmentParams:
    """How long the vessel stays with the way round it has chosen."""

    compare_length: float      # m of both paths compared from their starts
    min_remaining: float       # m: a current path with less left than this is always replaced
    shortcut_ratio: float      # a new path this much shorter (ratio of lengths) replaces it anyway


def truncate(path: np.ndarray, length: float) -> np.ndarray:
    """The first ``length`` metres of an (N, 2) polyline (the whole of a shorter one)."""
    path = np.asarray(path, dtype=float)
    seg = np.hypot(*np.diff(path, axis=0).T)
    cum = np.concatenate([[0.0], np.cumsum(seg)])
    if cum[-1] <= length:
        return path.copy()
    k = int(np.searchsorted(cum, length, side="right"))  # cum[k-1] <= length < cum[k]
    f = (length - cum[k - 1]) / max(seg[k - 1], 1e-12)
    return np.vstack([path[:k], path[k - 1] + f * (path[k] - path[k - 1])])


def obstacle_between(a: np.ndarray, b: np.ndarray, occ: np.ndarray, resolution: float) -> bool:
    """Whether an obstacle cell lies in the region enclosed by NED polylines ``a`` and ``b``
    (closed by joining their starts and their ends): if so they pass it on different sides."""
    ring = np.vstack([a, b[::-1]])
    lo = np.floor(ring.min(axis=0) / resolution).astype(int)
    hi = np.ceil(ring.max(axis=0) / resolution).astype(int)
    r0, r1 = max(lo[0], 0), min(hi[0] + 1, occ.shape[0])      # rows along north
    c0, c1 = max(lo[1], 0), min(hi[1] + 1, occ.shape[1])      # columns along east
    if r0 >= r1 or c0 >= c1:
        return False
    rows, cols = np.nonzero(occ[r0:r1, c0:c1])
    if len(rows) == 0:
        return False
    centres = np.column_stack([(rows + r0 + 0.5) * resolution, (cols + c0 + 0.5) * resolution])
    return bool(Path(ring).contains_points(centres).any())


def keep_current(current_ahead: np.ndarray, new: np.ndarray, occ: np.ndarray, resolution: float,
                 p: CommitmentParams) -> bool:
    """Whether to stay on ``current_ahead`` (the rest of the followed path, from the vessel's
    progress point) rather than switch to ``new`` (both NED polylines)."""
    left = path_length(current_ahead)
    if left < p.min_remaining:
        return False
    span = min(p.compare_length, left, path_length(new))
    if span <= 0.0 or not obstacle_between(truncate(current_ahead, span), truncate(new, span), occ, resolution):
        return False
    # The other way round: worth a swing across only if clearly shorter to where both lead.
    end_gap = math.hypot(*(np.asarray(current_ahead[-1]) - np.asarray(new[-1])))
    return path_length(new) >= p.shortcut_ratio * (left + end_gap)
