"""The vessel computer's end of the HIL MAVLink link: sensor frames in, thruster commands out.

The simulator sends one datagram per IMU period holding HIL_SENSOR and, when due, HIL_GPS,
HIL_STATE_QUATERNION, ODOMETRY (DVL) and OBSTACLE_DISTANCE (range sensor). This end decodes it into a :class:`SensorFrame` in SI
units and NED, converting GPS latitude/longitude with the shared geodesy. HIL_STATE_QUATERNION is
the truth: it is dropped here and counted, never used for control. Commands go back as
HIL_ACTUATOR_CONTROLS whose ``time_usec`` echoes the sensor frame they answer (the lockstep
protocol of docs/simulator.md).

AIS_VESSEL reports of other ships (from the simulator's AIS stand-in, or any other source on the
link) are decoded into :class:`~autopilot_bridge.ais_tracking.AisReport` and queued for the
tracker (:meth:`HilLink.take_ais`), stamped with the newest sensor time. AIS_VESSEL from the
simulator's truth component is the traffic truth: dropped and counted like HIL_STATE_QUATERNION.
"""

from __future__ import annotations

import math
from collections import Counter
from dataclasses import dataclass

from autopilot_bridge.ais_tracking import AisReport
from common.geodesy import LocalFrame
from common.mavlink import MAV_TYPE, Codec
from common.udp import UdpEndpoint

TAKEN = ("HIL_SENSOR", "HIL_GPS", "ODOMETRY", "OBSTACLE_DISTANCE", "HIL_STATE_QUATERNION", "AIS_VESSEL")
UINT16_MAX = 65535


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
class SensorFrame:
    """One decoded sensor datagram at simulated time ``t`` (s)."""

    time_usec: int
    yaw_rate: float | None       # rad/s, gyro z (includes bias)
    heading: float | None        # rad, from the magnetometer and the declination
    gps: GpsFix | None           # None when no fix was due; see gps_dropout
    gps_dropout: bool            # a HIL_GPS arrived with fix_type < 3
    dvl: tuple[float, float] | None  # body velocity over ground (u, v), m/s
    scan: RangeScan | None = None    # range sensor, when a scan was due

    @property
    def t(self) -> float:
        return self.time_usec * 1e-6


class HilLink:
    """UDP endpoint + MAVLink codec of the vessel computer's HIL link."""

    def __init__(self, listen: str, actuators_to: tuple[str, ...], geo: LocalFrame, *, declination: float = 0.0,
                 system_id: int = 1, component_id: int = 1, send_loss: float = 0.0, recv_loss: float = 0.0,
                 loss_seed: int = 0, extra_destinations: tuple[str, ...] = (), truth_component_id: int = 52) -> None:
        self.ep = UdpEndpoint(listen, list(actuators_to) + list(extra_destinations),
                              send_loss=send_loss, recv_loss=recv_loss, loss_seed=loss_seed)
        self.codec = Codec(system_id, component_id, accept=TAKEN)
        self.geo = geo
        self.declination = declination
        self.rejects: Counter = Counter()
        self.truth_ignored = 0
        self.frames = 0
        self.commands_sent = 0
        self.truth_component_id = truth_component_id
        self.ais: list[AisReport] = []
        self.ais_received = 0
        self.last_t = 0.0

    @property
    def address(self) -> tuple[str, int]:
        return self.ep.address

    def decode(self, datagram: bytes) -> SensorFrame | None:
        """The sensor frame in one datagram, or None (rejects counted by reason)."""
        msgs, rejects = self.codec.decode(datagram)
        for r in rejects:
            self.rejects[r] += 1
        sensor = gps = odo = obstacles = None
        ais = []
        for m in msgs:
            kind = m.get_type()
            if kind == "AIS_VESSEL":
                if m.get_srcComponent() == self.truth_component_id:
                    self.truth_ignored += 1
                else:
                    ais.append(m)
            elif kind == "HIL_SENSOR":
                sensor = m
            elif kind == "HIL_GPS":
                gps = m
            elif kind == "ODOMETRY":
                odo = m
            elif kind == "OBSTACLE_DISTANCE":
                obstacles = m
            else:  # HIL_STATE_QUATERNION: the truth is for evaluation only
                self.truth_ignored += 1
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
        if math.isfinite(sensor.xmag) and math.isfinite(sensor.ymag) and (sensor.xmag or sensor.ymag):
            heading = math.atan2(-sensor.ymag, sensor.xmag) + self.declination
        yaw_rate = float(sensor.zgyro) if math.isfinite(sensor.zgyro) else None
        fix, dropout = None, False
        if gps is not None:
            if gps.fix_type >= 3:
                north, east = self.geo.geodetic_to_sea_level(gps.lat * 1e-7, gps.lon * 1e-7)
                fix = GpsFix(north, east, gps.vn * 0.01, gps.ve * 0.01)
            else:
                dropout = True
        dvl = None
        if odo is not None and odo.child_frame_id == MAV_TYPE.MAV_FRAME_BODY_FRD:
            if math.isfinite(odo.vx) and math.isfinite(odo.vy):
                dvl = (float(odo.vx), float(odo.vy))
        scan = self._scan(obstacles) if obstacles is not None else None
        self.frames += 1
        return SensorFrame(int(sensor.time_usec), yaw_rate, heading, fix, dropout, dvl, scan)

    def _scan(self, m) -> RangeScan | None:
        """OBSTACLE_DISTANCE per the MAVLink spec: cm; max_distance + 1 = nothing; UINT16_MAX = unused."""
        if m.frame != MAV_TYPE.MAV_FRAME_BODY_FRD or m.max_distance <= m.min_distance:
            self.rejects["obstacle_distance_unsupported"] += 1
            return None
        inc = m.increment_f if m.increment_f > 0 else float(m.increment)
        if inc <= 0:
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
        first = self.ep.recv(timeout=timeout)
        if first is None:
            return []
        out = []
        for datagram in [first, *self.ep.drain()]:
            frame = self.decode(datagram)
            if frame is not None:
                out.append(frame)
        return out

    def take_ais(self) -> list[AisReport]:
        """The AIS reports decoded since the last call, oldest first."""
        out, self.ais = self.ais, []
        return out

    def send_controls(self, time_usec: int, port: float, stdb: float, armed: bool = True) -> None:
        """HIL_ACTUATOR_CONTROLS answering the frame at ``time_usec``: controls[0] port, [1] starboard."""
        controls = [float(port), float(stdb)] + [0.0] * 14
        mode = MAV_TYPE.MAV_MODE_FLAG_SAFETY_ARMED if armed else 0
        self.ep.send(self.codec.encode("hil_actuator_controls", time_usec, controls, mode, 0))
        self.commands_sent += 1

    def send_raw(self, data: bytes) -> None:
        self.ep.send(data)

    def close(self) -> None:
        self.ep.close()


def _ais_report(m, t: float) -> AisReport:
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
