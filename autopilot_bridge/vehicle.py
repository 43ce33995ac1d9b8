"""What a ground station commands: arming, the mode, the mission and its progress, home, the route.

Modes use ArduPilot Rover's ``custom_mode`` numbers so that boat ground stations (QGroundControl,
MAVProxy, Mission Planner) show their names:

* MANUAL (0): thrusters from MANUAL_CONTROL (x: surge, r: yaw, each -1000..1000); zero without input.
* HOLD (4): both thrusters at zero, the boat drifts with wind and current (as ArduPilot Rover's
  HOLD does for boats; no station keeping).
* AUTO (10): follow the mission from the current item: the online planner (section 2.2 of the paper)
  plans local paths along the global reference path [position where AUTO began, items...].
* RTL (11): reference path [position, home]; holds (zero thrust) once home.
* GUIDED (15): go to the target of the last MAV_CMD_DO_REPOSITION; holds without one.

Disarmed means zero thrust whatever the mode. The mission's current item advances when the boat is
within the item's acceptance radius or has passed the line through the item perpendicular to the
leg into it (the final item must be reached within its radius). All positions NED metres.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from enum import IntEnum

import numpy as np


class Mode(IntEnum):
    MANUAL = 0
    HOLD = 4
    AUTO = 10
    RTL = 11
    GUIDED = 15


@dataclass(frozen=True)
class Waypoint:
    north: float         # m
    east: float          # m
    radius: float        # m, acceptance radius


@dataclass(frozen=True)
class Route:
    """The global reference path the planner follows now, NED; ``version`` 0 is the scenario's own."""

    version: int
    path: np.ndarray     # (N, 2) north, east
    goal_radius: float   # m


class Vehicle:
    """Armed state, mode, mission progress and the active route (no I/O)."""

    def __init__(self, mission: list[Waypoint], *, armed: bool, mode: Mode, scenario_route: np.ndarray | None = None,
                 default_radius: float = 3.0) -> None:
        self.armed, self.mode = armed, mode
        self.mission: list[Waypoint] = list(mission)
        self.current = 0
        self.default_radius = default_radius
        self.home: tuple[float, float] | None = None
        self.guided_target: tuple[float, float] | None = None
        self.route: Route | None = None
        self._versions = 0
        self.reached: list[int] = []          # items reached since last taken (MISSION_ITEM_REACHED)
        self._last_reported = -1              # the item reported last (each is reported once)
        self.complete = False                 # the active route's end reached
        self.manual: tuple[float, float, float] | None = None  # (x, r, wall time) of MANUAL_CONTROL
        if scenario_route is not None and mode == Mode.AUTO:
            # The scenario's reference path as given (version 0): runs without a GCS stay as they were.
            self.route = Route(0, np.asarray(scenario_route, dtype=float), self._final_radius())
        self.changed = False                  # mode/arming changed since last looked (telemetry)

    def _final_radius(self) -> float:
        return self.mission[-1].radius if self.mission else self.default_radius

    def _new_route(self, path: list[tuple[float, float]], goal_radius: float) -> None:
        self._versions += 1
        self.route = Route(self._versions, np.asarray(path, dtype=float).reshape(-1, 2), goal_radius)
        self.complete = False

    # -- commands -------------------------------------------------------------------------------
    def arm(self, on: bool) -> tuple[bool, str]:
        if on == self.armed:
            return True, "already " + ("armed" if on else "disarmed")
        self.armed = on
        self.changed = True
        return True, "armed" if on else "disarmed"

    def set_mode(self, mode: Mode, position: tuple[float, float] | None) -> tuple[bool, str]:
        """Switch mode; AUTO/RTL need a navigation fix (``position``), RTL a home too."""
        if mode in (Mode.AUTO, Mode.RTL, Mode.GUIDED) and position is None:
            return False, f"{mode.name}: no position yet"
        if mode == Mode.RTL and self.home is None:
            return False, "RTL: no home position"
        if mode == Mode.AUTO and not self.mission:
            return False, "AUTO: no mission"
        self.mode = mode
        self.changed = True
        self.complete = False
        if mode == Mode.AUTO:
            self._route_from(position)
        elif mode == Mode.RTL:
            self._new_route([position, self.home], self.default_radius)
        elif mode == Mode.GUIDED:
            self.route = None
            if self.guided_target is not None:
                self._new_route([position, self.guided_target], self.default_radius)
        else:
            self.route = None
        return True, mode.name

    def _route_from(self, position: tuple[float, float]) -> None:
        rest = self.mission[self.current:] or self.mission[-1:]
        self._new_route([position] + [(w.north, w.east) for w in rest], rest[-1].radius)

    def reposition(self, target: tuple[float, float], position: tuple[float, float] | None) -> tuple[bool, str]:
        if position is None:
            return False, "GUIDED: no position yet"
        self.guided_target = target
        return self.set_mode(Mode.GUIDED, position)

    def replace_mission(self, mission: list[Waypoint], position: tuple[float, float] | None) -> None:
        """A new mission, all at once: restart at its first item (re-route now if in AUTO)."""
        self.mission = list(mission)
        self.current = 0
        self.reached.clear()
        self._last_reported = -1
        if self.mode == Mode.AUTO:
            if self.mission and position is not None:
                self._route_from(position)
            else:
                self.route = None  # nothing to do: hold
        self.changed = True

    def set_current(self, seq: int, position: tuple[float, float] | None) -> bool:
        if not 0 <= seq < len(self.mission):
            return False
        self.current = seq
        self._last_reported = -1
        if self.mode == Mode.AUTO and position is not None:
            self._route_from(position)
        self.changed = True
        return True

    def mission_start(self, first: int, position: tuple[float, float] | None) -> tuple[bool, str]:
        if not self.mission:
            return False, "no mission"
        if not 0 <= first < len(self.mission):
            return False, f"no item {first}"
        self.current = first
        self._last_reported = -1
        self.mode = Mode.AUTO  # set_mode re-routes from the (new) current item
        return self.set_mode(Mode.AUTO, position)

    # -- per frame ------------------------------------------------------------------------------
    def wants_thrust(self) -> bool:
        """True when the planner and the controllers drive the thrusters."""
        return self.armed and self.route is not None and self.mode in (Mode.AUTO, Mode.RTL, Mode.GUIDED)

    def update(self, north: float, east: float) -> None:
        """Advance the mission's current item from the position (AUTO only), note the route's end."""
        if self.home is None:
            self.home = (north, east)
        if self.route is not None and not self.complete:
            end = self.route.path[-1]
            if math.hypot(end[0] - north, end[1] - east) <= self.route.goal_radius:
                self.complete = True
        if self.mode != Mode.AUTO or not self.mission or self.current >= len(self.mission) or not self.armed:
            return
        while self.current < len(self.mission):
            w = self.mission[self.current]
            final = self.current == len(self.mission) - 1
            d = math.hypot(w.north - north, w.east - east)
            passed = False
            if not final and self.current > 0:
                prev = self.mission[self.current - 1]
                leg = (w.north - prev.north, w.east - prev.east)
                passed = (north - w.north) * leg[0] + (east - w.east) * leg[1] > 0.0
            if d <= w.radius or passed:
                self._report(self.current)
                if final:
                    self.complete = True
                    return
                self.current += 1
                self.changed = True
            else:
                return

    def finish(self) -> None:
        """The autopilot reached the final goal: every item not yet reported counts as reached."""
        while self.mission and self.current < len(self.mission):
            self._report(self.current)
            if self.current == len(self.mission) - 1:
                break
            self.current += 1
        self.complete = True

    def _report(self, seq: int) -> None:
        """Item ``seq`` reached: reported once (a boat keeping station at the final goal stays
        within its radius frame after frame)."""
        if seq != self._last_reported:
            self.reached.append(seq)
            self._last_reported = seq

    def take_reached(self) -> list[int]:
        r, self.reached = self.reached, []
        return r
