"""The vehicle's control modes, one class each, as ArduPilot Rover organises them (mode.h, mode_*.cpp).

Mode numbers are Rover's ``custom_mode`` so that boat ground stations (QGroundControl, MAVProxy,
Mission Planner) show their names. Each mode says what it needs to be entered (:meth:`RoverMode.enter`),
what it does per frame with the mission or its target (:meth:`RoverMode.update`) and where the thrust
comes from (:meth:`RoverMode.output`):

* MANUAL (0): thrusters from MANUAL_CONTROL (x: surge, r: yaw, each -1000..1000); without input for 1 s,
  HOLD's behaviour (ArduRover's radio failsafe: HOLD), which keeps station near obstacles.
* HOLD (4): both thrusters at zero, the boat drifts with wind and current (as Rover's HOLD does for
  boats) - but never onto an obstacle or across the fence: near them it keeps station
  (:meth:`autopilot_bridge.helm.Helm.hold`).
* LOITER (5): keep station where the mode was entered, against the current
  (:mod:`autopilot_bridge.station_keeping`).
* AUTO (10): run the mission (:mod:`autopilot_bridge.mission_executor`); the online planner (section 2.2
  of the paper) plans local paths along the global reference path [position, waypoints of the leg...].
* RTL (11): reference path [position, home]; keeps station at home (``mission_done``).
* GUIDED (15): go to the last goto target (MAV_CMD_DO_REPOSITION, SET_POSITION_TARGET_GLOBAL_INT) and
  keep station there; without a target, keep station where the mode was entered, as LOITER does (Rover's
  ``ModeGuided::_enter`` starts loitering on a boat: ``is_boat()`` -> ``start_loiter()``; a boat left at
  zero thrust drifts with the current).

Disarmed means zero thrust whatever the mode. All positions NED metres.
"""

from __future__ import annotations

from enum import IntEnum
from typing import TYPE_CHECKING, Protocol

from common.mavlink import MAV_TYPE as M

if TYPE_CHECKING:
    from autopilot_bridge.control import Thrust
    from autopilot_bridge.navigation import NavState
    from autopilot_bridge.vehicle import Vehicle


class Mode(IntEnum):
    """ArduPilot Rover's custom_mode numbers of the modes this boat has."""

    MANUAL = 0
    HOLD = 4
    LOITER = 5
    AUTO = 10
    RTL = 11
    GUIDED = 15


class Driver(Protocol):
    """What a mode drives the thrusters with (the autopilot implements it); each returns a Thrust."""

    def idle(self) -> Thrust: ...                    # both thrusters at zero

    # (x, r, wall time) or None; without a fresh stick: hold
    def manual(self, stick: tuple[float, float, float] | None, s: NavState, dt: float) -> Thrust: ...

    def navigate(self, s: NavState, dt: float) -> Thrust: ...  # follow vehicle.route (planned/fallback, station)

    def hold(self, s: NavState, dt: float) -> Thrust: ...      # HOLD: drift, but never onto an obstacle or the fence


_AUTO_FLAGS = M.MAV_MODE_FLAG_AUTO_ENABLED | M.MAV_MODE_FLAG_GUIDED_ENABLED | M.MAV_MODE_FLAG_STABILIZE_ENABLED
_GUIDED_FLAGS = M.MAV_MODE_FLAG_GUIDED_ENABLED | M.MAV_MODE_FLAG_STABILIZE_ENABLED


class RoverMode:
    """A mode: entry conditions, per-frame behaviour, thrust source; HEARTBEAT base_mode flags."""

    number: Mode = Mode.HOLD
    flags: int = 0
    needs_position = False
    drives = False            # the planner and the controllers follow vehicle.route

    @property
    def name(self) -> str:
        return self.number.name

    def enter(self, v: Vehicle, position: tuple[float, float] | None) -> tuple[bool, str]:
        """Refuse (False, why) or take over: set the vehicle's route for this mode."""
        v.route = None
        return True, self.name

    def update(self, v: Vehicle, north: float, east: float, t: float) -> None:
        """Per frame, after navigation (position NED m, vehicle time s)."""

    def output(self, driver: Driver, v: Vehicle, s: NavState, dt: float) -> Thrust:
        if self.drives and v.route is not None:
            return driver.navigate(s, dt)
        return driver.idle()


class ModeManual(RoverMode):
    number, flags = Mode.MANUAL, M.MAV_MODE_FLAG_MANUAL_INPUT_ENABLED

    def output(self, driver: Driver, v: Vehicle, s: NavState, dt: float) -> Thrust:
        return driver.manual(v.manual, s, dt)


class ModeHold(RoverMode):
    number = Mode.HOLD

    def output(self, driver: Driver, v: Vehicle, s: NavState, dt: float) -> Thrust:
        return driver.hold(s, dt)


class ModeLoiter(RoverMode):
    number, flags, needs_position, drives = Mode.LOITER, _GUIDED_FLAGS, True, True

    def enter(self, v: Vehicle, position: tuple[float, float] | None) -> tuple[bool, str]:
        assert position is not None  # needs_position: Vehicle.set_mode checked it
        v.loiter_at(position)
        return True, self.name


class ModeAuto(RoverMode):
    number, flags, needs_position, drives = Mode.AUTO, _AUTO_FLAGS, True, True

    def enter(self, v: Vehicle, position: tuple[float, float] | None) -> tuple[bool, str]:
        if len(v.mission) <= v.executor.first:   # nothing, or only home (item 0, ArduPilot's convention)
            return False, "AUTO: no mission"
        assert position is not None  # needs_position: Vehicle.set_mode checked it
        v.route = None
        resumed_speed = v.executor.mission_speed
        v.executor.start(v.executor.current, v, position, v.t)
        if v.speed is None and resumed_speed is not None:
            v.speed = resumed_speed      # a resumed mission keeps its DO_CHANGE_SPEED
        return True, self.name

    def update(self, v: Vehicle, north: float, east: float, t: float) -> None:
        if v.armed:
            v.executor.update(v, north, east, t)


class ModeRTL(RoverMode):
    number, flags, needs_position, drives = Mode.RTL, _AUTO_FLAGS, True, True

    def enter(self, v: Vehicle, position: tuple[float, float] | None) -> tuple[bool, str]:
        assert position is not None  # needs_position: Vehicle.set_mode checked it
        rally = v.rally_target(position)
        target = rally if rally is not None else v.home
        if target is None:
            return False, "RTL: no home position"
        v.new_route([position, target], v.default_radius)
        return True, self.name if rally is None else f"{self.name} to rally point {rally[0]:.0f} m N {rally[1]:.0f} m E"


class ModeGuided(RoverMode):
    number, flags, needs_position, drives = Mode.GUIDED, _GUIDED_FLAGS, True, True

    def enter(self, v: Vehicle, position: tuple[float, float] | None) -> tuple[bool, str]:
        assert position is not None  # needs_position: Vehicle.set_mode checked it
        if v.guided_target is not None:
            v.new_route([position, v.guided_target], v.default_radius)
        else:
            v.loiter_at(position)
        return True, self.name


MODES: dict[Mode, RoverMode] = {m.number: m for m in (ModeManual(), ModeHold(), ModeLoiter(), ModeAuto(), ModeRTL(),
                                                      ModeGuided())}
