"""Path-following statistics of a run: cross-track and heading errors while following a local path.

Reported in the autopilot's summary (``tracking``), so that a collision can be told apart as a
tracking problem (large cross-track error) or a planning one (the path itself too close).
"""

from __future__ import annotations

import math
from typing import NotRequired, TypedDict

import numpy as np

from autopilot_bridge.angles import wrap_angle


class TrackingSummary(TypedDict):
    """The ``tracking`` section of the summaries: errors over the frames that followed a local path
    (none but ``frames`` when there were none); m and rad."""

    frames: int
    cross_track_rms_m: NotRequired[float]
    cross_track_p95_m: NotRequired[float]
    cross_track_max_m: NotRequired[float]
    heading_error_rms_rad: NotRequired[float]
    heading_error_p95_rad: NotRequired[float]


class TrackingStats:
    """Collects |cross-track error| (m) and |heading error| (rad, desired minus estimated) per frame."""

    def __init__(self) -> None:
        self.cross_track: list[float] = []
        self.heading_error: list[float] = []

    def add(self, cross_track: float, heading_ref: float, heading: float) -> None:
        self.cross_track.append(abs(cross_track))
        self.heading_error.append(abs(wrap_angle(heading_ref - heading)))

    def summary(self) -> TrackingSummary:
        if not self.cross_track:
            return {"frames": 0}
        x, h = np.array(self.cross_track), np.array(self.heading_error)
        return {"frames": len(x),
                "cross_track_rms_m": round(math.sqrt(float(np.mean(x * x))), 4),
                "cross_track_p95_m": round(float(np.percentile(x, 95)), 4),
                "cross_track_max_m": round(float(x.max()), 4),
                "heading_error_rms_rad": round(math.sqrt(float(np.mean(h * h))), 4),
                "heading_error_p95_rad": round(float(np.percentile(h, 95)), 4)}
