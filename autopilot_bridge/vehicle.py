"""What a ground station commands: arming, the mode, the mission and its progress, home, the route.

The modes are classes of their own (:mod:`autopilot_bridge.modes`, numbered as ArduPilot Rover's
``custom_mode``); the mission runs in :mod:`autopilot_bridge.mission_executor`. Disarmed means zero
thrust whatever the mode. All positions NED metres, times s of vehicle (simulated) time.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from autopilot_bridge.mission_commands import MissionCommand, waypoint
from autopilot_bridge.mission_executor import MissionExecutor
from autopilot_bridge.modes import MODES, Mode, RoverMode
from autopilot_bridge.parameters import Tunable

SPEED_RANGE = (0.2, 3.0)   # m/s: speed set-points a GCS or a mission may give (3 m/s: the hull's top speed)
MIS_DONE_HOLD, MIS_DONE_LOITER = 0, 1   # MIS_DONE_BEHAVE values (ArduRover's: 0 Hold, 1 Loiter)

__all__ = ["Mode", "Route", "Vehicle", "Waypoint"]


@dataclass(frozen=True)
class Waypoint:
    north: float         # m
    east: float          # m
    radius: float        # m, acceptance radius


@dataclass(frozen=True)
class Route:
    """The global reference path the planner follows now, NED; ``version`` 0 is the scenario's own.

    ``loiter``: at its end the boat keeps station whatever ``mission_done`` says (LOITER mode, loiter
    items, waypoint hold times)."""

    version: int
    path: np.ndarray     # (N, 2) north, east
    goal_radius: float   # m
    loiter: bool = False


def _command(w: Waypoint | MissionCommand) -> MissionCommand:
    return w if isinstance(w, MissionCommand) else waypoint(w.north, w.east, w.radius)


class Vehicle:
    """Armed state, the active mode, mission progress and the active route (no I/O).

    It owns the navigation parameters a Rover user knows by ArduRover's names (read live: the
    mission executor and the modes ask the vehicle, never keep a copy). ``home_item``: item 0 of the
    mission is home and is never executed (ArduPilot's convention, when the boat identifies as it)."""

    wp_speed = Tunable("WP_SPEED", *SPEED_RANGE, "m/s",
                       "speed over ground set-point in AUTO, GUIDED and LOITER's way back (ArduRover: WP_SPEED)")
    rtl_speed = Tunable("RTL_SPEED", 0.0, SPEED_RANGE[1], "m/s", "speed over ground in RTL; 0: WP_SPEED")
    wp_radius = Tunable("WP_RADIUS", 0.5, 50.0, "m",
                        "acceptance radius of waypoints that give none, and of RTL, GUIDED and loiter targets")
    mission_done = Tunable("MIS_DONE_BEHAVE", 0, 1, "",
                           "after the last mission item: 0 hold (thrusters off), 1 loiter (keep station)",
                           integer=True)
    arming_check = Tunable("ARMING_CHECK", 0, 1, "",
                           "1: refuse to arm without a navigation fix; 0: no pre-arm check", integer=True)

    def __init__(self, mission: list[Waypoint] | list[MissionCommand] | tuple, *, armed: bool, mode: Mode,
                 scenario_route: np.ndarray | None = None, default_radius: float = 3.0, wp_speed: float = 1.5,
                 mission_done: int = MIS_DONE_LOITER, home_item: bool = False) -> None:
        self.armed = armed
        self.active: RoverMode = MODES[Mode(mode)]
        self.wp_radius, self.wp_speed, self.rtl_speed = default_radius, wp_speed, 0.0
        self.mission_done, self.arming_check = mission_done, 1
        self.home_item = home_item
        self.executor = self._executor(tuple(_command(w) for w in mission))
        self.home: tuple[float, float] | None = None
        self.guided_target: tuple[float, float] | None = None
        self.route: Route | None = None
        self.speed: float | None = None       # m/s, DO_CHANGE_SPEED's set-point until the mode changes
        self.t = 0.0
        self._versions = 0
        self.reached: list[int] = []          # items reached since last taken (MISSION_ITEM_REACHED)
        self.notes: list[tuple[str, bool]] = []  # (text, warning) for STATUSTEXT
        self._last_reported = -1              # the item reported last (each is reported once)
        self._at_route_end = False
        self.manual: tuple[float, float, float] | None = None  # (x, r, wall time) of MANUAL_CONTROL
        # RTL's destination other than home: the nearest rally point inside the fence (autopilot_bridge.geofence)
        self.rally_target: Callable[[tuple[float, float]], tuple[float, float] | None] = lambda _p: None
        if scenario_route is not None and self.active.number == Mode.AUTO:
            # The scenario's reference path as given (version 0): runs without a GCS stay as they were.
            self.route = Route(0, np.asarray(scenario_route, dtype=float), self._final_radius())
            first = self.executor.first if len(self.mission) > self.executor.first else 0
            self.executor.adopt_leg(list(range(first, len(self.mission))),
                                    [c.required_position() for c in self.mission[first:]])
        self.changed = False                  # mode/arming changed since last looked (telemetry)

    # -- state ----------------------------------------------------------------------------------
    @property
    def mode(self) -> Mode:
        return self.active.number

    @property
    def mission(self) -> tuple[MissionCommand, ...]:
        return self.executor.commands

    @property
    def current(self) -> int:
        return self.executor.current

    @property
    def complete(self) -> bool:
        """AUTO: the mission is complete; other modes: the route's end was reached."""
        return self.executor.complete if self.mode == Mode.AUTO else self._at_route_end

    def _final_radius(self) -> float:
        return self.executor.radius(self.mission[-1]) if self.mission else self.wp_radius

    @property
    def default_radius(self) -> float:
        """WP_RADIUS, m."""
        return self.wp_radius

    def _executor(self, commands: tuple[MissionCommand, ...]) -> MissionExecutor:
        return MissionExecutor(commands, lambda: self.wp_radius, first=1 if self.home_item else 0)

    def speed_setpoint(self) -> float:
        """Speed over ground (m/s) to aim at: DO_CHANGE_SPEED's until the mode changes, else RTL_SPEED
        in RTL (when set), else WP_SPEED."""
        if self.speed is not None:
            return min(max(self.speed, SPEED_RANGE[0]), SPEED_RANGE[1])
        if self.mode == Mode.RTL and self.rtl_speed > 0.0:
            return max(self.rtl_speed, SPEED_RANGE[0])
        return self.wp_speed

    # -- MissionHost ----------------------------------------------------------------------------
    def new_route(self, path: list[tuple[float, float]], goal_radius: float, loiter: bool = False) -> None:
        self._versions += 1
        self.route = Route(self._versions, np.asarray(path, dtype=float).reshape(-1, 2), goal_radius, loiter)
        self._at_route_end = False

    def loiter_at(self, position: tuple[float, float]) -> None:
        """Keep station at ``position`` (NED m), as ArduRover's ``start_loiter()``: LOITER, and GUIDED
        without a target on a boat."""
        self.new_route([position, position], self.default_radius, loiter=True)

    def set_speed(self, speed: float) -> None:
        """DO_CHANGE_SPEED (m/s over ground); outside SPEED_RANGE it is clamped, with a warning."""
        v = min(max(float(speed), SPEED_RANGE[0]), SPEED_RANGE[1])
        self.speed = v
        self.note(f"speed {v:g} m/s" + ("" if v == speed else f" ({speed:g} asked, limited)"), warning=v != speed)

    def note(self, text: str, warning: bool = False) -> None:
        self.notes.append((text, warning))

    # -- commands -------------------------------------------------------------------------------
    def arm(self, on: bool) -> tuple[bool, str]:
        if on == self.armed:
            return True, "already " + ("armed" if on else "disarmed")
        self.armed = on
        self.changed = True
        return True, "armed" if on else "disarmed"

    def set_mode(self, mode: Mode, position: tuple[float, float] | None) -> tuple[bool, str]:
        """Switch mode (the mode class decides whether it can be entered). GUIDED entered this way keeps
        station where the boat is, whatever target it had before (ArduRover's ``ModeGuided::_enter`` on a
        boat: ``start_loiter()``); a target comes only with :meth:`reposition`."""
        return self._switch(Mode(mode), position, None)

    def reposition(self, target: tuple[float, float], position: tuple[float, float] | None) -> tuple[bool, str]:
        """GUIDED towards ``target`` (NED m)."""
        if position is None:
            return False, "GUIDED: no position yet"
        return self._switch(Mode.GUIDED, position, target)

    def _switch(self, mode: Mode, position: tuple[float, float] | None,
                guided_target: tuple[float, float] | None) -> tuple[bool, str]:
        new = MODES[mode]
        if new.needs_position and position is None:
            return False, f"{new.name}: no position yet"
        previous, previous_speed, previous_target = self.active, self.speed, self.guided_target
        self.active = new
        self.speed = None   # a new mode starts at its own speed; entering AUTO may run a DO_CHANGE_SPEED
        self.guided_target = guided_target
        ok, why = new.enter(self, position)
        if not ok:
            self.active, self.speed, self.guided_target = previous, previous_speed, previous_target
            return False, why
        self.changed = True
        self._at_route_end = False
        return True, why

    def replace_mission(self, mission: list[Waypoint] | list[MissionCommand] | tuple,
                        position: tuple[float, float] | None) -> None:
        """A new mission, all at once: restart at its first item (re-route now if in AUTO)."""
        self.executor = self._executor(tuple(_command(w) for w in mission))
        self.reached.clear()
        self._last_reported = -1
        if self.mode == Mode.AUTO:
            if self.mission and position is not None:
                self.executor.start(0, self, position, self.t)
            else:
                self.route = None  # nothing to do: hold
        self.changed = True

    def set_current(self, seq: int, position: tuple[float, float] | None) -> bool:
        if not 0 <= seq < len(self.mission):
            return False
        seq = max(seq, self.executor.first)   # item 0 is home where home_item: go to item 1
        self.executor.current = seq
        self.executor.complete = False
        self._last_reported = -1
        if self.mode == Mode.AUTO and position is not None:
            self.executor.start(seq, self, position, self.t)
        self.changed = True
        return True

    def mission_start(self, first: int, position: tuple[float, float] | None) -> tuple[bool, str]:
        """MAV_CMD_MISSION_START: ``first`` 0 resumes where the mission stands (ArduRover's MIS_RESTART = 0:
        a paused mission goes on from its current item; a finished one starts again); else from ``first``."""
        if not self.mission:
            return False, "no mission"
        if not 0 <= first < len(self.mission):
            return False, f"no item {first}"
        if len(self.mission) <= self.executor.first:
            return False, "no mission items after home"
        if first == 0 and not self.executor.complete:
            if self.mode == Mode.AUTO:
                return True, "mission running"
            return self.set_mode(Mode.AUTO, position)
        self.executor.current = max(first, self.executor.first)
        self.executor.complete = False
        self._last_reported = -1
        return self.set_mode(Mode.AUTO, position)

    # -- per frame ------------------------------------------------------------------------------
    def wants_thrust(self) -> bool:
        """True when the planner and the controllers drive the thrusters."""
        return self.armed and self.route is not None and self.active.drives

    def update(self, north: float, east: float, t: float | None = None) -> None:
        """The position (NED m) at vehicle time ``t`` (s): home from the first fix, the mode's progress."""
        if t is not None:
            self.t = t
        if self.home is None:
            self.home = (north, east)
        if self.route is not None and not self._at_route_end:
            end = self.route.path[-1]
            if math.hypot(end[0] - north, end[1] - east) <= self.route.goal_radius:
                self._at_route_end = True
        before = self.current
        self.active.update(self, north, east, self.t)
        if self.current != before:
            self.changed = True

    def finish(self) -> None:
        """The autopilot reached the end of the route: in AUTO, the leg's items not yet reported count
        as reached (the mission goes on from there)."""
        if self.mode == Mode.AUTO:
            self.executor.finish_leg(self, self.t)

    def reached_item(self, seq: int) -> None:
        """Item ``seq`` reached: reported once (a boat keeping station at the final goal stays
        within its radius frame after frame)."""
        if seq != self._last_reported:
            self.reached.append(seq)
            self._last_reported = seq

    def take_reached(self) -> list[int]:
        r, self.reached = self.reached, []
        return r

    def take_notes(self) -> list[tuple[str, bool]]:
        n, self.notes = self.notes, []
        return n
