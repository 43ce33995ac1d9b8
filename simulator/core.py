"""The simulator without sockets: truth, environment, sensors, MAVLink frames and commands.

One *frame* is the period of the IMU (``1 / sensors.imu.rate_hz``), an integer number of RK4
steps of ``sim.dt``. :meth:`SimulatorCore.frame` encodes everything due at the current time as
one datagram (HIL_SENSOR always; HIL_GPS, HIL_STATE_QUATERNION, the DVL's ODOMETRY and the
range sensor's OBSTACLE_DISTANCE when their rate says so); :meth:`SimulatorCore.step` advances the truth by
one frame with the newest command. The socket loops live in :mod:`simulator.server`.
"""

from __future__ import annotations

import math
from collections import Counter
from typing import TYPE_CHECKING, TypedDict

from common.current_sources import NoCurrent, make_current
from common.current_tally import CurrentTally
from common.dronecan_layout import RAW_COMMAND_MAX
from common.geodesy import LocalFrame
from common.mavlink import MAV_TYPE, Codec
from simulator.battery import Pack, ThrusterPower
from simulator.config import SimulatorSettings
from simulator.rangefinder import Rangefinder, WorldMap
from simulator.sensors import Compass, Dvl, G, Gps, Imu, sensor_rngs
from simulator.vessel import State, Vessel, hull_dynamics, hull_rk4_step
from simulator.waves import WaveModel

if TYPE_CHECKING:
    from simulator.traffic import ShipSpec, Traffic

# Rejections counted by the simulator besides the codec's framing reasons.
INVALID_CONTROLS = "invalid_controls"      # NaN/inf control: previous command kept
STALE_TIMES_KEPT = 1000   # stale-command failsafe times kept for the summary (the count is exact)
OUT_OF_STEP = "out_of_step_command"        # lockstep: time_usec is not the current frame's
WRONG_SOURCE_ID = "wrong_source_id"        # a command not from the autopilot's system/component id

HIL_SENSOR_FIELDS = 0x1FF  # bits 0-8: x/y/z acc, x/y/z gyro, x/y/z mag


class BatterySummary(TypedDict):
    """The pack at the end of a run."""

    state_of_charge: float     # 0-1
    voltage_v: float           # V at the terminals
    consumed_mah: float        # mAh
    energy_wh: float           # Wh
    depleted: bool


class TruthState(TypedDict):
    """The truth at one instant: time (s), NED position (m), heading (rad), body velocities (m/s,
    rad/s), latitude and longitude (degrees)."""

    t: float
    x: float
    y: float
    psi: float
    u: float
    v: float
    r: float
    lat: float
    lon: float


class Command:
    """One HIL_ACTUATOR_CONTROLS, validated: normalised port/starboard commands."""

    __slots__ = ("time_usec", "port", "stdb")

    def __init__(self, time_usec: int, port: float, stdb: float) -> None:
        self.time_usec, self.port, self.stdb = time_usec, port, stdb


class _Schedule:
    """Is an output of ``rate_hz`` due at frame n? (integer-safe, no drift)."""

    def __init__(self, rate_hz: float, frame_dt: float) -> None:
        self.k = rate_hz * frame_dt

    def due(self, n: int) -> bool:
        return n == 0 or int(n * self.k + 1e-9) != int((n - 1) * self.k + 1e-9)


def frame_layout(dt: float, imu_rate_hz: float) -> tuple[float, int]:
    """(frame period s, RK4 steps per frame); ValueError('key: problem') if they do not divide."""
    frame_dt = 1.0 / imu_rate_hz
    sub = int(round(frame_dt / dt))
    if sub < 1 or abs(sub * dt - frame_dt) > 1e-9 * max(1.0, frame_dt):
        raise ValueError(f"sensors.imu.rate_hz: the IMU period 1/{imu_rate_hz:g} s must be a whole "
                         f"number of sim.dt = {dt:g} s steps")
    return frame_dt, sub


class SimulatorCore:
    """Truth + sensors + MAVLink encoding for one run."""

    def __init__(self, cfg: SimulatorSettings, world: WorldMap | None = None,
                 traffic: tuple[ShipSpec, ...] = ()) -> None:
        """``traffic``: the ships (``simulator.traffic.ShipSpec``) reported by AIS on the link."""
        self.cfg = cfg
        self.frame_dt, self.substeps = frame_layout(cfg.sim.dt, cfg.sensors.imu.rate_hz)
        self.dt = self.frame_dt / self.substeps
        self.vessel = Vessel(cfg.vessel)
        self.geo = LocalFrame(cfg.geodesy.lat0, cfg.geodesy.lon0, cfg.geodesy.alt0)
        # eq. (13), a uniform current or a file's (common.current_sources): the planner's source too
        self.current = make_current(cfg.current, self.geo) or NoCurrent()
        self.current_felt = CurrentTally()   # the current at the hull, once a frame
        rngs = sensor_rngs(cfg.sim.seed)
        s = cfg.sensors
        self.waves = WaveModel(cfg.waves, cfg.vessel, rngs["waves"])
        self.imu = Imu(s.imu, rngs["imu"], self.frame_dt)
        self.compass = Compass(s.compass, rngs["compass"])
        self.gps = Gps(s.gps, rngs["gps"], rngs["gps_events"], self.geo, self.frame_dt, rngs["gps_satellites"])
        self.dvl = Dvl(s.dvl, rngs["dvl"]) if s.dvl.enabled else None
        self.gps_due = _Schedule(s.gps.rate_hz, self.frame_dt)
        self.truth_due = _Schedule(cfg.sim.truth_rate_hz, self.frame_dt)
        self.dvl_due = _Schedule(s.dvl.rate_hz, self.frame_dt)
        self.rangefinder = (Rangefinder(s.rangefinder, world, rngs["rangefinder"])
                            if world is not None and s.rangefinder.enabled else None)
        self.rangefinder_due = _Schedule(s.rangefinder.rate_hz, self.frame_dt)
        bp = cfg.battery
        self.battery = Pack(bp)
        self.thruster_power = ThrusterPower(cfg.esc, cfg.vessel)
        # Electrical energy (J) of the frames since the pack last drew it: the pack is integrated when
        # its BATTERY_STATUS is due, with the mean power of those frames (a pack changes over minutes).
        self._energy_due, self._frames_due = 0.0, 0
        self.battery_due = _Schedule(bp.rate_hz, self.frame_dt)
        # The only peer whose commands count: the vessel computer's ids from the same configuration.
        self.peer_ids = (cfg.computer.system_id, cfg.computer.component_id)
        i = cfg.sim.initial
        self.state: State = (float(i.x), float(i.y), float(i.psi), float(i.u), float(i.v), float(i.r))
        self.n = 0
        self.controls = (0.0, 0.0)
        self.thrust = (0.0, 0.0)  # N, port and starboard thrust applied now (after the ESC lag)
        tau = cfg.esc.time_constant
        self._lag = math.exp(-self.frame_dt / tau) if tau > 0 else 0.0
        self._int14 = cfg.esc.int14_resolution or cfg.can.actuators == "can"
        self.last_command_t = 0.0
        self.stale = False
        self.stale_command_events = 0
        self.stale_command_times: list[float] = []   # s of simulated time, the first STALE_TIMES_KEPT
        self.commands_received = 0
        self.clamped_controls = 0
        self.messages_sent: Counter = Counter()
        self.rejects: Counter = Counter()
        self.distance = 0.0
        self._env = self._environment(0.0)
        # compile (or load from numba's cache) the hull's kernels now, not in the first timed step
        hull_rk4_step(self.state, self.dt, (0.0, 0.0, 0.0), *self._env, self.vessel.coefficients)
        self.traffic: Traffic | None = None
        if traffic:
            from simulator.traffic import Traffic

            ais = cfg.traffic
            self.traffic = Traffic(tuple(traffic), ais, cfg.sim.seed, self.geo)
            self.truth_codec = Codec(cfg.link.system_id, ais.truth_component_id)
        self.codec = Codec(cfg.link.system_id, cfg.link.component_id, accept=("HIL_ACTUATOR_CONTROLS",))

    # -- time ------------------------------------------------------------------------------
    @property
    def t(self) -> float:
        """Simulated time (s) of the current frame."""
        return self.n * self.frame_dt

    @property
    def time_usec(self) -> int:
        return int(round(self.n * self.frame_dt * 1e6))

    # -- commands --------------------------------------------------------------------------
    def receive(self, datagram: bytes) -> list[Command]:
        """Valid commands in one datagram. A datagram with any invalid part counts as one reject
        (by the first reason); valid commands in it are still returned. Only commands from the
        autopilot's system and component id (``autopilot.system_id``/``component_id``) count."""
        frames, rejects = self.codec.frames(datagram)   # fields read from the frame, no message objects
        if rejects:
            self.rejects[rejects[0]] += 1
        out = []
        for _, system, component, fields in frames:
            if (system, component) != self.peer_ids:
                self.rejects[WRONG_SOURCE_ID] += 1
                continue
            m = fields()
            c = m.controls
            port, stdb = float(c[0]), float(c[1])
            if not (math.isfinite(port) and math.isfinite(stdb)):
                self.rejects[INVALID_CONTROLS] += 1
                continue
            if abs(port) > 1.0 or abs(stdb) > 1.0:
                self.clamped_controls += 1
                port, stdb = max(-1.0, min(1.0, port)), max(-1.0, min(1.0, stdb))
            out.append(Command(int(m.time_usec), port, stdb))
        return out

    def apply(self, cmd: Command) -> None:
        """Make ``cmd`` the newest command (received at the current simulated time).

        With ``esc.int14_resolution`` (always on the CAN path, where commands are int14 anyway) the
        simulated ESCs round to DroneCAN RawCommand's resolution, so MAVLink (float32) and CAN
        commands of the same value drive the same thrust.
        """
        if self._int14:
            self.controls = (_esc_resolution(cmd.port), _esc_resolution(cmd.stdb))
        else:
            self.controls = (cmd.port, cmd.stdb)
        self.last_command_t = self.t
        self.stale = False
        self.commands_received += 1

    def thrusts(self) -> tuple[float, float]:
        """Port and starboard thrust set-points (N) now, after the stale-command failsafe (and none
        from a depleted battery: its BMS has cut the thrusters off)."""
        if self.battery.depleted:
            return 0.0, 0.0
        if self.t - self.last_command_t > self.cfg.sim.stale_command_timeout + 1e-9:
            if not self.stale:
                self.stale = True
                self.stale_command_events += 1
                if len(self.stale_command_times) < STALE_TIMES_KEPT:
                    self.stale_command_times.append(self.t)
            return 0.0, 0.0
        return self.vessel.thrust(self.controls[0]), self.vessel.thrust(self.controls[1])

    # -- truth -----------------------------------------------------------------------------
    def _environment(self, t: float) -> tuple[tuple[float, float, float], tuple[float, float]]:
        """Wave forces (body) and current (north, east) at the present state and time t."""
        s = self.state
        return self.waves.forces(s[2]), self.current.velocity_at(s[0], s[1], t)

    def derivative(self) -> State:
        """State derivative now (with the thrust currently applied)."""
        tau = self.vessel.propulsion(*self.thrust)
        return hull_dynamics(self.state, tau, *self._env, self.vessel.coefficients)

    def step(self) -> None:
        """Advance the truth by one frame: RK4 substeps with thrust held for the frame and waves and
        current evaluated at the start of each substep (they vary over tens of seconds). The thrust
        follows its set-point through the ESC's first-order lag, discretised exactly per frame."""
        (sp, ss), (tp, ts), a = self.thrusts(), self.thrust, self._lag
        self.thrust = (sp + (tp - sp) * a, ss + (ts - ss) * a)
        tau = self.vessel.propulsion(*self.thrust)
        coefficients = self.vessel.coefficients
        power = self.thruster_power
        self._energy_due += power(self.thrust[0]) + power(self.thrust[1])
        self._frames_due += 1
        for k in range(1, self.substeps + 1):
            tau_w, cur = self._env
            x0, y0 = self.state[0], self.state[1]
            self.state = hull_rk4_step(self.state, self.dt, tau, tau_w, cur, coefficients)
            self.distance += math.hypot(self.state[0] - x0, self.state[1] - y0)
            self.waves.advance(self.dt)
            self._env = self._environment(self.n * self.frame_dt + k * self.dt)
        self.current_felt.add(*self._env[1])
        self.n += 1

    # -- output ----------------------------------------------------------------------------
    def frame(self) -> bytes:
        """One datagram with every message due at the current time (HIL_SENSOR always)."""
        x, y, psi, u, v, r = self.state
        t, tu = self.t, self.time_usec
        c, sn = math.cos(psi), math.sin(psi)
        vn, ve = u * c - v * sn, u * sn + v * c
        self.gps.record(t, x, y, vn, ve)
        d = self.derivative()
        ax, ay = d[3] - v * r, d[4] + u * r  # acceleration over ground in body axes
        parts = []
        acc_gyro = self.imu.measure(r, ax, ay)
        mag = self.compass.measure(psi)
        parts.append(self.codec.encode("hil_sensor", tu, *acc_gyro, *mag, 0.0, 0.0, 0.0, 0.0, HIL_SENSOR_FIELDS))
        self.messages_sent["HIL_SENSOR"] += 1
        if self.gps_due.due(self.n):
            parts.append(self.codec.encode("hil_gps", tu, **self.gps.measure(t, self.cfg.geodesy.alt0)))
            self.messages_sent["HIL_GPS"] += 1
        if self.truth_due.due(self.n):
            lat, lon = self.geo.sea_level_to_geodetic(x, y)
            mg = 1000.0 / G
            parts.append(self.codec.encode(
                "hil_state_quaternion", tu, [math.cos(psi / 2), 0.0, 0.0, math.sin(psi / 2)], 0.0, 0.0, r,
                int(round(lat * 1e7)), int(round(lon * 1e7)), int(round(self.cfg.geodesy.alt0 * 1000)),
                _i16(100 * vn), _i16(100 * ve), 0, 0, 0, _i16(ax * mg), _i16(ay * mg), _i16(-1000.0)))
            self.messages_sent["HIL_STATE_QUATERNION"] += 1
        if self.dvl is not None and self.dvl_due.due(self.n):
            bu, bv, bw = self.dvl.measure(u, v)
            var = self.cfg.sensors.dvl.vel_std ** 2
            nan = float("nan")
            parts.append(self.codec.encode(
                "odometry", tu, MAV_TYPE.MAV_FRAME_LOCAL_FRD, MAV_TYPE.MAV_FRAME_BODY_FRD, nan, nan, nan,
                [nan, nan, nan, nan], bu, bv, bw, nan, nan, nan, [nan] + [0.0] * 20,
                [var, 0, 0, 0, 0, 0, var, 0, 0, 0, 0, var] + [0.0] * 9, 0, 0, 100))
            self.messages_sent["ODOMETRY"] += 1
        if self.battery_due.due(self.n):
            self.settle_battery()
            parts.append(self.codec.encode("battery_status", **self.battery.battery_status()))
            self.messages_sent["BATTERY_STATUS"] += 1
        if self.rangefinder is not None and self.rangefinder_due.due(self.n):
            rf = self.rangefinder
            parts.append(self.codec.encode(
                "obstacle_distance", tu, MAV_TYPE.MAV_DISTANCE_SENSOR_LASER, rf.scan(x, y, psi),
                int(round(rf.increment_deg)), rf.min_cm, rf.max_cm, rf.increment_deg, 0.0,
                MAV_TYPE.MAV_FRAME_BODY_FRD))
            self.messages_sent["OBSTACLE_DISTANCE"] += 1
        if self.traffic is not None:
            reports = self.traffic.ais_messages(t, self.codec)
            parts += reports
            self.messages_sent["AIS_VESSEL"] += len(reports)
            if self.truth_due.due(self.n):
                parts += self.traffic.truth_messages(t, self.truth_codec)
                self.messages_sent["AIS_VESSEL_TRUTH"] += len(self.traffic.ships)
        return b"".join(parts)

    def settle_battery(self) -> None:
        """Let the pack deliver the thrusters' energy of the frames since it last did, plus the hotel load."""
        if self._frames_due:
            pack = self.battery
            pack.draw(self._energy_due / self._frames_due + pack.p.hotel_power, self._frames_due * self.frame_dt)
            self._energy_due, self._frames_due = 0.0, 0

    def battery_summary(self) -> BatterySummary:
        """The pack at the end: state of charge (0-1), terminal voltage (V), consumed mAh and Wh, empty."""
        self.settle_battery()
        b = self.battery
        return BatterySummary(state_of_charge=round(b.soc, 5), voltage_v=round(b.voltage, 3),
                              consumed_mah=round(b.consumed_mah, 1), energy_wh=round(b.energy_j / 3600.0, 3),
                              depleted=b.depleted)

    def truth(self) -> TruthState:
        x, y, psi, u, v, r = self.state
        lat, lon = self.geo.sea_level_to_geodetic(x, y)
        return TruthState(t=self.t, x=x, y=y, psi=psi, u=u, v=v, r=r, lat=lat, lon=lon)


def _esc_resolution(x: float) -> float:
    return round(x * RAW_COMMAND_MAX) / RAW_COMMAND_MAX


def _i16(v: float) -> int:
    return max(-32768, min(32767, int(round(v))))
