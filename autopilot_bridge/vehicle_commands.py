"""The vessel's command API (:class:`autopilot_bridge.vehicle_api.VehicleApi`), served to ground stations.

Every command is checked here before it reaches the vehicle: a GUIDED target or a home is refused, with
the reason, when it is off the chart, in an obstacle (with the planner's safety margin) or unreachable
by water from the boat, exactly as a mission waypoint would be; a speed must be finite and within the
hull's range. Positions NED m, speeds m/s over ground.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import TYPE_CHECKING

from autopilot_bridge.geofence import GeoFence
from autopilot_bridge.mission_commands import MissionCommand
from autopilot_bridge.modes import Mode
from autopilot_bridge.onboard_status import OnboardStatus
from autopilot_bridge.parameters import Param, ParamTable
from autopilot_bridge.route_planning import POSITION_COMMANDS, check_mission, check_mission_items
from autopilot_bridge.vehicle import SPEED_RANGE, Vehicle
from autopilot_bridge.vehicle_api import Result, VehicleStatus
from common.mavlink import MAV_TYPE as M
from planner.fence import Fence
from planner.gridmap import OccupancyGrid

if TYPE_CHECKING:
    from autopilot_bridge.actuators import Actuators
    from autopilot_bridge.gcs.mission import MissionItem


DISARM_DRIFT_S = 30.0   # s of drift with the current that a disarm may leave the boat clear of obstacles and fence
DRIFT_STEP_S = 0.5      # s between the drift's samples (at 3 m/s, the hull's top speed, 1.5 m: 3 chart cells)


class VehicleCommands:
    """What a ground station may do to the vessel, checked against the chart and the parameters."""

    def __init__(self, vehicle: Vehicle, grid: OccupancyGrid, safety_radius: float, params: ParamTable,
                 actuators: Actuators, status: Callable[[], VehicleStatus | None],
                 record: Callable[[str], None], geofence: GeoFence, fence_changed: Callable[[Fence], None],
                 onboard: Callable[[], OnboardStatus] | None = None,
                 current: Callable[[], tuple[float, float]] = lambda: (0.0, 0.0), coast_s: float = 0.0) -> None:
        """``onboard``: the sensors' and the pack's state (autopilot_bridge.onboard_status; None: nothing known);
        ``current``: the current's estimate (NED m/s) a disarmed boat would drift with; ``coast_s``: the time
        constant (s) in which the hull's own way through the water dies away, thrusters off (m11 / d_u of
        eq. (4)'s linear damping; the quadratic and cubic terms only shorten the run)."""
        self.vehicle, self.grid, self.safety_radius = vehicle, grid, safety_radius
        self._current, self.coast_s = current, coast_s
        self.param_table, self.actuators = params, actuators
        self._status, self._record = status, record
        self.geofence, self._fence_changed = geofence, fence_changed
        self._onboard = onboard

    def _position(self) -> tuple[float, float] | None:
        st = self._status()
        return None if st is None else st.position

    def check_target(self, north: float, east: float, what: str) -> str | None:
        """Why a boat cannot be sent to (north, east): off the chart, in an obstacle, unreachable; or None."""
        if not (math.isfinite(north) and math.isfinite(east)):
            return f"{what}: position not finite"
        if not self.geofence.allows(north, east):
            return f"{what}: outside the geofence or inside an exclusion zone"
        bad = check_mission(self.grid, [(north, east)], self.safety_radius, self._position())
        return None if bad is None else f"{what}: {bad[2]}"

    # -- VehicleApi -----------------------------------------------------------------------------
    def status(self) -> VehicleStatus | None:
        """The newest frame's status (None before the first navigation fix)."""
        return self._status()

    def arm(self, on: bool, force: bool = False) -> Result:
        """Arm or disarm. A disarm that would leave the boat to drift onto an obstacle or across the fence
        within ``DISARM_DRIFT_S`` is refused unless forced (MAV_CMD_COMPONENT_ARM_DISARM param2 = 21196,
        as ArduPilot's vehicles refuse a disarm in flight): disarmed, nothing holds the boat off a quay."""
        if on and self.vehicle.arming_check and self._position() is None:
            return Result(False, "arm: no navigation fix yet (ARMING_CHECK)", temporary=True)
        if not on and not force and self.vehicle.armed:
            why = self._drift_hazard()
            if why is not None:
                return Result(False, f"disarm refused: {why}; force with param2 = 21196", temporary=True)
        return Result(*self.vehicle.arm(on))

    def _drift_hazard(self) -> str | None:
        """Why a boat left to itself from here reaches within the safety radius of an obstacle or the fence's
        edge within ``DISARM_DRIFT_S``: it drifts with the current's estimate and coasts on with its own way
        through the water, which dies away in ``coast_s``. None if it stays clear."""
        st = self._status()
        if st is None or st.nav is None:
            return None
        nav = st.nav
        cn, ce = self._current()
        if not (math.isfinite(cn) and math.isfinite(ce)):
            cn = ce = 0.0
        c, sn = math.cos(nav.psi), math.sin(nav.psi)
        wn, we = nav.u * c - nav.v * sn - cn, nav.u * sn + nav.v * c - ce    # the way through the water
        for k in range(int(DISARM_DRIFT_S / DRIFT_STEP_S) + 1):
            t = k * DRIFT_STEP_S
            coast = self.coast_s * (1.0 - math.exp(-t / self.coast_s)) if self.coast_s > 0.0 else 0.0
            n, e = nav.x + cn * t + wn * coast, nav.y + ce * t + we * coast
            if self.grid.clearance_at(e, n) < self.safety_radius:
                what = "an obstacle"
            elif self.geofence.depth(n, e) < self.safety_radius:
                what = "the fence"
            else:
                continue
            if k == 0:
                return f"within {self.safety_radius:g} m of {what}"
            return (f"drifting with the current ({math.hypot(cn, ce):.2f} m/s) and coasting on its way through the "
                    f"water ({math.hypot(wn, we):.2f} m/s), the boat would be within {self.safety_radius:g} m of "
                    f"{what} in {t:g} s")
        return None

    def set_mode(self, mode: Mode) -> Result:
        return Result(*self.vehicle.set_mode(mode, self._position()))

    def set_param(self, name: str, value: float) -> Result:
        return Result(*self.param_table.set(name, value))

    def goto(self, north: float, east: float) -> Result:
        why = self.check_target(north, east, "GUIDED target")
        if why is not None:
            return Result(False, why)
        return Result(*self.vehicle.reposition((float(north), float(east)), self._position()))

    def set_home(self, north: float | None, east: float | None) -> Result:
        """Home at (north, east), or where the boat is when both are None (MAV_CMD_DO_SET_HOME param1 = 1)."""
        if north is None or east is None:
            here = self._position()
            if here is None:
                return Result(False, "set home: no position yet", temporary=True)
            north, east = here
        else:
            why = self.check_target(north, east, "home")
            if why is not None:
                return Result(False, why)
        self.vehicle.home = (float(north), float(east))
        self.vehicle.changed = True
        return Result(True, f"home set at {north:.1f} m N, {east:.1f} m E")

    def set_speed(self, speed: float | None) -> Result:
        if speed is None:
            self.vehicle.speed = None
            return Result(True, f"speed back to WP_SPEED {self.vehicle.wp_speed:g} m/s")
        lo, hi = SPEED_RANGE
        if not math.isfinite(speed) or not lo <= speed <= hi:
            return Result(False, f"speed {speed:g} m/s outside {lo:g}..{hi:g}")
        self.vehicle.speed = float(speed)
        return Result(True, f"speed {speed:g} m/s")

    def start_mission(self, first: int) -> Result:
        if not self.vehicle.armed:
            return Result(False, "mission start: not armed")
        return Result(*self.vehicle.mission_start(first, self._position()))

    def set_mission_current(self, seq: int) -> Result:
        ok = self.vehicle.set_current(seq, self._position())
        return Result(ok, "" if ok else f"no mission item {seq}")

    def replace_mission(self, commands: tuple[MissionCommand, ...]) -> None:
        self.vehicle.replace_mission(commands, self._position())

    def mission(self) -> tuple[MissionCommand, ...]:
        return self.vehicle.mission

    def check_mission(self, items: tuple[MissionItem, ...],
                      to_ned: Callable[[float, float], tuple[float, float]]) -> tuple[int, int, str] | None:
        first = 1 if self.vehicle.home_item else 0   # ArduPilot's item 0 is home: not a place to sail to
        for seq, it in enumerate(items):
            if seq >= first and it.command in POSITION_COMMANDS and not (it.x == 0 and it.y == 0) \
                    and not self.geofence.allows(*to_ned(it.lat, it.lon)):
                return seq, M.MAV_MISSION_INVALID, "outside the geofence or inside an exclusion zone"
        bad = check_mission_items(items[first:], to_ned, self.grid, self.safety_radius, self._position())
        if bad is not None:
            return bad[0] + first, bad[1], bad[2]
        return self._check_home_items(items, to_ned, first)

    def _check_home_items(self, items: tuple[MissionItem, ...], to_ned: Callable[[float, float], tuple[float, float]],
                          first: int) -> tuple[int, int, str] | None:
        """DO_SET_HOME items with a position: a home a later RTL could reach."""
        from autopilot_bridge.gcs.mission import has_position

        for seq, it in enumerate(items):
            if seq >= first and it.command == M.MAV_CMD_DO_SET_HOME and has_position(it):
                why = self.check_target(*to_ned(it.lat, it.lon), "DO_SET_HOME")
                if why is not None:
                    return seq, M.MAV_MISSION_INVALID, why
        return None

    def replace_fence(self, fence: Fence) -> None:
        """A new geofence (map frame; an empty one clears it): planning keeps out of it from now on."""
        self._fence_changed(fence)

    def fence(self) -> Fence:
        return self.geofence.fence

    def replace_rally(self, points: tuple[tuple[float, float], ...]) -> None:
        """New rally points (NED m): RTL goes to the nearest one inside the fence."""
        self.geofence.rally = tuple((float(n), float(e)) for n, e in points)

    def check_rally(self, points: tuple[tuple[float, float], ...]) -> tuple[int, str] | None:
        """(index, why) of the first rally point off the chart, in an obstacle, unreachable or outside the
        fence; None when all are good."""
        for i, (n, e) in enumerate(points):
            why = self.check_target(n, e, "rally point")
            if why is not None:
                return i, why
        return None

    def manual_input(self, x: float, r: float, wall_time: float) -> None:
        self.vehicle.manual = (x, r, wall_time)

    def record_event(self, text: str) -> None:
        self._record(text)

    def parameters(self) -> list[Param]:
        return self.param_table.params

    def esc_telemetry(self) -> list[dict[str, float] | None]:
        return self.actuators.esc_telemetry()

    def onboard_status(self) -> OnboardStatus:
        return OnboardStatus(0, 0, 0, None, None) if self._onboard is None else self._onboard()
