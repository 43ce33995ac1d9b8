"""The vessel's ground-station link: MAVLink 2 to any number of ground stations (Figure 2's console).

One :class:`GcsLink` per vessel computer. It

* sends the telemetry set on a schedule in the vessel's (simulated) time, at rates a GCS may change
  with MAV_CMD_SET_MESSAGE_INTERVAL or REQUEST_DATA_STREAM: HEARTBEAT (MAV_TYPE_SURFACE_BOAT, armed
  flag, ArduPilot Rover custom mode; also at least once per wall second so a GCS keeps the link
  while the simulator is paused), SYS_STATUS, GLOBAL_POSITION_INT, GPS_RAW_INT, LOCAL_POSITION_NED,
  ATTITUDE, VFR_HUD, HOME_POSITION, MISSION_CURRENT, ACTUATOR_OUTPUT_STATUS, ESC_TELEMETRY_1_TO_4 (the
  DroneCAN ESC Status of the CAN actuator path, as ArduPilot forwards it), the planned local path as
  TRAJECTORY_REPRESENTATION_WAYPOINTS, MISSION_ITEM_REACHED and STATUSTEXT events;
* answers commands (COMMAND_LONG / COMMAND_INT -> COMMAND_ACK), the mission microservice
  (:mod:`autopilot_bridge.gcs.mission`) and the parameter microservice (:mod:`.params`);
* runs the GCS-heartbeat failsafe (wall time: it watches a real link);
* optionally checks MAVLink 2 signatures (pymavlink's implementation) on everything that changes the
  vessel, and a system-id allow-list;
* copies every valid frame in and out to ``mirror_to`` (the `hil run` tap, which writes the run's
  .tlog), and counts every reject by reason.

Whatever arrives, nothing here raises into the control loop: bad input is counted and dropped.
"""

from __future__ import annotations

import hashlib
import math
import time
from collections import Counter
from pathlib import Path
from typing import Any, Callable

from autopilot_bridge.gcs.config import GcsParams
from autopilot_bridge.gcs.mission import MissionItem, MissionServer
from autopilot_bridge import mission_commands as mc
from autopilot_bridge.behaviour import Behaviour
from autopilot_bridge.gcs.mission import has_position
from autopilot_bridge.gcs.params import ParamTable, collect
from autopilot_bridge.gcs.transport import open_endpoint
from autopilot_bridge.mission_commands import MissionCommand
from autopilot_bridge.modes import Mode
from autopilot_bridge.parameters import Param
from autopilot_bridge.vehicle_api import Result, VehicleApi, VehicleStatus
from common.geodesy import LocalFrame
from common.mavlink import MAV_TYPE as M
from common.mavlink import Codec, mavlink2
from common.udp import UdpEndpoint

# Default stream intervals (s of vessel time); a GCS changes them per message.
DEFAULT_INTERVALS = {
    "HEARTBEAT": 1.0, "SYS_STATUS": 1.0, "GPS_RAW_INT": 0.5, "GLOBAL_POSITION_INT": 0.2,
    "LOCAL_POSITION_NED": 0.1, "ATTITUDE": 0.1, "VFR_HUD": 0.25, "MISSION_CURRENT": 1.0,
    "ACTUATOR_OUTPUT_STATUS": 0.5, "HOME_POSITION": 5.0, "ESC_TELEMETRY_1_TO_4": 0.5,
}
# REQUEST_DATA_STREAM groups (ArduPilot's grouping of the same messages).
STREAM_GROUPS = {
    M.MAV_DATA_STREAM_EXTENDED_STATUS: ("SYS_STATUS", "GPS_RAW_INT", "MISSION_CURRENT"),
    M.MAV_DATA_STREAM_POSITION: ("GLOBAL_POSITION_INT", "LOCAL_POSITION_NED"),
    M.MAV_DATA_STREAM_EXTRA1: ("ATTITUDE",),
    M.MAV_DATA_STREAM_EXTRA2: ("VFR_HUD",),
    M.MAV_DATA_STREAM_RAW_CONTROLLER: ("ACTUATOR_OUTPUT_STATUS",),
    M.MAV_DATA_STREAM_RC_CHANNELS: ("ACTUATOR_OUTPUT_STATUS",),
    M.MAV_DATA_STREAM_EXTRA3: ("ESC_TELEMETRY_1_TO_4",),
}
MSG_IDS = {name: getattr(mavlink2, f"MAVLINK_MSG_ID_{name}") for name in DEFAULT_INTERVALS}
ID_NAMES = {v: k for k, v in MSG_IDS.items()}
ON_REQUEST = {getattr(mavlink2, "MAVLINK_MSG_ID_AUTOPILOT_VERSION"): "AUTOPILOT_VERSION", **ID_NAMES}

# Messages that change the vessel: signing and the allow-list apply to these.
WRITES = frozenset({"COMMAND_LONG", "COMMAND_INT", "SET_MODE", "MISSION_COUNT", "MISSION_ITEM", "MISSION_ITEM_INT",
                    "MISSION_CLEAR_ALL", "MISSION_SET_CURRENT", "PARAM_SET", "MANUAL_CONTROL",
                    "SET_POSITION_TARGET_GLOBAL_INT"})
# SET_POSITION_TARGET_GLOBAL_INT type_mask bits: position ignored (x, y, z)
POSITION_IGNORED = 0b111
MISSION_WRITES = frozenset({"MISSION_COUNT", "MISSION_ITEM", "MISSION_ITEM_INT", "MISSION_CLEAR_ALL"})
SIGNING_EPOCH = 1420070400  # 2015-01-01 00:00:00 UTC, the MAVLink 2 signing timestamp origin
FIRMWARE_VERSION = (0 << 24) | (6 << 16) | (0 << 8) | 255  # 0.6.0 official

MODE_FLAGS = M.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED | M.MAV_MODE_FLAG_HIL_ENABLED


def load_signing_key(path: str) -> bytes:
    """32-byte key from a file: raw 32 bytes, 64 hex digits, or a passphrase (SHA-256 of it, as MAVProxy)."""
    try:
        raw = Path(path).read_bytes()
    except OSError as exc:
        raise ValueError(f"signing key file {path}: {exc.strerror or exc}") from None
    if len(raw) == 32:
        return raw
    text = raw.decode(errors="replace").strip()
    if not text:
        raise ValueError(f"signing key file {path}: empty")
    if len(text) == 64:
        try:
            return bytes.fromhex(text)
        except ValueError:
            pass
    return hashlib.sha256(text.encode()).digest()


def _enum_name(enum: str, value: int) -> str:
    entry = mavlink2.enums.get(enum, {}).get(int(value))
    return entry.name if entry is not None else f"{enum}_{int(value)}"


def _finite(x: Any) -> bool:
    return x is not None and math.isfinite(x)


def _text(v: Any) -> str:
    return (v.decode(errors="replace") if isinstance(v, (bytes, bytearray)) else str(v)).rstrip("\x00")


class _Stream:
    """One peer's parser (stream transports keep a partial frame between reads)."""

    def __init__(self, key: bytes | None) -> None:
        self.mav = mavlink2.MAVLink(None, 0, 0)
        self.mav.robust_parsing = True
        if key is not None:
            self.mav.signing.secret_key = key
            self.mav.signing.timestamp = int((time.time() - SIGNING_EPOCH) * 1e5)
            # Decode everything; whether a write was signed is decided per message (m._signed).
            self.mav.signing.allow_unsigned_callback = lambda _mav, _msgid: True
            # pymavlink records a frame's timestamp before checking its signature, so one forged frame
            # with a future timestamp would lock the real GCS out (replay check). Undo that on failure.
            check = self.mav.check_signature

            def checked(msgbuf: bytearray, src_system: int, src_component: int) -> bool:
                stamps = self.mav.signing.stream_timestamps
                key = (msgbuf[-13], src_system, src_component)
                before = stamps.get(key)
                ok = check(msgbuf, src_system, src_component)
                if not ok:
                    if before is None:
                        stamps.pop(key, None)
                    else:
                        stamps[key] = before
                return ok

            self.mav.check_signature = checked

    def parse(self, data: bytes, keep: bool) -> tuple[list[Any], list[str]]:
        mav = self.mav
        msgs, rejects = [], []
        try:
            got = mav.parse_buffer(data) or []
        except Exception:
            got, rejects = [], ["malformed"]
            keep = False
        for m in got:
            if isinstance(m, mavlink2.MAVLink_bad_data):
                reason = str(getattr(m, "reason", ""))
                rejects.append("not_mavlink" if "prefix" in reason else "bad_crc" if "CRC" in reason else "malformed")
            elif isinstance(m, mavlink2.MAVLink_unknown):
                rejects.append("unknown_message")
            else:
                msgs.append(m)
        if not keep:
            if mav.buf_len() > 0:
                rejects.append("truncated")
            mav.buf = bytearray()
            mav.buf_index = 0
            mav.expected_length = mavlink2.HEADER_LEN_V1 + 2
            mav.have_prefix_error = False
        elif mav.buf_len() > 1 << 16:  # a stream of garbage: do not let the buffer grow
            mav.buf, mav.buf_index = bytearray(), 0
        return msgs, rejects


class GcsLink:
    """MAVLink 2 ground-station endpoint(s) of one vessel; the autopilot's ``telemetry`` object."""

    def __init__(self, params: GcsParams, system_id: int, component_id: int, geo: LocalFrame, *,
                 mirror_to: tuple[str, ...] = (), chart_size: tuple[float, float] | None = None,
                 clock: Callable[[], float] = time.monotonic, log: Callable[[str], None] | None = None) -> None:
        self.params = params
        self.sysid, self.compid = system_id, component_id
        self.geo = geo
        self.clock = clock
        self.log = log or (lambda _m: None)
        self.key = load_signing_key(params.signing_key_file) if params.signing_key_file else None
        self.transports = []
        try:
            for spec in params.endpoints:
                self.transports.append(open_endpoint(spec, params.max_peers))
        except ValueError:
            self.close()
            raise
        self.addresses = [t.address for t in self.transports]
        self.mirror = UdpEndpoint("127.0.0.1:0", list(mirror_to)) if mirror_to else None
        self.codec = Codec(system_id, component_id)
        if self.key is not None:
            s = self.codec.mav.signing
            s.secret_key, s.sign_outgoing, s.link_id = self.key, True, 0
            s.timestamp = int((time.time() - SIGNING_EPOCH) * 1e5)
        self._streams: dict[Any, _Stream] = {}
        self.chart_size = chart_size        # (north extent, east extent) m of the chart, or None
        self.failsafe_timeout = params.failsafe_timeout
        self.failsafe_action = params.failsafe_action
        self.failsafe_active = False
        self.last_gcs_heartbeat: float | None = None
        self.intervals = dict(DEFAULT_INTERVALS)
        self.next_due: dict[str, float] = {k: 0.0 for k in DEFAULT_INTERVALS}
        self.last_wall_heartbeat = -math.inf
        self.api: VehicleApi | None = None
        self.mission: MissionServer | None = None
        self.params_table: ParamTable | None = None
        self.status: VehicleStatus | None = None   # the newest frame's (published by the vehicle)
        self.t = 0.0
        self._paths_sent = 0
        self.sent = 0
        self.datagrams_in = 0               # UDP datagrams / TCP reads from ground stations
        self._datagrams_out_closed = 0      # per-peer sends of transports already closed
        self.received: Counter = Counter()
        self.rejects: Counter = Counter()
        self.security: Counter = Counter()
        self.commands: Counter = Counter()        # "MAV_CMD_...:MAV_RESULT_..." of every COMMAND_ACK sent
        self.command_acks: Counter = Counter()    # COMMAND_ACKs sent, by MAV_RESULT (refusals included)
        self.mission_acks: Counter = Counter()    # MISSION_ACKs sent, by MAV_MISSION_RESULT
        self.failsafe_events = 0
        self.encode_errors: Counter = Counter()

    # -- wiring ---------------------------------------------------------------------------------
    def attach(self, api: VehicleApi) -> None:
        """Connect to the vessel through its command API: its mission, its parameters and ours."""
        self.api = api
        items = tuple(self._item(c) for c in api.mission())
        self.mission = MissionServer(items, system_id=self.sysid, component_id=self.compid,
                                     max_items=self.params.max_mission_items, item_timeout=self.params.mission_timeout,
                                     retries=self.params.mission_retries, position_check=self._on_chart,
                                     mission_check=self._check_mission)
        self.params_table = collect(api.parameters(), self.parameters())

    def parameters(self) -> list[Param]:
        """The link's own tunables: the GCS failsafe."""

        def set_fs_action(v: float) -> None:
            if v != int(v):
                raise ValueError("must be 0, 1 or 2")
            self.failsafe_action = ("none", "hold", "rtl")[int(round(v))]

        return [
            Param("FS_GCS_TIMEOUT", lambda: self.failsafe_timeout, lambda v: setattr(self, "failsafe_timeout", v),
                  1.0, 120.0, "no GCS heartbeat for this long in AUTO triggers the failsafe", "s"),
            Param("FS_GCS_ACTION", lambda: float(("none", "hold", "rtl").index(self.failsafe_action)), set_fs_action,
                  0.0, 2.0, "GCS failsafe action: 0 none, 1 hold, 2 return to launch"),
        ]

    def _item(self, c: MissionCommand) -> MissionItem:
        """A stored command as a MISSION_ITEM_INT (for a mission the vessel started with)."""
        lat = lon = 0.0
        if c.position is not None:
            lat, lon = self.geo.sea_level_to_geodetic(c.north, c.east)
        return MissionItem(M.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT, c.command, 1, c.p1, c.p2, c.p3, c.p4,
                           int(round(lat * 1e7)), int(round(lon * 1e7)), 0.0)

    def _command_of(self, it: MissionItem) -> MissionCommand:
        north = east = None
        if has_position(it):
            north, east = self.geo.geodetic_to_sea_level(it.lat, it.lon)
        return MissionCommand(it.command, north, east, it.param1, it.param2, it.param3, it.param4)

    def _check_mission(self, items: tuple[MissionItem, ...]) -> tuple[int, int, str] | None:
        """A complete upload's route through the chart: ``(seq, MAV_MISSION_RESULT, reason)`` or None."""
        return self.api.check_mission(items, self.geo.geodetic_to_sea_level)

    def _on_chart(self, lat: float, lon: float) -> tuple[int, str] | None:
        if self.chart_size is None:
            return None
        n, e = self.geo.geodetic_to_sea_level(lat, lon)
        if not 0.0 <= n <= self.chart_size[0]:
            return M.MAV_MISSION_INVALID_PARAM5_X, f"waypoint {n:.0f} m north is off the chart (0-{self.chart_size[0]:.0f})"
        if not 0.0 <= e <= self.chart_size[1]:
            return M.MAV_MISSION_INVALID_PARAM6_Y, f"waypoint {e:.0f} m east is off the chart (0-{self.chart_size[1]:.0f})"
        return None

    # -- sending --------------------------------------------------------------------------------
    def _send_frame(self, data: bytes) -> None:
        for tr in self.transports:
            tr.send(data)
        if self.mirror is not None:
            self.mirror.send(data)
        self.sent += 1

    def _send(self, name: str, *args: Any) -> None:
        try:
            frame = self.codec.encode(name, *args)
        except Exception as exc:  # a field out of its wire range must cost a message, never the control loop
            self.encode_errors[name] += 1
            if self.encode_errors[name] == 1:
                self.log(f"gcs: {name} not sent: {type(exc).__name__}: {exc}")
            return
        self._send_frame(frame)
        if name == "command_ack":
            cmd, result = _enum_name("MAV_CMD", args[0]), _enum_name("MAV_RESULT", args[1])
            self.command_acks[result] += 1
            self.commands[f"{cmd}:{result}"] += 1
        elif name == "mission_ack":
            self.mission_acks[_enum_name("MAV_MISSION_RESULT", args[2])] += 1

    def forward(self, name: str, *fields: Any) -> None:
        """Encode message ``name`` (e.g. "ais_vessel") with the vessel's ids and send it to every GCS."""
        self._send(name.lower(), *fields)

    def statustext(self, text: str, severity: int = M.MAV_SEVERITY_INFO) -> None:
        self._send("statustext", severity, text[:50].encode())

    def mission_item_reached(self, seq: int) -> None:
        self._send("mission_item_reached", seq)

    # -- telemetry ------------------------------------------------------------------------------
    def _position(self) -> tuple[float, float] | None:
        return None if self.status is None else self.status.position

    def heartbeat(self) -> None:
        st = self.status
        base = MODE_FLAGS
        custom, status = int(Mode.HOLD), M.MAV_STATE_STANDBY
        if st is not None:
            custom = int(st.mode)
            base |= st.mode_flags
            if st.armed:
                base |= M.MAV_MODE_FLAG_SAFETY_ARMED
                status = M.MAV_STATE_ACTIVE
            if self.failsafe_active:
                status = M.MAV_STATE_CRITICAL
        self._send("heartbeat", M.MAV_TYPE_SURFACE_BOAT, M.MAV_AUTOPILOT_GENERIC, base, custom, status)
        self.last_wall_heartbeat = self.clock()

    def _emit(self, name: str) -> None:
        s, t_ms = (None if self.status is None else self.status.nav), int(round(self.t * 1000))
        own = {"HEARTBEAT": self.heartbeat, "MISSION_CURRENT": self._mission_current, "SYS_STATUS": self._sys_status,
               "HOME_POSITION": self._home, "ESC_TELEMETRY_1_TO_4": self._esc_telemetry}.get(name)
        if own is not None:  # messages that need no navigation state
            own()
            return
        if s is None:
            return
        vn = s.u * math.cos(s.psi) - s.v * math.sin(s.psi)
        ve = s.u * math.sin(s.psi) + s.v * math.cos(s.psi)
        if name == "LOCAL_POSITION_NED":
            self._send("local_position_ned", t_ms, s.x, s.y, 0.0, vn, ve, 0.0)
        elif name == "ATTITUDE":
            self._send("attitude", t_ms, 0.0, 0.0, s.psi, 0.0, 0.0, s.r)
        elif name in ("GLOBAL_POSITION_INT", "GPS_RAW_INT"):
            lat, lon = self.geo.sea_level_to_geodetic(s.x, s.y)
            hdg = int(round(math.degrees(s.psi) % 360.0 * 100)) % 36000
            if name == "GLOBAL_POSITION_INT":
                self._send("global_position_int", t_ms, int(round(lat * 1e7)), int(round(lon * 1e7)),
                           int(round(self.geo.alt0 * 1000)), 0, int(round(vn * 100)), int(round(ve * 100)), 0, hdg)
            else:
                cog = int(round(math.degrees(math.atan2(ve, vn)) % 360.0 * 100)) % 36000
                eph = min(int(round(s.position_std * 100)), 65534)
                self._send("gps_raw_int", int(round(self.t * 1e6)), 3, int(round(lat * 1e7)), int(round(lon * 1e7)),
                           int(round(self.geo.alt0 * 1000)), eph, 65535, int(round(math.hypot(vn, ve) * 100)), cog, 255)
        elif name == "VFR_HUD":
            thr = 0  # VFR_HUD's throttle is 0-100 %: the mean of the two thrusters' magnitudes
            cmd = self.status.thrust
            if cmd is not None:
                thr = int(round(50.0 * (abs(cmd[0]) + abs(cmd[1]))))
            self._send("vfr_hud", 0.0, math.hypot(vn, ve), int(round(math.degrees(s.psi) % 360.0)) % 360,
                       max(0, min(100, thr)), 0.0, 0.0)
        elif name == "ACTUATOR_OUTPUT_STATUS":
            cmd = self.status.thrust
            if cmd is not None:
                act = [cmd[0], cmd[1]] + [0.0] * 30
                self._send("actuator_output_status", int(round(self.t * 1e6)), 0b11, act)

    def _esc_telemetry(self) -> None:
        """ESC_TELEMETRY_1_TO_4 from the newest ESC Status of each thruster (CAN path only), in the
        message's units: degC, cV, cA, mAh, rpm (magnitude), Status transfers received."""
        rows = self.api.esc_telemetry() if self.api is not None else []
        if not rows:
            return
        rows = (rows + [None] * 4)[:4]

        def col(key: str, scale: float, offset: float = 0.0, top: int = 65535) -> list[int]:
            return [0 if r is None else max(0, min(top, int(round((r[key] + offset) * scale)))) for r in rows]

        self._send("esc_telemetry_1_to_4", col("temperature", 1.0, -273.15, 255), col("voltage", 100.0),
                   col("current", 100.0), [0] * 4, [0 if r is None else min(65535, abs(int(r["rpm"]))) for r in rows],
                   [0 if r is None else int(r["count"]) % 65536 for r in rows])

    def _mission_current(self) -> None:
        st = self.status
        if st is None:
            total = len(self.mission.items) if self.mission is not None else 0
            state = M.MISSION_STATE_NOT_STARTED if total else M.MISSION_STATE_NO_MISSION
            self._send("mission_current", 0, total, state, 0)
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
        self._send("mission_current", min(st.mission_current, max(total - 1, 0)), total, state, 1 if auto else 0)

    def _sys_status(self) -> None:
        st = self.status
        s = None if st is None else st.nav
        present = (M.MAV_SYS_STATUS_SENSOR_3D_GYRO | M.MAV_SYS_STATUS_SENSOR_3D_MAG | M.MAV_SYS_STATUS_SENSOR_GPS
                   | M.MAV_SYS_STATUS_SENSOR_XY_POSITION_CONTROL | M.MAV_SYS_STATUS_AHRS
                   | M.MAV_SYS_STATUS_SENSOR_MOTOR_OUTPUTS)
        health = 0
        if s is not None:
            health |= M.MAV_SYS_STATUS_SENSOR_3D_GYRO | M.MAV_SYS_STATUS_SENSOR_3D_MAG | M.MAV_SYS_STATUS_AHRS
            if s.position_std < 3.0:
                health |= M.MAV_SYS_STATUS_SENSOR_GPS
        if st is not None and st.behaviour in (Behaviour.PLANNED, Behaviour.COMPLETE, Behaviour.RETURNING):
            health |= M.MAV_SYS_STATUS_SENSOR_XY_POSITION_CONTROL  # the planner delivers local paths
        health |= M.MAV_SYS_STATUS_SENSOR_MOTOR_OUTPUTS
        errors = min(sum(self.rejects.values()), 65535)
        self._send("sys_status", present, present, health, 0, 0, -1, -1, 0, errors, 0, 0, 0, 0)

    def _home(self) -> None:
        home = None if self.status is None else self.status.home
        if home is None:
            return
        lat, lon = self.geo.sea_level_to_geodetic(*home)
        self._send("home_position", int(round(lat * 1e7)), int(round(lon * 1e7)), int(round(self.geo.alt0 * 1000)),
                   float(home[0]), float(home[1]), 0.0, [1.0, 0.0, 0.0, 0.0], 0.0, 0.0, 0.0,
                   int(round(self.t * 1e6)))

    def _trajectory(self) -> None:
        st = self.status
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
        self._send("trajectory_representation_waypoints", int(round(self.t * 1e6)), n, xs, ys, [0.0] * n + [math.nan] * (5 - n),
                   nan5, nan5, nan5, nan5, nan5, nan5, nan5, nan5, [M.MAV_CMD_NAV_WAYPOINT] * n + [65535] * (5 - n))

    def on_frame(self, status: VehicleStatus) -> None:
        """Per control frame: the streams that are due at the frame's simulated time, progress events."""
        try:
            self._on_frame(status)
        except Exception as exc:  # telemetry must never stop the control loop
            self._internal_error("on_frame", exc)

    def _internal_error(self, where: str, exc: Exception) -> None:
        self.encode_errors[where] += 1
        if self.encode_errors[where] == 1:
            self.log(f"gcs: {where}: {type(exc).__name__}: {exc}")

    def _on_frame(self, status: VehicleStatus) -> None:
        self.t, self.status = status.t, status
        t = status.t
        for seq in status.reached:
            self.mission_item_reached(seq)
            self._mission_current()
        if status.changed:
            self.heartbeat()
            self._mission_current()
        for name, interval in self.intervals.items():
            if interval <= 0:
                continue
            if t + 1e-9 >= self.next_due[name] or self.next_due[name] - t > interval + 1.0:
                self.next_due[name] = t + interval
                self._emit(name)
        self._trajectory()

    # -- receiving ------------------------------------------------------------------------------
    def service(self) -> None:
        """Between frames: read every transport, answer, run timeouts and the failsafe."""
        try:
            self._service()
        except Exception as exc:  # e.g. a socket error: the control loop goes on
            self._internal_error("service", exc)

    def _service(self) -> None:
        now = self.clock()
        for tr in self.transports:
            for peer, data in tr.receive():
                if tr.stream and not data:
                    self._streams.pop(peer, None)
                    continue
                self.datagrams_in += 1
                stream = self._streams.get(peer) if tr.stream else None
                if stream is None:
                    stream = _Stream(self.key)
                    if tr.stream:
                        self._streams[peer] = stream
                    elif "udp" not in self._streams:
                        self._streams["udp"] = stream
                    else:
                        stream = self._streams["udp"]  # datagrams: one parser, signing state shared
                msgs, rejects = stream.parse(data, keep=tr.stream)
                for r in rejects:
                    self.rejects[r] += 1
                if msgs:
                    tr.heard(peer)
                for m in msgs:
                    if self.mirror is not None:
                        self.mirror.send(bytes(m.get_msgbuf()))
                    try:
                        self._handle(m, now)
                    except Exception as exc:  # absurd fields must never stop the boat
                        self.rejects["handler_error"] += 1
                        self.log(f"gcs: {m.get_type()} dropped: {type(exc).__name__}: {exc}")
        if self.mission is not None:
            for out in self.mission.tick(now):
                self._send(out.name, *out.args)
            self._mission_events()
        self._failsafe(now)
        if self.api is not None and now - self.last_wall_heartbeat >= 1.0:
            self.heartbeat()

    def _allowed(self, m: Any, kind: str) -> bool:
        if kind not in WRITES:
            return True
        if self.params.allowed_sysids and m.get_srcSystem() not in self.params.allowed_sysids:
            self.security["not_allowed_sysid"] += 1
            return False
        if self.key is not None and not getattr(m, "_signed", False):
            signed_flag = m.get_header().incompat_flags & mavlink2.MAVLINK_IFLAG_SIGNED
            self.security["bad_signature" if signed_flag else "unsigned"] += 1
            return False
        return True

    def _refuse(self, m: Any, kind: str) -> None:
        src = (m.get_srcSystem(), m.get_srcComponent())
        if kind in ("COMMAND_LONG", "COMMAND_INT"):
            self._send("command_ack", m.command, M.MAV_RESULT_DENIED, 0, 0, src[0], src[1])
        elif kind in MISSION_WRITES:
            self._send("mission_ack", src[0], src[1], M.MAV_MISSION_DENIED, getattr(m, "mission_type", 0))

    def _handle(self, m: Any, now: float) -> None:
        kind = m.get_type()
        self.received[kind] += 1
        if m.get_srcSystem() == self.sysid and m.get_srcComponent() == self.compid:
            return  # our own frames looped back
        if kind == "HEARTBEAT":
            if m.type == M.MAV_TYPE_GCS and (self.key is None or getattr(m, "_signed", False)):
                self.last_gcs_heartbeat = now
            return
        if not self._allowed(m, kind):
            self._refuse(m, kind)
            return
        if kind.startswith("MISSION_") and self.mission is not None:
            for out in self.mission.handle(m, now):
                self._send(out.name, *out.args)
            self._mission_events()
        elif kind in ("COMMAND_LONG", "COMMAND_INT"):
            self._command(m, kind)
        elif kind == "SET_MODE":
            if m.target_system == self.sysid and m.base_mode & M.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED:
                self._set_mode(m.custom_mode)
        elif kind.startswith("PARAM_"):
            self._param(m, kind)
        elif kind == "MANUAL_CONTROL":
            if m.target in (0, self.sysid) and self.api is not None:
                clip = lambda v: max(-1.0, min(1.0, v / 1000.0))  # noqa: E731
                self.api.manual_input(clip(m.x), clip(m.r), now)
        elif kind == "SET_POSITION_TARGET_GLOBAL_INT":
            if m.target_system in (0, self.sysid) and self.api is not None:
                self._position_target(m)
        elif kind == "PING":
            # The ping protocol (mavlink.io/en/services/ping.html): a request has target 0/0; the reply
            # echoes time_usec and seq, addressed to the sender.
            if m.target_system == 0 and m.target_component == 0:
                self._send("ping", m.time_usec, m.seq, m.get_srcSystem(), m.get_srcComponent())
        elif kind == "REQUEST_DATA_STREAM":
            if m.target_system in (0, self.sysid):
                self._data_stream(m.req_stream_id, m.req_message_rate, m.start_stop)

    def _mission_events(self) -> None:
        for ev in self.mission.take_events():
            if ev.kind == "replaced":
                commands = tuple(self._command_of(it) for it in ev.items)
                self.api.replace_mission(commands)
                skipped = sum(c.command in mc.STORED_ONLY for c in commands)
                self.statustext((f"mission: {len(commands)} items accepted"
                                 + (f" ({skipped} stored, not executed)" if skipped else ""))
                                if commands else "mission cleared")
                self._mission_current()
            elif ev.kind == "set_current":
                self.api.set_mission_current(ev.seq)
                self._mission_current()
            elif ev.kind == "rejected" and self.mission.last_reject is not None:
                seq, why = self.mission.last_reject
                self.statustext(f"mission item {seq} rejected: {why}", M.MAV_SEVERITY_WARNING)

    # -- commands -------------------------------------------------------------------------------
    def _set_mode(self, custom_mode: float) -> tuple[int, str]:
        try:
            mode = Mode(int(custom_mode))
        except (ValueError, OverflowError):
            return M.MAV_RESULT_DENIED, f"unknown mode {custom_mode}"
        r = self.api.set_mode(mode)
        ok, why = r.ok, r.text
        if ok:
            self.failsafe_active = False
            self.statustext(f"mode {mode.name}")
        return (M.MAV_RESULT_ACCEPTED if ok else M.MAV_RESULT_DENIED), why

    def _command(self, m: Any, kind: str) -> None:
        if m.target_system not in (0, self.sysid) or m.target_component not in (0, self.compid):
            return
        src = (m.get_srcSystem(), m.get_srcComponent())
        p = [m.param1, m.param2, m.param3, m.param4]
        if kind == "COMMAND_INT":
            x5, y6 = m.x * 1e-7, m.y * 1e-7
        else:
            x5, y6 = m.param5, m.param6
        result, why = self._execute(int(m.command), p, x5, y6)
        self._send("command_ack", m.command, result, 0, 0, src[0], src[1])
        if result != M.MAV_RESULT_ACCEPTED and why:
            self.statustext(why, M.MAV_SEVERITY_WARNING)

    @staticmethod
    def _ack_of(r: Result) -> tuple[int, str]:
        if r.ok:
            return M.MAV_RESULT_ACCEPTED, r.text
        return (M.MAV_RESULT_TEMPORARILY_REJECTED if r.temporary else M.MAV_RESULT_DENIED), r.text

    def _execute(self, cmd: int, p: list[float], x5: float, y6: float) -> tuple[int, str]:
        """One COMMAND_LONG/COMMAND_INT: (MAV_RESULT, why) from the handler registered for its id."""
        handler = self._COMMANDS.get(cmd)
        if handler is None or self.api is None:
            return M.MAV_RESULT_UNSUPPORTED, ""
        return handler(self, p, x5, y6)

    def _cmd_arm(self, p: list[float], x5: float, y6: float) -> tuple[int, str]:
        if not _finite(p[0]) or p[0] not in (0.0, 1.0):
            return M.MAV_RESULT_DENIED, "arm: param1 must be 0 or 1"
        r = self.api.arm(p[0] == 1.0)
        if r.ok:
            self.statustext(r.text)
        return self._ack_of(r)

    def _cmd_set_mode(self, p: list[float], x5: float, y6: float) -> tuple[int, str]:
        if not _finite(p[0]) or not _finite(p[1]) or not int(p[0]) & M.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED:
            return M.MAV_RESULT_DENIED, "set mode: custom mode flag (param1) and mode (param2) needed"
        if _finite(p[2]) and p[2] != 0.0:
            # Our modes have no sub-mode. A (main, sub) pair is another autopilot's numbering (PX4's
            # AUTO.MISSION is (4, 4), as MAVSDK sends to a non-ArduPilot vehicle): read as Rover's
            # custom mode 4 it would silently mean HOLD, so refuse it.
            return M.MAV_RESULT_DENIED, f"set mode: no sub-mode {p[2]:g} (Rover modes: param2 only)"
        return self._set_mode(p[1])

    def _cmd_mission_start(self, p: list[float], x5: float, y6: float) -> tuple[int, str]:
        r = self.api.start_mission(int(p[0]) if _finite(p[0]) else 0)
        if r.ok:
            self.failsafe_active = False
        return self._ack_of(r)

    def _cmd_pause_continue(self, p: list[float], x5: float, y6: float) -> tuple[int, str]:
        return self._set_mode(Mode.HOLD if (_finite(p[0]) and p[0] == 0.0) else Mode.AUTO)

    def _cmd_change_speed(self, p: list[float], x5: float, y6: float) -> tuple[int, str]:
        speed = p[1]
        if not _finite(speed) or speed == -1.0:
            return M.MAV_RESULT_ACCEPTED, "speed unchanged"
        return self._ack_of(self.api.set_speed(float(speed)))

    def _goto(self, lat: float, lon: float, what: str) -> tuple[int, str]:
        if not (_finite(lat) and _finite(lon)) or not -90 <= lat <= 90 or not -180 <= lon <= 180 or \
                (lat == 0.0 and lon == 0.0):
            return M.MAV_RESULT_DENIED, f"{what}: bad latitude/longitude"
        if self._on_chart(lat, lon) is not None:
            return M.MAV_RESULT_DENIED, f"{what}: target off the chart"
        r = self.api.goto(*self.geo.geodetic_to_sea_level(lat, lon))
        if r.ok:
            self.failsafe_active = False
        return self._ack_of(r)

    def _cmd_reposition(self, p: list[float], x5: float, y6: float) -> tuple[int, str]:
        return self._goto(x5, y6, "reposition")

    def _position_target(self, m: Any) -> None:
        """SET_POSITION_TARGET_GLOBAL_INT: a GUIDED goto (position only; velocity/acceleration ignored)."""
        if m.type_mask & POSITION_IGNORED == POSITION_IGNORED:
            return
        code, why = self._goto(m.lat_int * 1e-7, m.lon_int * 1e-7, "position target")
        if code != M.MAV_RESULT_ACCEPTED and why:
            self.statustext(why, M.MAV_SEVERITY_WARNING)

    def _cmd_set_current(self, p: list[float], x5: float, y6: float) -> tuple[int, str]:
        r = self.api.set_mission_current(int(p[0]) if _finite(p[0]) else -1)
        self._mission_current()
        return self._ack_of(r)

    def _cmd_message_interval(self, p: list[float], x5: float, y6: float) -> tuple[int, str]:
        name = ID_NAMES.get(int(p[0])) if _finite(p[0]) else None
        if name is None or not _finite(p[1]):
            return M.MAV_RESULT_DENIED, "message interval: message not streamed here"
        us = p[1]
        if us == -1:
            self.intervals[name] = 0.0
        elif us == 0:
            self.intervals[name] = DEFAULT_INTERVALS[name]
        elif us > 0:
            self.intervals[name] = max(us * 1e-6, 0.01)  # at most once per IMU frame
        else:
            return M.MAV_RESULT_DENIED, "message interval: negative interval"
        self.next_due[name] = self.t
        return M.MAV_RESULT_ACCEPTED, ""

    def _cmd_get_interval(self, p: list[float], x5: float, y6: float) -> tuple[int, str]:
        name = ID_NAMES.get(int(p[0])) if _finite(p[0]) else None
        if name is None:
            return M.MAV_RESULT_DENIED, ""
        iv = self.intervals[name]
        self._send("message_interval", MSG_IDS[name], int(iv * 1e6) if iv > 0 else -1)
        return M.MAV_RESULT_ACCEPTED, ""

    def _cmd_request_message(self, p: list[float], x5: float, y6: float) -> tuple[int, str]:
        name = ON_REQUEST.get(int(p[0])) if _finite(p[0]) else None
        if name is None:
            return M.MAV_RESULT_DENIED, "request message: not available"
        self._on_request(name)
        return M.MAV_RESULT_ACCEPTED, ""

    def _cmd_capabilities(self, p: list[float], x5: float, y6: float) -> tuple[int, str]:
        self._on_request("AUTOPILOT_VERSION")
        return M.MAV_RESULT_ACCEPTED, ""

    def _cmd_home(self, p: list[float], x5: float, y6: float) -> tuple[int, str]:
        self._home()
        return M.MAV_RESULT_ACCEPTED, ""

    _COMMANDS: dict[int, Callable[..., tuple[int, str]]] = {
        M.MAV_CMD_COMPONENT_ARM_DISARM: _cmd_arm,
        M.MAV_CMD_DO_SET_MODE: _cmd_set_mode,
        M.MAV_CMD_MISSION_START: _cmd_mission_start,
        M.MAV_CMD_DO_PAUSE_CONTINUE: _cmd_pause_continue,
        M.MAV_CMD_NAV_LOITER_UNLIM: lambda self, *_: self._set_mode(Mode.LOITER),
        M.MAV_CMD_NAV_RETURN_TO_LAUNCH: lambda self, *_: self._set_mode(Mode.RTL),
        M.MAV_CMD_DO_CHANGE_SPEED: _cmd_change_speed,
        M.MAV_CMD_DO_REPOSITION: _cmd_reposition,
        M.MAV_CMD_DO_SET_MISSION_CURRENT: _cmd_set_current,
        M.MAV_CMD_SET_MESSAGE_INTERVAL: _cmd_message_interval,
        M.MAV_CMD_GET_MESSAGE_INTERVAL: _cmd_get_interval,
        M.MAV_CMD_REQUEST_MESSAGE: _cmd_request_message,
        M.MAV_CMD_REQUEST_AUTOPILOT_CAPABILITIES: _cmd_capabilities,
        M.MAV_CMD_GET_HOME_POSITION: _cmd_home,
    }

    def _on_request(self, name: str) -> None:
        if name == "AUTOPILOT_VERSION":
            caps = (M.MAV_PROTOCOL_CAPABILITY_MISSION_INT | M.MAV_PROTOCOL_CAPABILITY_COMMAND_INT
                    | M.MAV_PROTOCOL_CAPABILITY_MAVLINK2 | M.MAV_PROTOCOL_CAPABILITY_PARAM_FLOAT)
            self._send("autopilot_version", caps, FIRMWARE_VERSION, 0, 0, 0, [0] * 8, [0] * 8, [0] * 8, 0, 0,
                       self.sysid)
        else:
            self._emit(name)

    def _data_stream(self, stream_id: int, rate_hz: int, start: int) -> None:
        names = sorted({n for g in STREAM_GROUPS.values() for n in g}) if stream_id == M.MAV_DATA_STREAM_ALL \
            else STREAM_GROUPS.get(stream_id, ())
        for n in names:
            self.intervals[n] = (1.0 / max(1, min(rate_hz, 100))) if (start and rate_hz > 0) else 0.0
            self.next_due[n] = self.t

    # -- parameters -----------------------------------------------------------------------------
    def _param_value(self, i: int) -> None:
        p = self.params_table.params[i]
        self._send("param_value", p.name.encode(), float(p.get()), M.MAV_PARAM_TYPE_REAL32,
                   len(self.params_table), i)

    def _param(self, m: Any, kind: str) -> None:
        if self.params_table is None or getattr(m, "target_system", self.sysid) not in (0, self.sysid):
            return
        t = self.params_table
        if kind == "PARAM_REQUEST_LIST":
            for i in range(len(t)):
                self._param_value(i)
        elif kind == "PARAM_REQUEST_READ":
            i = m.param_index if m.param_index >= 0 else t.index.get(_text(m.param_id), -1)
            if 0 <= i < len(t):
                self._param_value(i)
        elif kind == "PARAM_SET":
            name = _text(m.param_id)
            ok, why = t.set(name, float(m.param_value))
            if name in t.index:
                self._param_value(t.index[name])  # the value now in force, changed or not
            if not ok:
                self.statustext(why, M.MAV_SEVERITY_WARNING)
            else:
                self.log(f"gcs: {why}")

    # -- failsafe -------------------------------------------------------------------------------
    def _failsafe(self, now: float) -> None:
        st = self.status
        if self.api is None or st is None or self.last_gcs_heartbeat is None or self.failsafe_action == "none":
            return
        lost = now - self.last_gcs_heartbeat > self.failsafe_timeout
        if not lost:
            return
        if self.failsafe_active or not st.armed or st.mode != Mode.AUTO:
            return
        self.failsafe_active = True
        self.failsafe_events += 1
        target = Mode.RTL if self.failsafe_action == "rtl" and st.home is not None else Mode.HOLD
        self.api.set_mode(target)
        self.failsafe_active = True
        msg = f"GCS failsafe: no heartbeat {now - self.last_gcs_heartbeat:.1f}s: {target.name}"
        self.log(f"gcs: {msg}")
        self.statustext(msg, M.MAV_SEVERITY_CRITICAL)
        self.api.record_event(msg)

    # -- end ------------------------------------------------------------------------------------
    def summary(self) -> dict[str, Any]:
        """The link's counters (the autopilot's summary and the run's summary.json carry them as "gcs").

        Datagrams count what crossed the sockets (out: one per peer a frame went to); frames count MAVLink
        messages (in: valid ones only, by type in ``received``; out: each frame once, fanned out or not).
        """
        acks = self.mission_acks
        return {
            "endpoints": [f"{h}:{p}" for h, p in self.addresses],
            "datagrams_in": self.datagrams_in,
            "datagrams_out": self._datagrams_out_closed + sum(tr.sent for tr in self.transports),
            "frames_in": sum(self.received.values()),
            "frames_sent": self.sent,
            "received": dict(self.received),
            "rejects": dict(self.rejects),
            "security_rejects": dict(self.security),
            "signing": self.key is not None,
            "missions_accepted": self.mission.stats.get("uploads_accepted", 0) if self.mission is not None else 0,
            "missions_rejected": sum(n for r, n in acks.items() if r != "MAV_MISSION_ACCEPTED"),
            "mission_acks": dict(acks),
            "mission": dict(self.mission.stats) if self.mission is not None else {},
            "command_acks": dict(self.command_acks),
            "commands": dict(self.commands),
            "param_rejects": self.params_table.rejected if self.params_table is not None else 0,
            "encode_errors": dict(self.encode_errors),
            "failsafe_events": self.failsafe_events,
            "failsafe_active": self.failsafe_active,
        }

    def close(self) -> None:
        for tr in self.transports:
            self._datagrams_out_closed += tr.sent
            tr.close()
        self.transports = []
        if getattr(self, "mirror", None) is not None:
            self.mirror.close()
            self.mirror = None
