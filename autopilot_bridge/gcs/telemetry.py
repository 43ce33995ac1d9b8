"""The telemetry microservice: the streamed message set, its rates, and messages sent on request.

Streams are scheduled in the vessel's (simulated) time at rates a GCS changes with
MAV_CMD_SET_MESSAGE_INTERVAL or REQUEST_DATA_STREAM (both signed when signing is on: they change what
the boat sends). HEARTBEAT also goes out at least once per wall second, so a GCS keeps the link while
the simulator is paused. Each message has one encoder in :attr:`TelemetryService.encoders`, keyed by
name; the MAV_CMDs this service answers are in :meth:`TelemetryService.commands`.
"""

from __future__ import annotations

import math
from collections.abc import Callable

from autopilot_bridge.behaviour import Behaviour
from autopilot_bridge.gcs.context import Outbox, VehicleView, finite
from autopilot_bridge.gcs.identity import CAPABILITIES, Identity
from autopilot_bridge.modes import Mode
from autopilot_bridge.navigation import NavState
from autopilot_bridge.onboard_status import OnboardStatus
from common.mavlink import MAV_TYPE as M
from common.mavlink import MavMessage, mavlink2

# Default stream intervals (s of vessel time); a GCS changes them per message.
DEFAULT_INTERVALS = {
    "HEARTBEAT": 1.0, "SYS_STATUS": 1.0, "GPS_RAW_INT": 0.5, "GLOBAL_POSITION_INT": 0.2,
    "LOCAL_POSITION_NED": 0.1, "ATTITUDE": 0.1, "VFR_HUD": 0.25, "MISSION_CURRENT": 1.0,
    "ACTUATOR_OUTPUT_STATUS": 0.5, "HOME_POSITION": 5.0, "ESC_TELEMETRY_1_TO_4": 0.5, "BATTERY_STATUS": 1.0,
}
# REQUEST_DATA_STREAM groups (ArduPilot's grouping of the same messages).
STREAM_GROUPS = {
    M.MAV_DATA_STREAM_EXTENDED_STATUS: ("SYS_STATUS", "GPS_RAW_INT", "MISSION_CURRENT"),
    M.MAV_DATA_STREAM_POSITION: ("GLOBAL_POSITION_INT", "LOCAL_POSITION_NED"),
    M.MAV_DATA_STREAM_EXTRA1: ("ATTITUDE",),
    M.MAV_DATA_STREAM_EXTRA2: ("VFR_HUD",),
    M.MAV_DATA_STREAM_RAW_CONTROLLER: ("ACTUATOR_OUTPUT_STATUS",),
    M.MAV_DATA_STREAM_RC_CHANNELS: ("ACTUATOR_OUTPUT_STATUS",),
    M.MAV_DATA_STREAM_EXTRA3: ("ESC_TELEMETRY_1_TO_4", "BATTERY_STATUS"),
}
MSG_IDS = {name: getattr(mavlink2, f"MAVLINK_MSG_ID_{name}") for name in DEFAULT_INTERVALS}
ID_NAMES = {v: k for k, v in MSG_IDS.items()}
ON_REQUEST = {mavlink2.MAVLINK_MSG_ID_AUTOPILOT_VERSION: "AUTOPILOT_VERSION", **ID_NAMES}
MODE_FLAGS = M.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED | M.MAV_MODE_FLAG_HIL_ENABLED
MIN_INTERVAL = 0.01  # s: at most once per IMU frame
# SYS_STATUS bits the vessel computer reports besides its sensors' (autopilot_bridge.onboard_status).
CONTROL_BITS = M.MAV_SYS_STATUS_SENSOR_XY_POSITION_CONTROL | M.MAV_SYS_STATUS_SENSOR_MOTOR_OUTPUTS
GPS_NO_GPS, SATELLITES_UNKNOWN = 0, 255

CommandResult = tuple[int, str]


class TelemetryService:
    """Streams and on-request messages of one vessel (all ground stations share the schedule)."""

    def __init__(self, out: Outbox, view: VehicleView, clock: Callable[[], float], identity: Identity, *,
                 failsafe_active: Callable[[], bool], link_errors: Callable[[], int],
                 mission_total: Callable[[], int]) -> None:
        self.out, self.view, self.clock, self.identity = out, view, clock, identity
        self.failsafe_active = failsafe_active     # HEARTBEAT says MAV_STATE_CRITICAL while it is
        self.link_errors = link_errors             # SYS_STATUS errors_comm
        self.mission_total = mission_total         # MISSION_CURRENT's total before the first status
        self.intervals = dict(DEFAULT_INTERVALS)
        self.next_due: dict[str, float] = {k: 0.0 for k in DEFAULT_INTERVALS}
        self.last_wall_heartbeat = -math.inf
        self._paths_sent = 0
        self.encoders: dict[str, Callable[[], None]] = {
            "HEARTBEAT": self.heartbeat, "SYS_STATUS": self._sys_status, "MISSION_CURRENT": self.mission_current,
            "HOME_POSITION": self.home, "ESC_TELEMETRY_1_TO_4": self._esc_telemetry,
            "LOCAL_POSITION_NED": self._local_position, "ATTITUDE": self._attitude,
            "GLOBAL_POSITION_INT": self._global_position, "GPS_RAW_INT": self._gps_raw, "VFR_HUD": self._vfr_hud,
            "ACTUATOR_OUTPUT_STATUS": self._actuator_outputs, "AUTOPILOT_VERSION": self._autopilot_version,
            "BATTERY_STATUS": self._battery_status,
        }

    # -- dispatch tables -------------------------------------------------------------------------
    def handlers(self) -> dict[str, Callable[[MavMessage, float], None]]:
        return {"PING": self._on_ping, "REQUEST_DATA_STREAM": self._on_request_data_stream}

    def commands(self) -> dict[int, Callable[[list[float], float, float], CommandResult]]:
        return {
            M.MAV_CMD_SET_MESSAGE_INTERVAL: self._cmd_message_interval,
            M.MAV_CMD_GET_MESSAGE_INTERVAL: self._cmd_get_interval,
            M.MAV_CMD_REQUEST_MESSAGE: self._cmd_request_message,
            M.MAV_CMD_REQUEST_AUTOPILOT_CAPABILITIES: self._cmd_capabilities,
            M.MAV_CMD_GET_HOME_POSITION: self._cmd_home,
        }

    # -- per frame / per service call ----------------------------------------------------------------
    def on_frame(self) -> None:
        """The streams due at the newest status's time, and events (items reached, mode changes, paths)."""
        st = self.view.status
        assert st is not None
        t = st.t
        for seq in st.reached:
            self.out.send("mission_item_reached", seq)
            self.mission_current()
        if st.changed:
            self.heartbeat()
            self.mission_current()
        for name, interval in self.intervals.items():
            if interval <= 0:
                continue
            if t + 1e-9 >= self.next_due[name] or self.next_due[name] - t > interval + 1.0:
                self.next_due[name] = t + interval
                self.emit(name)
        self._trajectory()

    def keep_alive(self) -> None:
        """A HEARTBEAT once per wall second at least (the simulator may be paused)."""
        if self.view.api is not None and self.clock() - self.last_wall_heartbeat >= 1.0:
            self.heartbeat()

    def emit(self, name: str) -> None:
        self.encoders[name]()

    # -- encoders ----------------------------------------------------------------------------------
    def _t_ms(self) -> int:
        return int(round(self.view.t * 1000))

    def _t_us(self) -> int:
        return int(round(self.view.t * 1e6))

    def _nav(self) -> NavState | None:
        return None if self.view.status is None else self.view.status.nav

    @staticmethod
    def _velocity(s: NavState) -> tuple[float, float]:
        return (s.u * math.cos(s.psi) - s.v * math.sin(s.psi), s.u * math.sin(s.psi) + s.v * math.cos(s.psi))

    def heartbeat(self) -> None:
        st = self.view.status
        base = MODE_FLAGS
        custom, status = int(Mode.HOLD), M.MAV_STATE_STANDBY
        if st is not None:
            custom = int(st.mode)
            base |= st.mode_flags
            if st.armed:
                base |= M.MAV_MODE_FLAG_SAFETY_ARMED
                status = M.MAV_STATE_ACTIVE
            if self.failsafe_active():
                status = M.MAV_STATE_CRITICAL
        self.out.send("heartbeat", M.MAV_TYPE_SURFACE_BOAT, self.identity.autopilot, base, custom, status)
        self.last_wall_heartbeat = self.clock()

    def _local_position(self) -> None:
        s = self._nav()
        if s is not None:
            vn, ve = self._velocity(s)
            self.out.send("local_position_ned", self._t_ms(), s.x, s.y, 0.0, vn, ve, 0.0)

    def _attitude(self) -> None:
        s = self._nav()
        if s is not None:
            self.out.send("attitude", self._t_ms(), 0.0, 0.0, s.psi, 0.0, 0.0, s.r)

    def _fix(self, s: NavState) -> tuple[float, float, int, int, int]:
        """Velocity north/east (m/s) and position as MAVLink integers: lat, lon (degE7), alt (mm)."""
        vn, ve = self._velocity(s)
        geo = self.view.geo
        lat, lon = geo.sea_level_to_geodetic(s.x, s.y)
        return vn, ve, int(round(lat * 1e7)), int(round(lon * 1e7)), int(round(geo.alt0 * 1000))

    def _global_position(self) -> None:
        s = self._nav()
        if s is None:
            return
        vn, ve, lat, lon, alt = self._fix(s)
        hdg = int(round(math.degrees(s.psi) % 360.0 * 100)) % 36000
        self.out.send("global_position_int", self._t_ms(), lat, lon, alt, 0, int(round(vn * 100)),
                      int(round(ve * 100)), 0, hdg)

    def _onboard(self) -> OnboardStatus | None:
        """The vessel's account of its sensors and pack (None from an API without one)."""
        get = getattr(self.view.api, "onboard_status", None)
        return get() if callable(get) else None

    def _gps_raw(self) -> None:
        """The receiver's own report (its newest HIL_GPS): fix type, satellites, position, as ArduPilot
        sends GPS_RAW_INT; before any, "no GPS" with satellites unknown."""
        onboard = self._onboard()
        g = None if onboard is None else onboard.gps
        if g is None:
            self.out.send("gps_raw_int", self._t_us(), GPS_NO_GPS, 0, 0, 0, 65535, 65535, 65535, 65535,
                          SATELLITES_UNKNOWN)
            return
        self.out.send("gps_raw_int", self._t_us(), g.fix_type, g.lat, g.lon, g.alt, g.eph, g.epv, g.vel, g.cog,
                      g.satellites)

    def _battery_status(self) -> None:
        """The pack as the battery monitor knows it (nothing before its first reading)."""
        onboard = self._onboard()
        b = None if onboard is None else onboard.battery
        if b is None:
            return
        cells = list(b.cells[:10]) + [65535] * (10 - min(len(b.cells), 10))
        ext = list(b.cells[10:14]) + [0] * (4 - len(b.cells[10:14]))
        self.out.send("battery_status", 0, M.MAV_BATTERY_FUNCTION_ALL, M.MAV_BATTERY_TYPE_LION, 32767, cells,
                      _clamp(b.current, 100.0, -1), _clamp(b.consumed_mah, 1.0, -1, 2**31 - 1),
                      _clamp(b.energy_j, 0.01, -1, 2**31 - 1), -1 if b.remaining is None else b.remaining,
                      b.time_remaining, b.charge_state, ext)

    def _vfr_hud(self) -> None:
        s = self._nav()
        st = self.view.status
        if s is None or st is None:
            return
        vn, ve = self._velocity(s)
        thr = 0  # VFR_HUD's throttle is 0-100 %: the mean of the two thrusters' magnitudes
        if st.thrust is not None:
            thr = int(round(50.0 * (abs(st.thrust[0]) + abs(st.thrust[1]))))
        self.out.send("vfr_hud", 0.0, math.hypot(vn, ve), int(round(math.degrees(s.psi) % 360.0)) % 360,
                      max(0, min(100, thr)), 0.0, 0.0)

    def _actuator_outputs(self) -> None:
        st = self.view.status
        if self._nav() is None or st is None or st.thrust is None:
            return
        act = [st.thrust[0], st.thrust[1]] + [0.0] * 30
        self.out.send("actuator_output_status", self._t_us(), 0b11, act)

    def _esc_telemetry(self) -> None:
        """ESC_TELEMETRY_1_TO_4 from the newest ESC Status of each thruster (CAN path only), in the
        message's units: degC, cV, cA, mAh, rpm (magnitude), Status transfers received."""
        api = self.view.api
        got = api.esc_telemetry() if api is not None else []
        if not got:
            return
        rows: list[dict[str, float] | None] = [*got, None, None, None, None][:4]

        def col(key: str, scale: float, offset: float = 0.0, top: int = 65535) -> list[int]:
            return [0 if r is None else max(0, min(top, int(round((r[key] + offset) * scale)))) for r in rows]

        self.out.send("esc_telemetry_1_to_4", col("temperature", 1.0, -273.15, 255), col("voltage", 100.0),
                      col("current", 100.0), [0] * 4,
                      [0 if r is None else min(65535, abs(int(r["rpm"]))) for r in rows],
                      [0 if r is None else int(r["count"]) % 65536 for r in rows])

    def mission_current(self) -> None:
        st = self.view.status
        if st is None:
            total = self.mission_total()
            state = M.MISSION_STATE_NOT_STARTED if total else M.MISSION_STATE_NO_MISSION
            self.out.send("mission_current", 0, total, state, 0)
            return
        total = st.mission_count
        auto = st.mode == Mode.AUTO
        if total == 0:
            state = M.MISSION_STATE_NO_MISSION
        elif st.mission_complete and auto:
            state = M.MISSION_STATE_COMPLETE
        elif auto and st.armed:
            state = M.MISSION_STATE_ACTIVE
        else:
            state = M.MISSION_STATE_PAUSED if st.mission_current > 0 else M.MISSION_STATE_NOT_STARTED
        self.out.send("mission_current", min(st.mission_current, max(total - 1, 0)), total, state, 1 if auto else 0)

    def _sys_status(self) -> None:
        """Sensors present/enabled/healthy as the vessel computer sees them (autopilot_bridge.onboard_status),
        and the pack's voltage (mV), current (cA) and remaining charge (%); -1 where unknown."""
        st = self.view.status
        onboard = self._onboard()
        present = CONTROL_BITS | (0 if onboard is None else onboard.present)
        enabled = CONTROL_BITS | (0 if onboard is None else onboard.enabled)
        health = M.MAV_SYS_STATUS_SENSOR_MOTOR_OUTPUTS | (0 if onboard is None else onboard.health)
        if st is not None and st.behaviour in (Behaviour.PLANNED, Behaviour.COMPLETE, Behaviour.RETURNING):
            health |= M.MAV_SYS_STATUS_SENSOR_XY_POSITION_CONTROL  # the planner delivers local paths
        b = None if onboard is None else onboard.battery
        volts = 65535 if b is None else _clamp(b.voltage, 1000.0, 65535, 65534)
        amps = -1 if b is None else _clamp(b.current, 100.0, -1, 32767)
        remaining = -1 if b is None or b.remaining is None else b.remaining
        errors = min(self.link_errors(), 65535)
        self.out.send("sys_status", present, enabled, health, 0, volts, amps, remaining, 0, errors, 0, 0, 0, 0)

    def home(self) -> None:
        st = self.view.status
        home = None if st is None else st.home
        if home is None:
            return
        geo = self.view.geo
        lat, lon = geo.sea_level_to_geodetic(*home)
        self.out.send("home_position", int(round(lat * 1e7)), int(round(lon * 1e7)), int(round(geo.alt0 * 1000)),
                      float(home[0]), float(home[1]), 0.0, [1.0, 0.0, 0.0, 0.0], 0.0, 0.0, 0.0, self._t_us())

    def _autopilot_version(self) -> None:
        idn = self.identity
        self.out.send("autopilot_version", CAPABILITIES, idn.flight_sw_version(), 0, 0, 0, list(idn.custom_version),
                      [0] * 8, [0] * 8, 0, 0, self.view.sysid)

    def _trajectory(self) -> None:
        st = self.view.status
        if st is None or st.local_paths == self._paths_sent or not st.local_path:
            return
        self._paths_sent = st.local_paths
        pts = st.local_path
        # Five points along the local path (the message's capacity), first and last included.
        idx = [round(i * (len(pts) - 1) / 4) for i in range(5)] if len(pts) >= 5 else list(range(len(pts)))
        n = len(idx)
        xs = [float(pts[i][0]) for i in idx] + [math.nan] * (5 - n)
        ys = [float(pts[i][1]) for i in idx] + [math.nan] * (5 - n)
        nan5 = [math.nan] * 5
        self.out.send("trajectory_representation_waypoints", self._t_us(), n, xs, ys,
                      [0.0] * n + [math.nan] * (5 - n), nan5, nan5, nan5, nan5, nan5, nan5, nan5, nan5,
                      [M.MAV_CMD_NAV_WAYPOINT] * n + [65535] * (5 - n))

    # -- messages ---------------------------------------------------------------------------------
    def _on_ping(self, m: MavMessage, now: float) -> None:
        # The ping protocol (mavlink.io/en/services/ping.html): a request has target 0/0; the reply
        # echoes time_usec and seq, addressed to the sender.
        if m.target_system == 0 and m.target_component == 0:
            self.out.send("ping", m.time_usec, m.seq, m.get_srcSystem(), m.get_srcComponent())

    def _on_request_data_stream(self, m: MavMessage, now: float) -> None:
        if m.target_system not in (0, self.view.sysid):
            return
        start, rate_hz = m.start_stop, m.req_message_rate
        names = sorted({n for g in STREAM_GROUPS.values() for n in g}) if m.req_stream_id == M.MAV_DATA_STREAM_ALL \
            else STREAM_GROUPS.get(m.req_stream_id, ())
        for n in names:
            self.intervals[n] = (1.0 / max(1, min(rate_hz, 100))) if (start and rate_hz > 0) else 0.0
            self.next_due[n] = self.view.t

    # -- commands ---------------------------------------------------------------------------------
    def _cmd_message_interval(self, p: list[float], x5: float, y6: float) -> CommandResult:
        name = ID_NAMES.get(int(p[0])) if finite(p[0]) else None
        if name is None or not finite(p[1]):
            return M.MAV_RESULT_DENIED, "message interval: message not streamed here"
        us = p[1]
        if us == -1:
            self.intervals[name] = 0.0
        elif us == 0:
            self.intervals[name] = DEFAULT_INTERVALS[name]
        elif us > 0:
            self.intervals[name] = max(us * 1e-6, MIN_INTERVAL)
        else:
            return M.MAV_RESULT_DENIED, "message interval: negative interval"
        self.next_due[name] = self.view.t
        return M.MAV_RESULT_ACCEPTED, ""

    def _cmd_get_interval(self, p: list[float], x5: float, y6: float) -> CommandResult:
        name = ID_NAMES.get(int(p[0])) if finite(p[0]) else None
        if name is None:
            return M.MAV_RESULT_DENIED, ""
        iv = self.intervals[name]
        self.out.send("message_interval", MSG_IDS[name], int(iv * 1e6) if iv > 0 else -1)
        return M.MAV_RESULT_ACCEPTED, ""

    def _cmd_request_message(self, p: list[float], x5: float, y6: float) -> CommandResult:
        name = ON_REQUEST.get(int(p[0])) if finite(p[0]) else None
        if name is None:
            return M.MAV_RESULT_DENIED, "request message: not available"
        self.emit(name)
        return M.MAV_RESULT_ACCEPTED, ""

    def _cmd_capabilities(self, p: list[float], x5: float, y6: float) -> CommandResult:
        self.emit("AUTOPILOT_VERSION")
        return M.MAV_RESULT_ACCEPTED, ""

    def _cmd_home(self, p: list[float], x5: float, y6: float) -> CommandResult:
        self.home()
        return M.MAV_RESULT_ACCEPTED, ""


def _clamp(value: float | None, scale: float, unknown: int, top: int = 32767) -> int:
    """``value * scale`` rounded into a MAVLink integer field's range [0, top]; ``unknown`` for None."""
    if value is None or not math.isfinite(value):
        return unknown
    return max(0, min(top, int(round(value * scale))))
