"""The current as a process met it over a run: the truth the simulator applied to the hull, the
planner's field and the vessel computer's own estimate, each tallied where the boat was.

One small accumulator shared by the simulator and the vessel computer, so that a run's summary can set
the three side by side (``hil run``: ``current``) and a user can see that the current they gave was
the one the boat felt and the planner planned with.
"""

from __future__ import annotations

import math
from typing import TypedDict

from common.current_params import CurrentParams


class CurrentStats(TypedDict):
    """A current sampled along the boat's way (m/s, NED; the mean of the vectors and of their speeds)."""

    samples: int
    mean_north_m_s: float
    mean_east_m_s: float
    mean_speed_m_s: float
    max_speed_m_s: float


class CurrentTally:
    """Running sums of current samples (north, east) in m/s."""

    __slots__ = ("n", "north", "east", "speed", "max_speed")

    def __init__(self) -> None:
        self.n = 0
        self.north = self.east = self.speed = self.max_speed = 0.0

    def add(self, north: float, east: float) -> None:
        """One sample, m/s. A non-finite sample (a probe outside the field) is not counted."""
        s = math.hypot(north, east)
        if not math.isfinite(s):
            return
        self.n += 1
        self.north += north
        self.east += east
        self.speed += s
        if s > self.max_speed:
            self.max_speed = s

    def stats(self) -> CurrentStats | None:
        """The samples' means and largest speed (None before any sample)."""
        n = self.n
        if n == 0:
            return None
        return CurrentStats(samples=n, mean_north_m_s=round(self.north / n, 4), mean_east_m_s=round(self.east / n, 4),
                            mean_speed_m_s=round(self.speed / n, 4), max_speed_m_s=round(self.max_speed, 4))


def describe(p: CurrentParams) -> str:
    """Which source ``[current]`` selects, in a few words (a file by its name)."""
    if not p.enabled:
        return "none"
    if p.file:
        return f"file {p.file}"
    if p.uniform:
        return f"uniform [{p.uniform[0]:g}, {p.uniform[1]:g}] m/s east, north"
    return "eq. (13)"
