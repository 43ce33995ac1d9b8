"""The geofence and the rally points a ground station uploads, and what a breach does (ArduRover's
FENCE_ENABLE and FENCE_ACTION).

The fence is geometry (:class:`planner.fence.Fence`, map frame); it enters planning as obstacles on the
vessel computer's grid and the planner worker's (the same safety margin as the chart). A breach - the
boat outside an inclusion zone or inside an exclusion zone - triggers FENCE_ACTION once: 1 RTL (to the
nearest rally point inside the fence, else home), 2 hold station where the boat is, 0 report only.
While breached the fence is left off the planning grids, so that the way back can be planned from
outside the fence to inside it (ArduPilot issue 31399: RTL from outside the fence fails there); it
returns once the boat is inside again by ``CLEARED_MARGIN``.
"""

from __future__ import annotations

import math

from autopilot_bridge.parameters import Tunable
from planner.fence import Fence

FENCE_REPORT, FENCE_RTL, FENCE_HOLD = 0, 1, 2
CLEARED_MARGIN = 2.0     # m inside the fence before a breach counts as over


class GeoFence:
    enable = Tunable("FENCE_ENABLE", 0, 1, "", "geofence: 0 off, 1 on (planning keeps out, a breach acts)",
                     integer=True)
    action = Tunable("FENCE_ACTION", 0, 2, "",
                     "on a fence breach: 0 report only, 1 RTL to the nearest rally point inside the fence "
                     "(else home), 2 hold station", integer=True)

    def __init__(self) -> None:
        self.fence = Fence()
        self.enable = 1
        self.action = FENCE_RTL
        self.breached = False
        self.breaches = 0
        self.rally: tuple[tuple[float, float], ...] = ()   # NED m

    @property
    def active(self) -> Fence:
        """The fence in force (an empty one when disabled)."""
        return self.fence if self.enable else Fence()

    def for_planning(self) -> Fence:
        """The fence the planners keep out of: none while breached (the way back crosses it)."""
        return Fence() if self.breached else self.active

    def allows(self, north: float, east: float) -> bool:
        return self.active.contains(east, north)

    def depth(self, north: float, east: float) -> float:
        """m inside the fence (negative: outside); inf without one."""
        f = self.active
        return math.inf if f.empty else f.distance_inside(east, north)

    def check(self, north: float, east: float) -> str | None:
        """"breach" or "cleared" when the boat at (north, east) NED m crosses the fence; else None."""
        if self.active.empty:
            if self.breached:
                self.breached = False
                return "cleared"
            return None
        d = self.depth(north, east)
        if not self.breached and d < 0.0:
            self.breached = True
            self.breaches += 1
            return "breach"
        if self.breached and d >= CLEARED_MARGIN:
            self.breached = False
            return "cleared"
        return None

    def rally_point(self, position: tuple[float, float]) -> tuple[float, float] | None:
        """The rally point nearest ``position`` that the fence allows, or None."""
        ok = [p for p in self.rally if self.allows(*p)]
        return min(ok, key=lambda p: math.dist(p, position)) if ok else None
