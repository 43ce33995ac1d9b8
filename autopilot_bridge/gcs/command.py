"""The command microservice (https://mavlink.io/en/services/command.html) and the other vehicle writes.

COMMAND_LONG and COMMAND_INT are dispatched through one table keyed by MAV_CMD (:attr:`CommandService.table`);
other services add their commands to it (:meth:`register`). Every command is answered with one
COMMAND_ACK; a refusal's reason goes out as a STATUSTEXT warning. SET_MODE, MANUAL_CONTROL and
SET_POSITION_TARGET_GLOBAL_INT are handled here too (they command the vessel without a MAV_CMD).
"""

from __future__ import annotations

from collections.abc import Callable

from autopilot_bridge.gcs.context import Outbox, VehicleView, finite
from autopilot_bridge.gcs.failsafe import GcsFailsafe
from autopilot_bridge.modes import Mode
from autopilot_bridge.vehicle_api import Result, VehicleApi
from common.mavlink import MAV_TYPE as M
from common.mavlink import MavMessage

CommandResult = tuple[int, str]   # (MAV_RESULT, why)
CommandHandler = Callable[[list[float], float, float], CommandResult]   # (param1-4, x/param5, y/param6)
FORCE_ARM_DISARM = 21196.0   # MAV_CMD_COMPONENT_ARM_DISARM param2: disarm even where the vehicle refuses (MAVLink)
POSITION_IGNORED = 0b111  # SET_POSITION_TARGET_GLOBAL_INT type_mask bits: position ignored (x, y, z)


def ack_of(r: Result) -> CommandResult:
    if r.ok:
        return M.MAV_RESULT_ACCEPTED, r.text
    return (M.MAV_RESULT_TEMPORARILY_REJECTED if r.temporary else M.MAV_RESULT_DENIED), r.text


class CommandService:
    def __init__(self, out: Outbox, view: VehicleView, failsafe: GcsFailsafe,
                 on_mission_current: Callable[[], None]) -> None:
        self.out, self.view, self.failsafe = out, view, failsafe
        self.on_mission_current = on_mission_current
        self.table: dict[int, CommandHandler] = {
            M.MAV_CMD_COMPONENT_ARM_DISARM: self._arm,
            M.MAV_CMD_DO_SET_MODE: self._do_set_mode,
            M.MAV_CMD_MISSION_START: self._mission_start,
            M.MAV_CMD_DO_PAUSE_CONTINUE: self._pause_continue,
            M.MAV_CMD_NAV_LOITER_UNLIM: lambda *_: self.set_mode(Mode.LOITER),
            M.MAV_CMD_NAV_RETURN_TO_LAUNCH: lambda *_: self.set_mode(Mode.RTL),
            M.MAV_CMD_DO_CHANGE_SPEED: self._change_speed,
            M.MAV_CMD_DO_REPOSITION: lambda p, x5, y6: self._goto(x5, y6, "reposition"),
            M.MAV_CMD_DO_SET_MISSION_CURRENT: self._set_current,
            M.MAV_CMD_DO_SET_HOME: self._set_home,
        }

    def register(self, handlers: dict[int, CommandHandler]) -> None:
        """Add another service's commands (each MAV_CMD has one owner)."""
        twice = set(handlers) & set(self.table)
        if twice:
            raise ValueError(f"MAV_CMD handled twice: {sorted(twice)}")
        self.table.update(handlers)

    def handlers(self) -> dict[str, Callable[[MavMessage, float], None]]:
        return {"COMMAND_LONG": self._on_command, "COMMAND_INT": self._on_command, "SET_MODE": self._on_set_mode,
                "MANUAL_CONTROL": self._on_manual_control,
                "SET_POSITION_TARGET_GLOBAL_INT": self._on_position_target,
                "SET_HOME_POSITION": self._on_set_home_position}

    def refuse(self, m: MavMessage) -> None:
        """A command refused by the security gate: COMMAND_ACK DENIED to its sender."""
        if m.get_type() in ("COMMAND_LONG", "COMMAND_INT"):
            self.out.send("command_ack", m.command, M.MAV_RESULT_DENIED, 0, 0, m.get_srcSystem(), m.get_srcComponent())

    # -- messages ---------------------------------------------------------------------------------
    def _on_command(self, m: MavMessage, now: float) -> None:
        if m.target_system not in (0, self.view.sysid) or m.target_component not in (0, self.view.compid):
            return
        p = [m.param1, m.param2, m.param3, m.param4]
        if m.get_type() == "COMMAND_INT":
            x5, y6 = m.x * 1e-7, m.y * 1e-7
        else:
            x5, y6 = m.param5, m.param6
        result, why = self.execute(int(m.command), p, x5, y6)
        self.out.send("command_ack", m.command, result, 0, 0, m.get_srcSystem(), m.get_srcComponent())
        if result != M.MAV_RESULT_ACCEPTED and why:
            self.out.statustext(why, M.MAV_SEVERITY_WARNING)

    def execute(self, cmd: int, p: list[float], x5: float, y6: float) -> CommandResult:
        """One COMMAND_LONG/COMMAND_INT: (MAV_RESULT, why) from the handler registered for its id."""
        handler = self.table.get(cmd)
        if handler is None or self.view.api is None:
            return M.MAV_RESULT_UNSUPPORTED, ""
        return handler(p, x5, y6)

    def _on_set_mode(self, m: MavMessage, now: float) -> None:
        if m.target_system == self.view.sysid and m.base_mode & M.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED \
                and self.view.api is not None:
            self.set_mode(m.custom_mode)

    def _on_manual_control(self, m: MavMessage, now: float) -> None:
        api = self.view.api
        if m.target in (0, self.view.sysid) and api is not None:
            def clip(v: float) -> float:
                return max(-1.0, min(1.0, v / 1000.0))

            api.manual_input(clip(m.x), clip(m.r), now)

    def _on_position_target(self, m: MavMessage, now: float) -> None:
        """SET_POSITION_TARGET_GLOBAL_INT: a GUIDED goto (position only; velocity/acceleration ignored)."""
        if m.target_system not in (0, self.view.sysid) or self.view.api is None:
            return
        if m.type_mask & POSITION_IGNORED == POSITION_IGNORED:
            return
        code, why = self._goto(m.lat_int * 1e-7, m.lon_int * 1e-7, "position target")
        if code != M.MAV_RESULT_ACCEPTED and why:
            self.out.statustext(why, M.MAV_SEVERITY_WARNING)

    def _on_set_home_position(self, m: MavMessage, now: float) -> None:
        """SET_HOME_POSITION (deprecated for MAV_CMD_DO_SET_HOME, still sent by some ground stations)."""
        if m.target_system not in (0, self.view.sysid) or self.view.api is None:
            return
        code, why = self._set_home([0.0, 0.0, 0.0, 0.0], m.latitude * 1e-7, m.longitude * 1e-7)
        self.out.statustext(why, M.MAV_SEVERITY_INFO if code == M.MAV_RESULT_ACCEPTED else M.MAV_SEVERITY_WARNING)

    # -- commands ---------------------------------------------------------------------------------
    def _api(self) -> VehicleApi:
        api = self.view.api
        assert api is not None  # execute() answers UNSUPPORTED before attach
        return api

    def set_mode(self, custom_mode: float) -> CommandResult:
        try:
            mode = Mode(int(custom_mode))
        except (ValueError, OverflowError):
            return M.MAV_RESULT_DENIED, f"unknown mode {custom_mode}"
        r = self._api().set_mode(mode)
        if r.ok:
            self.failsafe.clear()
            self.out.statustext(f"mode {mode.name}")
        return (M.MAV_RESULT_ACCEPTED if r.ok else M.MAV_RESULT_DENIED), r.text

    def _arm(self, p: list[float], x5: float, y6: float) -> CommandResult:
        if not finite(p[0]) or p[0] not in (0.0, 1.0):
            return M.MAV_RESULT_DENIED, "arm: param1 must be 0 or 1"
        r = self._api().arm(p[0] == 1.0, force=p[1] == FORCE_ARM_DISARM)
        if r.ok:
            self.out.statustext(r.text)
        return ack_of(r)

    def _do_set_mode(self, p: list[float], x5: float, y6: float) -> CommandResult:
        if not finite(p[0]) or not finite(p[1]) or not int(p[0]) & M.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED:
            return M.MAV_RESULT_DENIED, "set mode: custom mode flag (param1) and mode (param2) needed"
        if finite(p[2]) and p[2] != 0.0:
            # Our modes have no sub-mode. A (main, sub) pair is another autopilot's numbering (PX4's
            # AUTO.MISSION is (4, 4), as MAVSDK sends to a non-ArduPilot vehicle): read as Rover's
            # custom mode 4 it would silently mean HOLD, so refuse it.
            return M.MAV_RESULT_DENIED, f"set mode: no sub-mode {p[2]:g} (Rover modes: param2 only)"
        return self.set_mode(p[1])

    def _mission_start(self, p: list[float], x5: float, y6: float) -> CommandResult:
        r = self._api().start_mission(int(p[0]) if finite(p[0]) else 0)
        if r.ok:
            self.failsafe.clear()
        return ack_of(r)

    def _pause_continue(self, p: list[float], x5: float, y6: float) -> CommandResult:
        return self.set_mode(Mode.HOLD if (finite(p[0]) and p[0] == 0.0) else Mode.AUTO)

    def _change_speed(self, p: list[float], x5: float, y6: float) -> CommandResult:
        """param2 speed m/s over ground; -1 leaves it as it is, -2 returns to the default (WP_SPEED)."""
        speed = p[1]
        if speed == -1.0:
            return M.MAV_RESULT_ACCEPTED, "speed unchanged"
        if speed == -2.0:
            return ack_of(self._api().set_speed(None))
        if not finite(speed) or speed < 0.0:
            return M.MAV_RESULT_DENIED, f"change speed: {speed:g} m/s is not a speed"
        return ack_of(self._api().set_speed(float(speed)))

    def _set_home(self, p: list[float], lat: float, lon: float) -> CommandResult:
        """MAV_CMD_DO_SET_HOME: param1 = 1 where the boat is, else at lat/lon, checked like a GUIDED target."""
        if finite(p[0]) and p[0] == 1.0:
            return ack_of(self._api().set_home(None, None))
        if not (finite(lat) and finite(lon)) or not -90 <= lat <= 90 or not -180 <= lon <= 180 or \
                (lat == 0.0 and lon == 0.0):
            return M.MAV_RESULT_DENIED, "set home: bad latitude/longitude"
        if self.view.on_chart(lat, lon) is not None:
            return M.MAV_RESULT_DENIED, "set home: off the chart"
        return ack_of(self._api().set_home(*self.view.geo.geodetic_to_sea_level(lat, lon)))

    def _goto(self, lat: float, lon: float, what: str) -> CommandResult:
        if not (finite(lat) and finite(lon)) or not -90 <= lat <= 90 or not -180 <= lon <= 180 or \
                (lat == 0.0 and lon == 0.0):
            return M.MAV_RESULT_DENIED, f"{what}: bad latitude/longitude"
        if self.view.on_chart(lat, lon) is not None:
            return M.MAV_RESULT_DENIED, f"{what}: target off the chart"
        r = self._api().goto(*self.view.geo.geodetic_to_sea_level(lat, lon))
        if r.ok:
            self.failsafe.clear()
        return ack_of(r)

    def _set_current(self, p: list[float], x5: float, y6: float) -> CommandResult:
        r = self._api().set_mission_current(int(p[0]) if finite(p[0]) else -1)
        self.on_mission_current()
        return ack_of(r)
