"""Keeping off: an armed boat at rest inside the safety radius is taken to clear water, whatever its mode.

The modes keep station where they are asked to (LOITER where it was entered, RTL at home, GUIDED at its
target, HOLD at the last point that was clear) and each mode change starts the station keeper afresh: it
turns into the current first, and in a current setting onto a breakwater a boat held 1.5 m off it was set
onto it while a ground station changed modes every 1-2 s (the chaos hour, seed 31, at f5d6fd1: unsigned at
983.7 s, signed at 1,739.9 s). So, ahead of the mode:

* inside the planner's safety radius of an obstacle (charted or sensed), or where the current would set it
  inside before it could turn to stem the current (:func:`drift_exposure`), and not under way (surge below
  ``UNDER_WAY``: a boat making its way along a planned path is governed by the avoidance limits), the boat
  keeps station at the nearest point within ``REACH`` that is ``MARGIN`` beyond the safety radius (else the
  clearest there), into the current, for at least ``HOLD_S``, until it is that clear or has arrived;
* a mode change does not end it (only disarming, or a pilot's stick in MANUAL);
* once released it takes over again only when the boat is back inside the safety radius and ``RENEW``
  nearer than where it was released, so a boat with no clear water in reach is not held for ever.

A boat broadside to a 0.5 m/s current turns to stem it in about 3.5 s (``TURN_RATE``) and is set 1.7 m on
meanwhile, however it uses its thrust; waiting until it is inside the radius left it 0.75 m to go (the
in-process chaos search beside the breakwater's end at 2,281 s of the harbour's jet, seeds 12-387 at 12c4b6c:
5 collisions in 376 two-minute runs, each a turn from broadside 1.8-2 m off; 2 in the same 376 with this
rule, 9ef0244).

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
TURN_RATE = 0.4       # rad/s: a turn on the spot at Helm.turn_on_the_spot's moment (in-process: 25 deg/s measured)
SETTLE_S = 0.5        # s for the thrust to take up the current once the hull is along it
STILL = 0.05          # m/s: a current below this sets nothing worth a turn


def drift_exposure(psi: float, current: tuple[float, float]) -> float:
    """Seconds a boat heading ``psi`` (rad) is set by ``current`` (NED m/s) before it can stem it: the turn of
    its nearer end into the current at ``TURN_RATE``, then ``SETTLE_S``; 0 in still water. Turning, a
    differential boat's thrust acts along its hull, so the set across it cannot be stopped sooner."""
    cn, ce = current
    if math.hypot(cn, ce) < STILL:
        return 0.0
    a = abs(math.remainder(psi - math.atan2(ce, cn), 2.0 * math.pi))
    return min(a, math.pi - a) / TURN_RATE + SETTLE_S


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

    def _set_clearance(self, s: NavState, current: tuple[float, float]) -> float:
        """m: the least clearance on the way the current sets the boat before it can stem it (its clearance
        now in still water or when the hull is along the current)."""
        c = self.grid.clearance_at(s.y, s.x)
        t = drift_exposure(s.psi, current)
        for k in (1, 2, 3):
            f = t * k / 3.0
            c = min(c, self.grid.clearance_at(s.y + f * current[1], s.x + f * current[0]))
        return c

    def command(self, s: NavState, dt: float) -> Thrust | None:
        current = self._current()
        c = self.grid.clearance_at(s.y, s.x)
        if self.point is None:
            set_c = self._set_clearance(s, current)
            if set_c >= self.safety_radius:
                self._released = None
                return None
            if s.u >= UNDER_WAY or (self._released is not None and set_c > self._released - RENEW):
                return None
            self.point, self._since = clear_point(self.grid, (s.x, s.y), self.safety_radius + MARGIN, REACH), s.t
            self.episodes += 1
            self.station.reset()
            self._behaviour.to(Behaviour.IDLE)
            self._on_take(s)
            if s.t - self._told >= TELL_S:
                self._told = s.t
                why = (f"{c:.1f} m from an obstacle, inside the {self.safety_radius:.1f} m safety radius"
                       if c < self.safety_radius else
                       f"the current ({math.hypot(*current):.1f} m/s) would set it within the {self.safety_radius:.1f}"
                       f" m safety radius before it turned to stem it")
                self._event(s.t, f"{why}: keeping station {math.dist(self.point, (s.x, s.y)):.1f} m off, "
                                 f"in clear water")
        elif s.t - self._since >= HOLD_S:
            set_c = self._set_clearance(s, current)
            if ((c >= self.safety_radius + 0.5 * MARGIN and set_c >= self.safety_radius)
                    or math.dist(self.point, (s.x, s.y)) <= ARRIVED):
                self.point, self._released = None, (set_c if set_c < self.safety_radius else None)
                self._on_take(s)
                return None
        return self.station.command(s, dt, self.point, True, self._behaviour, self._drive, current,
                                    lambda: self._on_take(s), rest=False)
