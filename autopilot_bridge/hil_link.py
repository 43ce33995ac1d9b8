"""The vessel computer's end of the HIL MAVLink link: sensor frames in, thruster commands out.

The simulator sends one datagram per IMU period holding HIL_SENSOR and, when due, HIL_GPS,
HIL_STATE_QUATERNION, ODOMETRY (DVL) and OBSTACLE_DISTANCE (range sensor). This end decodes it into a
:class:`SensorFrame` in SI units and NED, converting GPS latitude/longitude with the shared geodesy.
HIL_STATE_QUATERNION is the truth: it is dropped here and counted, never used for control. Commands go back as
HIL_ACTUATOR_CONTROLS whose ``time_usec`` echoes the sensor frame they answer (the lockstep
protocol of docs/simulator.md).

AIS_VESSEL reports of other ships (from the simulator's AIS stand-in, or any other source on the
link) are decoded into :class:`~autopilot_bridge.ais_tracking.AisReport` and queued for the
tracker (:meth:`HilLink.take_ais`), stamped with the newest sensor time. AIS_VESSEL from the
simulator's truth component is the traffic truth: dropped and counted like HIL_STATE_QUATERNION.

Only the simulator, only plausible numbers (docs/security.md): sensor messages count only when
they carry the simulator's system and component id (``sim_ids``) and, with ``sensors_from``,
come from the simulator's socket; every value is checked finite and in a physical range before it
reaches navigation (an implausible measurement is dropped, the rest of the frame kept); and a
frame's time must move forward by at most ``max_time_step`` from the last accepted one. A frame
off that timeline is refused unless :data:`TIMELINE_CONFIRM` consecutive frames agree on the new
timeline (a restarted simulator, or a long gap): one forged future or past frame can neither
stall lockstep nor reset navigation. Every refusal is counted in :attr:`HilLink.rejects`.
"""

from __future__ import annotations

import math
import time
from collections import Counter
from dataclasses import dataclass
from typing import NotRequired, Protocol, TypedDict

from autopilot_bridge.ais_tracking import AisReport
from common.geodesy import LocalFrame
from common.mavlink import MAV_TYPE, Codec, MavFields
from common.udp import BusyPoll, LossCounts, UdpEndpoint

TAKEN = ("HIL_SENSOR", "HIL_GPS", "ODOMETRY", "OBSTACLE_DISTANCE", "HIL_STATE_QUATERNION", "AIS_VESSEL",
         "BATTERY_STATUS")
UINT16_MAX = 65535

# Plausibility limits of a surface vessel's sensors (far beyond what the hull can do, far below
# what breaks the filter).
MAX_YAW_RATE = 10.0           # rad/s, gyro z
MAX_MAG_GAUSS = 10.0          # magnetometer field magnitude (Earth: ~0.5 gauss)
MAX_GPS_DISTANCE = 100e3      # m from the NED origin
MAX_SPEED = 50.0              # m/s, GPS ground speed per axis and DVL velocity
MAX_ACCEL = 16.0 * 9.80665    # m/s^2 per axis: a 16 g accelerometer's range
MAX_PACK_VOLTAGE = 100.0      # V (24S LiPo: ~100 V)
MAX_PACK_CURRENT = 320.0      # A (BATTERY_STATUS's int16 cA ends at 327 A)
HIL_SENSOR_ACCEL = 0b111      # fields_updated bits of xacc, yacc, zacc
TIMELINE_CONFIRM = 3          # consecutive consistent frames that establish a new timeline
MAX_DATAGRAMS_PER_RECEIVE = 256
# Real time: a vessel computer that comes back to its socket more than this late (wall s: it was paused, by
# SIGSTOP, a debugger, a starved VM) has stalled; of the frames that queued meanwhile only those within
# this much simulated time of the newest are acted on (issue 31), the rest are skipped and counted.
MAX_BEHIND_S = 0.25
STALLS_KEPT = 100

# Refusal reasons counted in HilLink.rejects besides the codec's framing reasons.
WRONG_SOURCE_ID = "wrong_source_id"
TIME_JUMP = "time_jump"            # a frame off the current timeline (forward beyond max_time_step, or back)
IMPLAUSIBLE = "implausible_"       # + gyro, compass, gps, dvl, range: a value dropped from a frame
NONFINITE_COMMAND = "nonfinite_command"  # a NaN/inf thruster command replaced by 0 (stop)


@dataclass(frozen=True)
class GpsFix:
    north: float        # m
    east: float         # m
    vn: float           # m/s over ground
    ve: float           # m/s


@dataclass(frozen=True)
class RangeScan:
    """One OBSTACLE_DISTANCE scan in SI units, body frame (bearings clockwise from the bow)."""

    bearings: tuple[float, ...]   # rad, centre of each sector that reported an obstacle
    ranges: tuple[float, ...]     # m, nearest return in that sector
    max_range: float              # m; sectors with nothing within it are not listed
    sector_width: float = 0.0     # rad; the return lies somewhere across its sector


@dataclass(frozen=True)
class GpsStatus:
    """What the receiver said about itself in one HIL_GPS, in its MAVLink units (a fix or not)."""

    fix_type: int           # GPS_FIX_TYPE: 0 no GPS, 1 no fix, 2 2-D, 3 3-D ...
    satellites: int         # satellites visible (255: unknown)
    lat: int                # degE7 (0 without a fix)
    lon: int                # degE7
    alt: int                # mm
    eph: int                # cm (65535: unknown)
    epv: int                # cm
    vel: int                # cm/s ground speed
    cog: int                # cdeg (65535: unknown)


@dataclass(frozen=True)
class BatteryReading:
    """One BATTERY_STATUS of the pack (SI units; None where the sender said "unknown")."""

    voltage: float                      # V, the pack (sum of the cells)
    cells: tuple[int, ...]              # mV of each cell reported (BATTERY_STATUS voltages)
    current: float | None               # A, discharge positive
    consumed_mah: float | None          # mAh since the start
    energy_j: float | None              # J since the start
    remaining: int | None               # % state of charge
    time_remaining: int                 # s (0: unknown)
    charge_state: int                   # MAV_BATTERY_CHARGE_STATE of the sender


@dataclass(frozen=True)
class SensorFrame:
    """One decoded sensor datagram at simulated time ``t`` (s)."""

    time_usec: int
    yaw_rate: float | None       # rad/s, gyro z (includes bias)
    heading: float | None        # rad, from the magnetometer and the declination
    gps: GpsFix | None           # None when no fix was due; see gps_dropout
    gps_dropout: bool            # a HIL_GPS arrived with fix_type < 3
    dvl: tuple[float, float] | None  # body velocity over ground (u, v), m/s
    scan: RangeScan | None = None    # range sensor, when a scan was due
    accel: tuple[float, float, float] | None = None   # m/s^2 specific force (FRD), when plausible
    gps_status: GpsStatus | None = None               # the receiver's fix type and satellites, when HIL_GPS came
    battery: BatteryReading | None = None             # the pack, when a BATTERY_STATUS came

    @property
    def t(self) -> float:
        return self.time_usec * 1e-6


class StallEvent(TypedDict):
    """A stall of the sensor stream: when (s of sensor time) and how long (s)."""

    t_s: float
    length_s: float


class StallSummary(TypedDict):
    count: int
    stale_frames_skipped: int
    events: list[StallEvent]


class LinkSummary(TypedDict):
    """The ``link`` section of the autopilot's summary (docs/security.md): refusals by reason, frames,
    timeline switches, stalls, the peer, the endpoint's counters, and fault injection where on."""

    rejects: dict[str, int]
    frames: int
    truth_ignored: int
    timeline_switches: int
    late_frames: int
    stalls: StallSummary
    sensors_from: str | None
    wrong_source: int
    budget_stops: int
    kernel_drops: int | None
    loss_injected: NotRequired[LossCounts]


class SensorLink(Protocol):
    """What the vessel computer needs of its link to the sensors and thrusters (:class:`HilLink` on UDP;
    a test harness may script frames without sockets)."""

    rejects: Counter[str]
    truth_ignored: int
    busy: BusyPoll | None

    def receive(self, timeout: float) -> list[SensorFrame]: ...

    def take_ais(self) -> list[AisReport]: ...

    def send_controls(self, time_usec: int, port: float, stdb: float, armed: bool = True) -> None: ...


class HilLink:
    """UDP endpoint + MAVLink codec of the vessel computer's HIL link."""

    def __init__(self, ep: UdpEndpoint, codec: Codec, geo: LocalFrame, *, busy: BusyPoll | None = None,
                 declination: float = 0.0, truth_component_id: int = 52, sim_ids: tuple[int, int] | None = None,
                 max_time_step: float = 1.0, late_window: float = 1.0, realtime: bool = False) -> None:
        """The link on a socket and codec built by the assembly (:meth:`open` builds both): ``ep`` is
        the UDP socket the sensor frames arrive on and the actuator commands leave from (the link owns
        and closes it; :func:`only_from` restricts it to the simulator's address); ``codec``: the vessel
        computer's MAVLink ids, accepting :data:`TAKEN`; ``busy``: (lockstep) each wait for a frame polls
        the socket first (None: it sleeps on it).
        ``sim_ids``: (system, component) id of the simulator (None: any); ``max_time_step``: largest
        forward step (s) of sensor time between consecutive accepted frames; ``late_window``: a frame
        at most this far (s) behind the last accepted one is late (reordered), refused without counting
        towards a new timeline; ``realtime``: stalls of this process are detected and skipped (MAX_BEHIND_S)."""
        self.ep = ep
        self.busy = busy
        self.sim_ids = sim_ids
        self.max_step_usec = int(round(max_time_step * 1e6))
        self.late_window_usec = int(round(late_window * 1e6))
        self.late_frames = 0
        self.realtime = realtime
        self._left_at: float | None = None                # wall time the last receive() returned
        self.stalls: list[tuple[float, float]] = []       # (simulated s, wall s), the first STALLS_KEPT
        self.stall_count = 0
        self.stale_frames_skipped = 0
        self.last_usec: int | None = None                # time of the last accepted frame
        self._candidate: tuple[int, int] | None = None   # (last time, frames) of another timeline
        self.timeline_switches = 0
        self.codec = codec
        self.geo = geo
        self.declination = declination
        self.rejects: Counter[str] = Counter()
        self.truth_ignored = 0
        self.frames = 0
        self.commands_sent = 0
        self.truth_component_id = truth_component_id
        self.ais: list[AisReport] = []
        self.ais_received = 0
        self.last_t = 0.0

    @classmethod
    def open(cls, listen: str, actuators_to: tuple[str, ...], geo: LocalFrame, *, system_id: int = 1,
             component_id: int = 1, send_loss: float = 0.0, recv_loss: float = 0.0, loss_seed: int = 0,
             extra_destinations: tuple[str, ...] = (), declination: float = 0.0, truth_component_id: int = 52,
             sim_ids: tuple[int, int] | None = None, sensors_from: str | None = None, max_time_step: float = 1.0,
             busy_poll: float = 0.0, late_window: float = 1.0, realtime: bool = False) -> HilLink:
        """A link with its own socket (bound to ``listen`` "HOST:PORT", sending to ``actuators_to`` and
        ``extra_destinations``, dropping ``send_loss``/``recv_loss`` of the datagrams, seeded by
        ``loss_seed``; only from ``sensors_from``, :func:`only_from`) and codec (the vessel computer's
        ``system_id``/``component_id``), polling it up to ``busy_poll`` s (:func:`lockstep_poll`), for
        tests and tools; the vessel computer's assembly builds them itself."""
        ep = UdpEndpoint(listen, list(actuators_to) + list(extra_destinations),
                         send_loss=send_loss, recv_loss=recv_loss, loss_seed=loss_seed)
        try:
            _only_from(ep, sensors_from)
        except ValueError:
            ep.close()
            raise
        return cls(ep, Codec(system_id, component_id, accept=TAKEN), geo, busy=_lockstep_poll(busy_poll),
                   declination=declination, truth_component_id=truth_component_id, sim_ids=sim_ids,
                   max_time_step=max_time_step, late_window=late_window, realtime=realtime)

    @property
    def address(self) -> tuple[str, int]:
        return self.ep.address

    def decode(self, datagram: bytes) -> SensorFrame | None:
        """The sensor frame in one datagram, or None (rejects counted by reason)."""
        # Fields are read only from the frames used: the truth is counted, never decoded.
        frames, rejects = self.codec.frames(datagram)
        for r in rejects:
            self.rejects[r] += 1
        sensor = gps = odo = obstacles = battery = None
        ais = []
        for kind, system, component, fields in frames:
            if kind != "AIS_VESSEL" and self.sim_ids is not None and (system, component) != self.sim_ids:
                self.rejects[WRONG_SOURCE_ID] += 1
                continue
            if kind == "AIS_VESSEL":
                if component == self.truth_component_id:
                    self.truth_ignored += 1
                else:
                    ais.append(fields())
            elif kind == "HIL_SENSOR":
                sensor = fields()
            elif kind == "HIL_GPS":
                gps = fields()
            elif kind == "ODOMETRY":
                odo = fields()
            elif kind == "OBSTACLE_DISTANCE":
                obstacles = fields()
            elif kind == "BATTERY_STATUS":
                battery = fields()
            else:  # HIL_STATE_QUATERNION: the truth is for evaluation only
                self.truth_ignored += 1
        if sensor is not None and not self._on_timeline(int(sensor.time_usec)):
            self.rejects[TIME_JUMP] += 1
            sensor = gps = odo = obstacles = battery = None
            ais = []
        if sensor is not None:
            self.last_t = sensor.time_usec * 1e-6
        for m in ais:
            self.ais.append(_ais_report(m, self.last_t))
            self.ais_received += 1
        if sensor is None:
            if gps is not None or odo is not None:
                self.rejects["frame_without_hil_sensor"] += 1
            return None
        heading = None
        mx, my = float(sensor.xmag), float(sensor.ymag)
        if math.isfinite(mx) and math.isfinite(my) and (mx or my):
            if math.hypot(mx, my) <= MAX_MAG_GAUSS:
                heading = math.atan2(-my, mx) + self.declination
            else:
                self.rejects[IMPLAUSIBLE + "compass"] += 1
        elif not (math.isfinite(mx) and math.isfinite(my)):
            self.rejects[IMPLAUSIBLE + "compass"] += 1
        gyro = float(sensor.zgyro)
        yaw_rate: float | None = gyro
        if not (math.isfinite(gyro) and abs(gyro) <= MAX_YAW_RATE):
            self.rejects[IMPLAUSIBLE + "gyro"] += 1
            yaw_rate = None
        accel = None
        if int(sensor.fields_updated) & HIL_SENSOR_ACCEL == HIL_SENSOR_ACCEL:
            ax, ay, az = float(sensor.xacc), float(sensor.yacc), float(sensor.zacc)
            if abs(ax) <= MAX_ACCEL and abs(ay) <= MAX_ACCEL and abs(az) <= MAX_ACCEL:   # NaN fails these
                accel = (ax, ay, az)
            else:
                self.rejects[IMPLAUSIBLE + "accel"] += 1
        fix, dropout, gps_status = None, False, None
        if gps is not None:
            gps_status = _gps_status(gps)
            if gps.fix_type >= 3:
                fix = self._gps_fix(gps)
            else:
                dropout = True
        dvl = None
        if odo is not None and odo.child_frame_id == MAV_TYPE.MAV_FRAME_BODY_FRD:
            vx, vy = float(odo.vx), float(odo.vy)
            if math.isfinite(vx) and math.isfinite(vy) and abs(vx) <= MAX_SPEED and abs(vy) <= MAX_SPEED:
                dvl = (vx, vy)
            else:
                self.rejects[IMPLAUSIBLE + "dvl"] += 1
        scan = self._scan(obstacles) if obstacles is not None else None
        pack = None
        if battery is not None:
            pack = _battery_reading(battery)
            if pack is None:
                self.rejects[IMPLAUSIBLE + "battery"] += 1
        self.frames += 1
        return SensorFrame(int(sensor.time_usec), yaw_rate, heading, fix, dropout, dvl, scan, accel, gps_status, pack)

    def _on_timeline(self, usec: int) -> bool:
        """Is a frame at ``usec`` on the current timeline (a repeat, or at most max_time_step ahead)?
        Off it, frames are refused until TIMELINE_CONFIRM consecutive ones agree on a new one."""
        last = self.last_usec
        if last is None or 0 <= usec - last <= self.max_step_usec:
            self.last_usec, self._candidate = usec, None
            return True
        c = self._candidate
        if 0 < last - usec <= self.late_window_usec:
            # Late: reordered on the way, unless the same frame comes again and again (a young simulator
            # restarted in lockstep resends its frame 0). Before issue 31, three different delayed frames in
            # a row at 30 % loss with reordering were taken for a new timeline: a spurious switch.
            self.late_frames += 1
            c = (usec, c[1] + 1) if c is not None and c[0] == usec else (usec, 1)
        elif c is not None and 0 <= usec - c[0] <= self.max_step_usec:
            c = (usec, c[1] + 1)
        else:
            c = (usec, 1)
        if c[1] >= TIMELINE_CONFIRM:
            self.last_usec, self._candidate = usec, None
            self.timeline_switches += 1
            return True
        self._candidate = c
        return False

    def _gps_fix(self, gps: MavFields) -> GpsFix | None:
        lat, lon, vn, ve = gps.lat * 1e-7, gps.lon * 1e-7, gps.vn * 0.01, gps.ve * 0.01
        if abs(lat) <= 90.0 and abs(lon) <= 180.0 and abs(vn) <= MAX_SPEED and abs(ve) <= MAX_SPEED:
            north, east = self.geo.geodetic_to_sea_level(lat, lon)
            if math.isfinite(north) and math.isfinite(east) and math.hypot(north, east) <= MAX_GPS_DISTANCE:
                return GpsFix(north, east, vn, ve)
        self.rejects[IMPLAUSIBLE + "gps"] += 1
        return None

    def _scan(self, m: MavFields) -> RangeScan | None:
        """OBSTACLE_DISTANCE per the MAVLink spec: cm; max_distance + 1 = nothing; UINT16_MAX = unused."""
        if m.frame != MAV_TYPE.MAV_FRAME_BODY_FRD or m.max_distance <= m.min_distance:
            self.rejects["obstacle_distance_unsupported"] += 1
            return None
        inc = m.increment_f if m.increment_f > 0 else float(m.increment)
        if not (0 < inc <= 360.0 and math.isfinite(m.angle_offset)):
            self.rejects["obstacle_distance_unsupported"] += 1
            return None
        bearings, ranges = [], []
        for i, d in enumerate(m.distances):
            if d == UINT16_MAX or d > m.max_distance or d < m.min_distance:
                continue
            bearings.append(math.radians(m.angle_offset + i * inc))
            ranges.append(d * 0.01)
        return RangeScan(tuple(bearings), tuple(ranges), m.max_distance * 0.01, math.radians(inc))

    def receive(self, timeout: float) -> list[SensorFrame]:
        """Every sensor frame queued now (waiting up to ``timeout`` s for the first), oldest first."""
        away = time.monotonic() - self._left_at if self._left_at is not None else 0.0
        first = self.ep.recv(timeout=timeout, poll=self.busy)
        if first is None:
            self._left_at = time.monotonic()
            return []
        out = []
        for datagram in [first, *self.ep.drain(limit=MAX_DATAGRAMS_PER_RECEIVE)]:
            frame = self.decode(datagram)
            if frame is not None:
                out.append(frame)
        if self.realtime and away > MAX_BEHIND_S and out:
            out = self._skip_ahead(out, away)
        self._left_at = time.monotonic()
        return out

    def _skip_ahead(self, frames: list[SensorFrame], away: float) -> list[SensorFrame]:
        """After a stall of ``away`` wall seconds: the frames within MAX_BEHIND_S of the newest (the rest
        are stale: acting on them would steer by where the boat was). Counted, and the stall recorded."""
        newest = frames[-1].time_usec
        fresh = [f for f in frames if newest - f.time_usec <= MAX_BEHIND_S * 1e6]
        self.stale_frames_skipped += len(frames) - len(fresh)
        self.stall_count += 1
        if len(self.stalls) < STALLS_KEPT:
            self.stalls.append((newest * 1e-6, away))
        return fresh

    def take_ais(self) -> list[AisReport]:
        """The AIS reports decoded since the last call, oldest first."""
        out, self.ais = self.ais, []
        return out

    def send_controls(self, time_usec: int, port: float, stdb: float, armed: bool = True) -> None:
        """HIL_ACTUATOR_CONTROLS answering the frame at ``time_usec``: controls[0] port, [1] starboard."""
        port, stdb = float(port), float(stdb)
        if not (math.isfinite(port) and math.isfinite(stdb)):
            self.rejects[NONFINITE_COMMAND] += 1  # a numeric fault upstream: stop rather than send NaN
            port = stdb = 0.0
        controls = [port, stdb] + [0.0] * 14
        mode = MAV_TYPE.MAV_MODE_FLAG_SAFETY_ARMED if armed else 0
        self.ep.send(self.codec.encode("hil_actuator_controls", time_usec, controls, mode, 0))
        self.commands_sent += 1

    def summary(self) -> LinkSummary:
        """The link's refusals by reason, its endpoint's (source address, kernel drops) and
        timeline switches (simulator restarts or long gaps accepted); with fault injection on, the
        datagrams it dropped on purpose each way."""
        counters = self.ep.counters()
        out = LinkSummary(
            rejects=dict(sorted(self.rejects.items())), frames=self.frames, truth_ignored=self.truth_ignored,
            timeline_switches=self.timeline_switches, late_frames=self.late_frames,
            stalls=StallSummary(count=self.stall_count, stale_frames_skipped=self.stale_frames_skipped,
                                events=[StallEvent(t_s=round(t, 3), length_s=round(d, 3)) for t, d in self.stalls]),
            sensors_from=None if self.ep.peer is None else f"{self.ep.peer[0]}:{self.ep.peer[1]}",
            wrong_source=counters["wrong_source"], budget_stops=counters["budget_stops"],
            kernel_drops=counters["kernel_drops"])
        if self.ep.send_loss or self.ep.recv_loss:
            out["loss_injected"] = LossCounts(sent=self.ep.sent, dropped_out=self.ep.dropped_out,
                                              received=self.ep.recv_count, dropped_in=self.ep.dropped_in)
        return out

    def send_raw(self, data: bytes) -> None:
        self.ep.send(data)

    def close(self) -> None:
        self.ep.close()


def _gps_status(m: MavFields) -> GpsStatus:
    """HIL_GPS's own account of the fix (its integers clamped to GPS_RAW_INT's field ranges)."""
    def u16(v: int) -> int:
        return max(0, min(UINT16_MAX, int(v)))

    fix = max(0, min(8, int(m.fix_type)))
    if fix < 2:   # no fix: no position
        return GpsStatus(fix, min(255, int(m.satellites_visible)) if fix else 0, 0, 0, 0, UINT16_MAX, UINT16_MAX,
                         0, UINT16_MAX)
    return GpsStatus(fix, min(255, int(m.satellites_visible)), int(m.lat), int(m.lon), int(m.alt), u16(m.eph),
                     u16(m.epv), u16(m.vel), u16(m.cog))


def _battery_reading(m: MavFields) -> BatteryReading | None:
    """BATTERY_STATUS per the MAVLink spec (mV per cell, UINT16_MAX unused; cA, mAh, hJ, % with -1 unknown),
    or None when it is implausible for a boat's pack (no cell, a voltage or current out of range)."""
    every = list(m.voltages) + list(getattr(m, "voltages_ext", None) or [])
    cells = tuple(int(v) for v in every if 0 < int(v) < UINT16_MAX)
    volts = sum(cells) * 1e-3
    if not cells or not 0.0 < volts <= MAX_PACK_VOLTAGE:
        return None
    current = None if m.current_battery == -1 else m.current_battery * 0.01
    if current is not None and abs(current) > MAX_PACK_CURRENT:
        return None
    consumed = None if m.current_consumed == -1 else float(m.current_consumed)
    energy = None if m.energy_consumed == -1 else m.energy_consumed * 100.0
    remaining = None if m.battery_remaining == -1 else max(0, min(100, int(m.battery_remaining)))
    return BatteryReading(volts, cells, current, consumed, energy, remaining, max(0, int(m.time_remaining)),
                          int(getattr(m, "charge_state", 0)))


def _ais_report(m: MavFields, t: float) -> AisReport:
    """AIS_VESSEL in SI units; course/speed None when AIS marks them unavailable (36000, 65535) or
    the flags say they are not valid."""
    flags = int(m.flags)
    cog_ok = m.COG < 36000 and (flags & MAV_TYPE.AIS_FLAGS_VALID_COG or not flags)
    sog_ok = m.velocity < 65535 and (flags & MAV_TYPE.AIS_FLAGS_VALID_VELOCITY or not flags)
    course = math.radians(m.COG * 0.01) if cog_ok else None
    speed = m.velocity * 0.01 if sog_ok else None
    name = m.name if isinstance(m.name, str) else m.name.decode("ascii", "replace")
    return AisReport(t, int(m.MMSI), m.lat * 1e-7, m.lon * 1e-7, course, speed, float(m.dimension_bow),
                     float(m.dimension_stern), float(m.dimension_port), float(m.dimension_starboard),
                     name.rstrip("\x00 "))


def _only_from(ep: UdpEndpoint, sensors_from: str | None) -> None:
    """Restrict the link's socket to the simulator's "HOST:PORT" (None: any address); ValueError with
    one line on an address that cannot be used."""
    if sensors_from:
        try:
            ep.set_peer(sensors_from)
        except (ValueError, OSError) as exc:
            raise ValueError(f"sensors_from {sensors_from!r}: {exc}") from None


def _lockstep_poll(busy_poll: float) -> BusyPoll | None:
    """(lockstep) wait for the next frame polling the socket first, up to ``busy_poll`` s
    (:class:`common.udp.BusyPoll`); None (0): sleep on it."""
    return BusyPoll(busy_poll) if busy_poll > 0 else None
