"""The vessel computer's own failsafes: the planner that keeps failing, navigation that degrades.

Both end in station keeping (LOITER, against the current), never in a drifting HOLD (issue 33):

* **planner failure**: the reactive avoidance behaviour (FALLBACK) steers while planning fails; after
  ``PLANNER_FAIL_S`` (30 s of vehicle time) without a valid local path, in AUTO, GUIDED or RTL, the boat
  holds station where it is and says why, instead of wandering on reactively;
* **degraded navigation**: when the navigation estimate's position uncertainty passes
  ``POSITION_STD_LIMIT`` (10 m: GPS lost, dead reckoning for a minute or more), in a mode that sails, the
  boat holds station on its dead-reckoned estimate (the DVL's bottom track keeps that drift small) -
  ArduRover's EKF failsafe (FS_EKF_ACTION) likewise holds.

Each fires once per episode (a mode change by a ground station, or recovery, re-arms it).
"""

from __future__ import annotations

from collections.abc import Callable

from autopilot_bridge.behaviour import Behaviour
from autopilot_bridge.modes import Mode
from autopilot_bridge.navigation import NavState
from autopilot_bridge.vehicle import Vehicle

PLANNER_FAIL_S = 30.0       # s of vehicle time in FALLBACK before the boat holds station
POSITION_STD_LIMIT = 10.0   # m: navigation this uncertain is not fit to sail by
SAILING = (Mode.AUTO, Mode.GUIDED, Mode.RTL)


class OnboardFailsafes:
    def __init__(self, vehicle: Vehicle, event: Callable[[float, str, bool], None]) -> None:
        self.vehicle, self._event = vehicle, event
        self.fallback_since: float | None = None
        self.planner_fired = False
        self.nav_fired = False
        self.events = 0

    def check(self, s: NavState, behaviour: Behaviour) -> None:
        v = self.vehicle
        sailing = v.armed and v.mode in SAILING
        if behaviour is Behaviour.FALLBACK and sailing:
            if self.fallback_since is None:
                self.fallback_since = s.t
            elif not self.planner_fired and s.t - self.fallback_since >= PLANNER_FAIL_S:
                self.planner_fired = True
                self._hold(s, f"planner failsafe: no valid local path for {s.t - self.fallback_since:.0f} s")
        else:
            self.fallback_since = None
            self.planner_fired = False
        if s.position_std > POSITION_STD_LIMIT:
            if sailing and not self.nav_fired:
                self.nav_fired = True
                self._hold(s, f"navigation failsafe: position uncertain to {s.position_std:.0f} m")
        elif s.position_std < 0.5 * POSITION_STD_LIMIT:
            self.nav_fired = False

    def _hold(self, s: NavState, why: str) -> None:
        self.events += 1
        ok, _ = self.vehicle.set_mode(Mode.LOITER, (s.x, s.y))
        self._event(s.t, f"{why}: {'holding station (LOITER)' if ok else 'LOITER refused'}", True)
