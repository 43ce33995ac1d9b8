"""Typed configuration of the simulator: the vessel, its sea, its sensors, its clock and its link.

Frozen dataclasses, filled strictly from the TOML sections of the same names by
``hil.config``. Units are SI (metres, seconds, radians, newtons, kilograms) unless a field's
``unit`` says otherwise; frames are NED (x north, y east, yaw clockwise from north).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

from common.current_params import CurrentParams as CurrentParams  # [current]: common's current model owns it
from common.params import param

if TYPE_CHECKING:
    from common.can_params import CanParams
    from simulator.battery import BatteryParams
    from simulator.traffic import AisParams


@dataclass(frozen=True)
class VesselParams:
    """Parameters of the 3-DOF model of eqs. (2)-(5) (the paper's Table 1, which is missing)."""

    m: float = param("rigid-body mass", "kg", gt=0)
    L: float = param("hull length used in eq. (5)", "m", gt=0)
    W: float = param("hull width (beam) used in eq. (5)", "m", gt=0)
    D: float = param("average draft (depth of underwater penetration), eq. (5)", "m", gt=0)
    B_u: float = param("distance between port and starboard propellers", "m", gt=0)
    rho: float = param("water density", "kg/m^3", gt=0)
    d_u: float = param("linear surge damping; d_u2 = 0.2 d_u, d_u3 = 0.1 d_u", "kg/s", ge=0)
    d_v: float = param("linear sway damping; d_v2 = 0.2 d_v, d_v3 = 0.1 d_v", "kg/s", ge=0)
    d_r: float = param("linear yaw damping; d_r2 = 0.2 d_r, d_r3 = 0.1 d_r", "kg m^2/s", ge=0)
    T_max: float = param("largest forward thrust of one propeller", "N", gt=0)
    T_min: float = param("largest reverse thrust of one propeller (<= 0)", "N", le=0)


@dataclass(frozen=True)
class WaveParams:
    """Wave forces of eq. (6) (the paper's Table 2, which is missing)."""

    enabled: bool = param("apply the wave forces of eq. (6)")
    amplitude: float = param("mean wave amplitude alpha", "m", ge=0)
    amplitude_std: float = param("std of the slow variation of the amplitude", "m", ge=0)
    direction: float = param("mean direction the waves travel towards, clockwise from north", "rad")
    direction_std: float = param("std of the slow variation of the wave direction", "rad", ge=0)
    correlation_time: float = param("time constant of the slow (Ornstein-Uhlenbeck) variation", "s", gt=0)
    C_X: float = param("non-dimensional surge wave coefficient")
    C_Y: float = param("non-dimensional sway wave coefficient")
    C_N: float = param("non-dimensional yaw wave coefficient")


@dataclass(frozen=True)
class GpsParams:
    rate_hz: float = param("GPS output rate", "Hz", gt=0, le=50)
    latency: float = param("delay between the measured instant and its output", "s", ge=0)
    pos_std: float = param("horizontal position noise, per axis", "m", ge=0)
    vel_std: float = param("velocity noise, per axis", "m/s", ge=0)
    dropouts: tuple[tuple[float, float], ...] = param(
        "scheduled dropout windows [[start_s, duration_s], ...] in simulated time")
    dropout_rate: float = param("random dropouts started per second", "1/s", ge=0)
    dropout_duration: float = param("duration of a random dropout", "s", ge=0)
    glitch_probability: float = param("probability that a GPS fix is a glitch", "", ge=0, le=1)
    glitch_magnitude: float = param("position jump of a glitch", "m", ge=0)
    satellites: int = param("mean number of satellites tracked (HIL_GPS satellites_visible; 0 in a dropout)",
                            ge=4, le=60, default=12)
    satellite_interval: float = param("mean time between a satellite rising or setting; 0 = the count stays",
                                      "s", ge=0, default=90.0)


@dataclass(frozen=True)
class ImuParams:
    rate_hz: float = param("IMU (HIL_SENSOR) output rate", "Hz", gt=0, le=1000)
    gyro_std: float = param("gyro white noise", "rad/s", ge=0)
    gyro_bias: float = param("initial gyro bias std (constant per run)", "rad/s", ge=0)
    gyro_bias_walk: float = param("gyro bias random walk", "rad/s/sqrt(s)", ge=0)
    accel_std: float = param("accelerometer white noise", "m/s^2", ge=0)
    accel_bias: float = param("initial accelerometer bias std (constant per run)", "m/s^2", ge=0)


@dataclass(frozen=True)
class CompassParams:
    heading_std: float = param("heading noise", "rad", ge=0)
    field_strength: float = param("horizontal magnetic field strength", "gauss", gt=0)
    declination: float = param("magnetic declination, east positive", "rad")


@dataclass(frozen=True)
class DvlParams:
    enabled: bool = param("send DVL bottom-lock body velocity")
    rate_hz: float = param("DVL output rate", "Hz", gt=0, le=50)
    vel_std: float = param("body velocity noise, per axis", "m/s", ge=0)


@dataclass(frozen=True)
class RangefinderParams:
    """A 2-D scanning range sensor (lidar/radar class) reported as MAVLink OBSTACLE_DISTANCE.

    Each of ``sectors`` sectors reports the nearest return of ``rays_per_sector`` rays spread
    over it, as PX4/ArduPilot bin a scanning lidar. It needs the true world map (``hil sim
    --world``); without one it is silent.
    """

    enabled: bool = param("scan the true map (chart plus uncharted obstacles) and send OBSTACLE_DISTANCE")
    rate_hz: float = param("scan rate", "Hz", gt=0, le=50)
    sectors: int = param("sectors around the vessel (OBSTACLE_DISTANCE holds at most 72)", "", ge=4, le=72)
    rays_per_sector: int = param("rays cast per sector; a sector reports the nearest", "", ge=1, le=16)
    min_range: float = param("nearest measurable distance", "m", ge=0)
    max_range: float = param("farthest measurable distance", "m", gt=0, le=600)
    range_std: float = param("range noise", "m", ge=0)
    miss_probability: float = param("probability that a sector returns nothing in a scan", "", ge=0, le=1)


@dataclass(frozen=True)
class SensorParams:
    gps: GpsParams
    imu: ImuParams
    compass: CompassParams
    dvl: DvlParams
    rangefinder: RangefinderParams


@dataclass(frozen=True)
class InitialState:
    """Where the vessel starts (NED metres, radians, m/s, rad/s)."""

    x: float = param("north", "m")
    y: float = param("east", "m")
    psi: float = param("heading, clockwise from north", "rad")
    u: float = param("surge velocity", "m/s")
    v: float = param("sway velocity", "m/s")
    r: float = param("yaw rate", "rad/s")


@dataclass(frozen=True)
class SimParams:
    """Clock and integration of the simulator process."""

    dt: float = param("integration step (fixed-step RK4)", "s", gt=0, le=0.1)
    seed: int = param("seed of every random process (sensors, waves)", ge=0)
    duration: float = param("simulated time after which the run ends; 0 = until stopped", "s", ge=0)
    lockstep: bool = param("advance one step per HIL_ACTUATOR_CONTROLS instead of the wall clock")
    speedup: float = param("real-time mode: simulated seconds per wall second", "", gt=0)
    truth_rate_hz: float = param("HIL_STATE_QUATERNION (truth) rate", "Hz", gt=0)
    stale_command_timeout: float = param("no command for this long (simulated time) -> thrust 0", "s", gt=0)
    lockstep_resend: float = param("lockstep: re-send the latest frame when no command for this long (wall)", "s", gt=0)
    lockstep_pipeline: bool = param(
        "lockstep: compute the next frame while the vessel computer answers the newest, so both work at once; "
        "a command then acts one frame later (a one-frame actuator delay, the same in every run)")
    lockstep_busy_poll: float = param(
        "lockstep: wait for the command polling the socket this long before sleeping on it (common.udp.BusyPoll; "
        "0 = sleep at once)", "s", ge=0, le=0.1)
    initial: InitialState = param("where the vessel starts")


@dataclass(frozen=True)
class EscParams:
    """The thrusters' electronic speed controllers and propellers (both actuator paths; defaults as in
    configs/default.toml)."""

    time_constant: float = param("first-order lag from thrust set-point to thrust; 0 = instantaneous", "s", ge=0,
                                 default=0.0)
    int14_resolution: bool = param(
        "round commands to DroneCAN RawCommand's int14 resolution on the MAVLink path too (always on for CAN)",
        default=False)
    max_rpm: float = param("propeller speed at full forward thrust (thrust ~ rpm^2)", "rpm", gt=0, default=992.0)
    max_power: float = param("electrical power at full forward thrust (power ~ rpm^3)", "W", gt=0, default=500.0)
    voltage: float = param("supply voltage reported in ESC Status", "V", gt=0, default=24.0)
    ambient_temperature: float = param("ESC temperature at rest", "K", gt=0, default=298.15)
    heating: float = param("steady temperature rise per watt", "K/W", ge=0, default=0.02)


@dataclass(frozen=True)
class LinkParams:
    """UDP/MAVLink endpoints of the simulator."""

    state_to: tuple[str, ...] = param("HOST:PORT destinations of the sensor/truth broadcast")
    commands_on: str = param("HOST:PORT where HIL_ACTUATOR_CONTROLS are received")
    system_id: int = param("MAVLink system id of the simulator", ge=1, le=255)
    component_id: int = param("MAVLink component id of the simulator", ge=0, le=255)


@dataclass(frozen=True)
class GeodesyParams:
    """Origin of the local NED frame on WGS-84."""

    lat0: float = param("latitude of the NED origin", "deg", ge=-89, le=89)
    lon0: float = param("longitude of the NED origin", "deg", ge=-180, le=180)
    alt0: float = param("height of the NED origin above the ellipsoid", "m")
    positions_origin: tuple[float, ...] = param(
        "[lat, lon] from which a chart scenario's positions in metres count, when the NED origin was moved to its "
        "map's corner (set by hil with lat0/lon0; [] = lat0, lon0)", "deg", ge=-180, le=360, default=())

    def __post_init__(self) -> None:
        if len(self.positions_origin) not in (0, 2):
            raise ValueError("positions_origin: expected [latitude, longitude] or []")

    def metres_origin(self) -> tuple[float, float]:
        """(lat, lon) of the frame in which a scenario's positions in metres are given."""
        return (self.positions_origin[0], self.positions_origin[1]) if self.positions_origin else (self.lat0, self.lon0)


@dataclass(frozen=True)
class PeerIds:
    """The MAVLink ids of the vessel computer, the one peer whose commands the simulator applies."""

    system_id: int
    component_id: int


@dataclass(frozen=True)
class SimulatorSettings:
    """The root of the simulator's configuration: the sections :class:`simulator.core.SimulatorCore`
    and the simulator's assembly read, and the ids of the vessel computer it serves. The HIL tool maps
    its configuration onto it once (``hil.assembly.simulator.simulator_settings``); the simulator
    imports nothing of ``hil/``."""

    vessel: VesselParams
    waves: WaveParams
    current: CurrentParams
    sensors: SensorParams
    sim: SimParams
    link: LinkParams
    geodesy: GeodesyParams
    esc: EscParams
    can: CanParams
    traffic: AisParams
    battery: BatteryParams
    computer: PeerIds
