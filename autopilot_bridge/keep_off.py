"""Keeping off: an armed boat at rest inside the safety radius is taken to clear water, whatever its mode.

The modes keep station where they are asked to (LOITER where it was entered, RTL at home, GUIDED at its
target, HOLD at the last point that was clear) and each mode change starts the station keeper afresh: it
turns into the current first, and in a current setting onto a breakwater a boat held 1.5 m off it was set
onto it while a ground station changed modes every 1-2 s (the chaos hour, seed 31, at f5d6fd1: unsigned at
983.7 s, signed at 1,739.9 s). So, ahead of the mode:

* inside the planner's safety radius of an obstacle (charted or sensed) and not under way (surge below
  ``UNDER_WAY``: a boat making its way along a planned path is governed by the avoidance limits), the boat
  keeps station at the nearest point within ``REACH`` that is ``MARGIN`` beyond the safety radius (else the
  clearest there), into the current, for at least ``HOLD_S``, until it is that clear or has arrived;
* a mode change does not end it (only disarming, or a pilot's stick in MANUAL);
* once released it takes over again only when the boat is back inside the safety radius and ``RENEW``
  nearer than where it was released, so a boat with no clear water in reach is not held for ever.

Station points of the modes themselves are moved to clear water by :func:`clear_point` too (Helm).
Positions NED m, times s of vehicle time, speeds m/s.
"""

from __future__ import annotations

import math
from collections.abc import Callable

from autopilot_bridge.behaviour import Behaviour, BehaviourMachine
from autopilot_bridge.control import Thrust
from autopilot_bridge.navigation import NavState
from autopilot_bridge.station_keeping import Drive, StationKeeper
from planner.gridmap import OccupancyGrid

UNDER_WAY = 0.5       # m/s of surge: above it the boat's own way governs (the avoidance limits); min_turn_speed 0.6
MARGIN = 0.5          # m beyond the safety radius that a keep-off point has
REACH = 3.0           # m: how far from the boat that point may be
HOLD_S = 5.0          # s: kept off at least this long (no flicker at the radius)
ARRIVED = 0.75        # m from the point: arrived (with no clearer water in reach, released there)
RENEW = 0.25          # m nearer than the release clearance before it takes over again
BEARINGS = 16         # directions searched for a clear point
TELL_S = 10.0         # s between two events


def clear_point(grid: OccupancyGrid, point: tuple[float, float], need: float, reach: float) -> tuple[float, float]:
    """The nearest point (NED m) within ``reach`` of ``point`` with at least ``need`` m of clearance from every
    obstacle (rings one grid cell apart, ``BEARINGS`` directions), else the clearest one there; ``point`` itself
    when it is that clear."""
    best, best_clearance = point, grid.clearance_at(point[1], point[0])
    if best_clearance >= need:
        return best
    for k in range(1, int(reach / grid.resolution) + 1):
        d = k * grid.resolution
        for j in range(BEARINGS):
            a = 2.0 * math.pi * j / BEARINGS
            n, e = point[0] + d * math.cos(a), point[1] + d * math.sin(a)
            c = grid.clearance_at(e, n)
            if c > best_clearance:
                best, best_clearance = (n, e), c
        if best_clearance >= need:
            break
    return best


class KeepOff:
    """The guard ahead of the modes (module docstring). ``command`` answers None when the mode has the helm."""

    def __init__(self, grid: OccupancyGrid, safety_radius: float, station: StationKeeper, drive: Drive,
                 current: Callable[[], tuple[float, float]], on_take: Callable[[NavState], None],
                 event: Callable[[float, str], None]) -> None:
        self.grid, self.safety_radius, self.station = grid, safety_radius, station
        self._drive, self._current, self._on_take, self._event = drive, current, on_take, event
        self.point: tuple[float, float] | None = None       # NED m: where the boat is kept, None: not kept
        self.episodes = 0
        self._since = self._told = -math.inf
        self._released: float | None = None     # m: clearance where it was last released inside the radius
        self._behaviour = BehaviourMachine(start=Behaviour.IDLE)

    def reset(self) -> None:
        """Disarmed, or a pilot at the stick: the guard lets go."""
        self.point = self._released = None

    def command(self, s: NavState, dt: float) -> Thrust | None:
        c = self.grid.clearance_at(s.y, s.x)
        if self.point is None:
            if c >= self.safety_radius:
                self._released = None
                return None
            if s.u >= UNDER_WAY or (self._released is not None and c > self._released - RENEW):
                return None
            self.point, self._since = clear_point(self.grid, (s.x, s.y), self.safety_radius + MARGIN, REACH), s.t
            self.episodes += 1
            self.station.reset()
            self._behaviour.to(Behaviour.IDLE)
            self._on_take(s)
            if s.t - self._told >= TELL_S:
                self._told = s.t
                self._event(s.t, f"{c:.1f} m from an obstacle, inside the {self.safety_radius:.1f} m safety radius: "
                                 f"keeping station {math.dist(self.point, (s.x, s.y)):.1f} m off, in clear water")
        elif s.t - self._since >= HOLD_S and (c >= self.safety_radius + 0.5 * MARGIN or
                                              math.dist(self.point, (s.x, s.y)) <= ARRIVED):
            self.point, self._released = None, (c if c < self.safety_radius else None)
            self._on_take(s)
            return None
        return self.station.command(s, dt, self.point, True, self._behaviour, self._drive, self._current(),
                                    lambda: self._on_take(s), rest=False)
