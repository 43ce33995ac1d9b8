"""Line-of-sight path following on a polyline (Fossen, Breivik and Skjetne 2003).

The local path (Dubins-smoothed, densely sampled) is a polyline in NED. For the vessel's position
the guidance finds the closest point ahead of the last progress, the cross-track error ``e``
(positive to starboard of the path) and commands

    psi_d = pi_p - atan(e / Delta)

where ``pi_p`` is the path-tangential angle and ``Delta`` the look-ahead distance. The progress
along the path only moves forward, so a path that folds back on itself is followed in order.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class GuidanceOutput:
    heading: float          # rad, desired heading (NED, clockwise from north)
    cross_track: float      # m, positive when the vessel is to starboard of the path
    remaining: float        # m, path length from the closest point to the end
    finished: bool          # within the acceptance radius of the end point
    curvature_ahead: float  # 1/m, the sharpest turn of the path within the preview distance
    curvature: float = 0.0  # 1/m, signed (> 0 turning to starboard) path curvature at the closest point


class LineOfSight:
    """LOS guidance along an NED polyline ``path`` of shape (N, 2) (north, east)."""

    def __init__(self, path: np.ndarray, lookahead: float, acceptance_radius: float) -> None:
        path = np.asarray(path, dtype=float)
        if path.ndim != 2 or path.shape[1] != 2 or len(path) < 2:
            raise ValueError("path must be an (N >= 2, 2) array of NED points")
        seg = np.diff(path, axis=0)
        keep = np.hypot(seg[:, 0], seg[:, 1]) > 1e-9
        self.path = np.vstack([path[:1], path[1:][keep]])
        if len(self.path) < 2:
            raise ValueError("path has no length")
        self.seg = np.diff(self.path, axis=0)
        self.seg_len = np.hypot(self.seg[:, 0], self.seg[:, 1])
        self.cum = np.concatenate([[0.0], np.cumsum(self.seg_len)])
        self.lookahead = lookahead
        self.acceptance_radius = acceptance_radius
        self.index = 0  # segment of the last progress
        # Discrete curvature at each interior vertex: turning angle over the mean adjacent length.
        ang = np.arctan2(self.seg[:, 1], self.seg[:, 0])
        turn = np.abs((np.diff(ang) + np.pi) % (2.0 * np.pi) - np.pi)
        self.vertex_curvature = turn / np.maximum(0.5 * (self.seg_len[:-1] + self.seg_len[1:]), 1e-6)
        signed = (np.diff(ang) + np.pi) % (2.0 * np.pi) - np.pi
        self.signed_curvature = signed / np.maximum(0.5 * (self.seg_len[:-1] + self.seg_len[1:]), 1e-6)

    @property
    def length(self) -> float:
        return float(self.cum[-1])

    def curvature_ahead(self, index: int, along: float, preview: float) -> float:
        """Largest vertex curvature (1/m) between ``along`` metres into segment ``index`` and ``preview`` m on."""
        start = self.cum[index] + along
        hi = int(np.searchsorted(self.cum, start + preview, side="right"))
        k = self.vertex_curvature[index:max(index, hi - 1)]  # vertex j sits at the end of segment j
        return float(k.max()) if len(k) else 0.0

    def curvature_at(self, index: int, along: float, span: float = 1.0) -> float:
        """Mean signed curvature (1/m, > 0 to starboard) of the vertices within ``span`` m either
        side of ``along`` metres into segment ``index``: the turn a yaw-rate feed-forward follows."""
        s = self.cum[index] + along
        lo = int(np.searchsorted(self.cum, s - span, side="left"))
        hi = int(np.searchsorted(self.cum, s + span, side="right"))
        k = self.signed_curvature[max(lo - 1, 0):max(hi - 1, 0)]  # vertex j sits at cum[j + 1]
        return float(k.sum()) / len(k) if len(k) else 0.0   # k.mean(), without its Python-level overhead

    def update(self, north: float, east: float, preview: float = 0.0) -> GuidanceOutput:
        """Desired heading for the vessel at (north, east); ``preview`` m of path are scanned for curvature."""
        p = np.array([north, east])
        # Search a window ahead of the last progress only, so the vessel never skips back.
        lo, hi = self.index, min(self.index + 50, len(self.seg))
        a, d, ln = self.path[lo:hi], self.seg[lo:hi], self.seg_len[lo:hi]
        # np.clip's Python wrapper costs more than the arithmetic on <= 50 segments: same result.
        s_all = np.minimum(np.maximum(np.einsum("ij,ij->i", p - a, d) / (ln * ln), 0.0), 1.0)
        gap = a + s_all[:, None] * d - p
        dist = np.einsum("ij,ij->i", gap, gap)
        k = int(np.argmin(dist))  # the first of equally close segments: progress is monotone
        i, s = lo + k, float(s_all[k])
        self.index = i
        d = self.seg[i]
        pi_p = math.atan2(d[1], d[0])
        a = self.path[i]
        # Cross-track error in the path frame: positive to starboard (right of the direction of travel).
        e = -(p[0] - a[0]) * math.sin(pi_p) + (p[1] - a[1]) * math.cos(pi_p)
        remaining = float(self.cum[-1] - (self.cum[i] + s * self.seg_len[i]))
        end_dist = float(np.hypot(*(self.path[-1] - p)))
        heading = pi_p - math.atan2(e, self.lookahead)
        if remaining < self.lookahead:
            # Near the end, aim at the end point itself.
            heading = math.atan2(self.path[-1][1] - east, self.path[-1][0] - north) if end_dist > 1e-6 else pi_p
        return GuidanceOutput(heading=heading, cross_track=e, remaining=remaining,
                              finished=end_dist <= self.acceptance_radius,
                              curvature_ahead=self.curvature_ahead(i, s * self.seg_len[i], preview),
                              curvature=self.curvature_at(i, s * self.seg_len[i]))
