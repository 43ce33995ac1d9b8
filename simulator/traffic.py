"""Ship traffic in the simulator: other vessels, their truth, and their AIS reports.

A :class:`Ship` sails at constant velocity, or along waypoints with a speed per leg (it keeps
its last course and speed after the last waypoint). Its motion is a closed-form function of time,
so its truth is exact at any instant. Frames: NED (north, east, metres), courses clockwise from
north (radians in code, degrees in AIS and in scenario files, as AIS COG is).

Each ship has an AIS transponder reporting like a class A station (ITU-R M.1371-5, Annex 1,
Table 1: every 10 s below 14 kn, 3 1/3 s below 14 kn while changing course, 6 s at 14-23 kn,
2 s above 23 kn; the intervals are configurable in :class:`AisParams`). Reports carry position
noise (the target's GNSS), course and speed noise, and may be lost; all of it drawn from a
generator seeded by the run's seed and the ship's MMSI, so a run is repeatable. The first report
of each ship comes at a seeded instant within its first interval (transponders are not in step).

:meth:`Traffic.ais_messages` gives the AIS_VESSEL reports due at a frame; the simulator sends
them on the HIL link. :meth:`Traffic.truth_messages` gives every ship's exact state as
AIS_VESSEL from the simulator's *truth* component (``AisParams.truth_component_id``), like
HIL_STATE_QUATERNION for the own ship: for judging only, the vessel computer drops it.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import TYPE_CHECKING

import numpy as np

from common.params import param

if TYPE_CHECKING:
    from common.geodesy import LocalFrame
    from common.mavlink import Codec

KNOT = 1852.0 / 3600.0  # m/s


@dataclass(frozen=True)
class ShipSpec:
    """One traffic ship of a scenario (``[[traffic]]`` tables; map frame as the scenario: x east, y north)."""

    mmsi: int = param("Maritime Mobile Service Identity (9 digits)", ge=100000000, le=999999999)
    start: tuple[float, float] = param("position at t = 0 [x east, y north]", "m")
    speed: float = param("speed over ground (first leg)", "m/s", ge=0, le=30)
    course: float = param("course over ground, clockwise from north (constant-velocity ships)", "deg",
                          ge=0, lt=360, default=0.0)
    waypoints: tuple[tuple[float, float], ...] = param(
        "optional waypoints [[x, y], ...] after start; the ship sails them in order", "m", default=())
    speeds: tuple[float, ...] = param("optional speed of each waypoint leg (default: speed)", "m/s", ge=0,
                                      default=())
    name: str = param("ship name (AIS, at most 20 characters)", default="")
    ship_type: int = param("AIS ship type (e.g. 70 cargo, 52 tug, 37 pleasure craft)", ge=0, le=255, default=70)
    bow: float = param("AIS dimension A: reference point to bow", "m", ge=0, default=4.0)
    stern: float = param("AIS dimension B: reference point to stern", "m", ge=0, default=4.0)
    port: float = param("AIS dimension C: reference point to port side", "m", ge=0, default=1.5)
    starboard: float = param("AIS dimension D: reference point to starboard side", "m", ge=0, default=1.5)

    def __post_init__(self) -> None:
        if self.speeds and len(self.speeds) != len(self.waypoints):
            raise ValueError("speeds: one speed per waypoint leg (as many as waypoints)")
        if len(self.name) > 20:
            raise ValueError("name: at most 20 characters (AIS)")

    @property
    def hull_radius(self) -> float:
        """Radius (m) of the circle about the reference point that contains the hull."""
        return math.hypot(max(self.bow, self.stern), max(self.port, self.starboard))


@dataclass(frozen=True)
class AisParams:
    """The [traffic] section: AIS reporting of the traffic ships (class A-like) and its faults."""

    interval_slow: float = param("report interval below 14 kn (ITU-R M.1371 class A: 10 s)", "s", gt=0, default=10.0)
    interval_turning: float = param("report interval below 14 kn while changing course (3.33 s)", "s", gt=0,
                                    default=3.33)
    interval_fast: float = param("report interval at 14-23 kn (6 s)", "s", gt=0, default=6.0)
    interval_very_fast: float = param("report interval above 23 kn (2 s)", "s", gt=0, default=2.0)
    pos_std: float = param("position noise of a report, per axis", "m", ge=0, default=2.0)
    sog_std: float = param("speed over ground noise", "m/s", ge=0, default=0.05)
    cog_std: float = param("course over ground noise", "deg", ge=0, default=1.0)
    loss: float = param("probability that a report is lost", "", ge=0, le=1, default=0.0)
    turning_window: float = param("a ship counts as changing course this long around a waypoint", "s",
                                  ge=0, default=5.0)
    truth_component_id: int = param("MAVLink component id of the traffic truth (judging only)", ge=0, le=255,
                                    default=52)


@dataclass
class ShipState:
    north: float
    east: float
    course: float        # rad, clockwise from north
    speed: float         # m/s
    turning: bool        # near a waypoint (course changing)


class Ship:
    """Closed-form motion of one :class:`ShipSpec` in NED."""

    def __init__(self, spec: ShipSpec) -> None:
        self.spec = spec
        pts = [(spec.start[1], spec.start[0])] + [(y, x) for x, y in spec.waypoints]  # NED
        self.points = np.array(pts, dtype=float)
        speeds = list(spec.speeds) if spec.speeds else [spec.speed] * len(spec.waypoints)
        # Legs: (t_start, t_end, p0, velocity); the last one open-ended.
        self.legs: list[tuple[float, float, np.ndarray, np.ndarray]] = []
        self.turn_times: list[float] = []
        t = 0.0
        for i in range(len(spec.waypoints)):
            p0, p1 = self.points[i], self.points[i + 1]
            d = float(np.hypot(*(p1 - p0)))
            v = speeds[i]
            if d < 1e-9 or v <= 0:
                continue
            u = (p1 - p0) / d
            self.legs.append((t, t + d / v, p0, u * v))
            t += d / v
            self.turn_times.append(t)
        if self.legs:
            self.turn_times.pop()  # no turn after the last waypoint: the ship keeps going
            t0, t1, p0, vel = self.legs[-1]
            self.legs[-1] = (t0, math.inf, p0, vel)
        else:
            c = math.radians(spec.course)
            self.legs.append((0.0, math.inf, self.points[0], np.array([math.cos(c), math.sin(c)]) * spec.speed))

    def state(self, t: float, turning_window: float = 5.0) -> ShipState:
        t0, _, p0, vel = next((leg for leg in self.legs if t < leg[1]), self.legs[-1])
        p = p0 + vel * (max(t, 0.0) - t0)
        speed = float(np.hypot(*vel))
        course = math.atan2(vel[1], vel[0]) % (2 * math.pi) if speed > 0 else math.radians(self.spec.course)
        turning = any(abs(t - tt) <= turning_window for tt in self.turn_times)
        return ShipState(float(p[0]), float(p[1]), course, speed, turning)


def report_interval(speed: float, turning: bool, p: AisParams) -> float:
    """Class A reporting interval (s) for a ship at ``speed`` (m/s)."""
    kn = speed / KNOT
    if kn > 23.0:
        return p.interval_very_fast
    if kn >= 14.0:
        return p.interval_fast
    return p.interval_turning if turning else p.interval_slow


def _cdeg(rad: float) -> int:
    return int(round(math.degrees(rad) * 100.0)) % 36000


def _bytes(text: str, n: int) -> bytes:
    return text.encode("ascii", "replace")[:n]


@dataclass
class Traffic:
    """All traffic ships of a run, their AIS schedule and their encoders."""

    specs: tuple[ShipSpec, ...]
    params: AisParams
    seed: int
    geo: LocalFrame
    ships: list[Ship] = field(init=False)
    next_report: list[float] = field(init=False)
    rngs: list[np.random.Generator] = field(init=False)
    reports_sent: int = 0
    reports_lost: int = 0

    def __post_init__(self) -> None:
        mmsis = [s.mmsi for s in self.specs]
        if len(set(mmsis)) != len(mmsis):
            raise ValueError("traffic: two ships share an MMSI")
        self.ships = [Ship(s) for s in self.specs]
        self.rngs = [np.random.default_rng([int(self.seed), int(s.mmsi), 0xA15]) for s in self.specs]
        self.next_report = []
        for ship, rng in zip(self.ships, self.rngs, strict=False):
            st = ship.state(0.0, self.params.turning_window)
            self.next_report.append(float(rng.uniform(0.0, report_interval(st.speed, st.turning, self.params))))

    def _fields(self, spec: ShipSpec, north: float, east: float, course: float, speed: float, tslc: int) -> tuple:
        from common.mavlink import MAV_TYPE as M

        lat, lon = self.geo.sea_level_to_geodetic(north, east)
        flags = (M.AIS_FLAGS_POSITION_ACCURACY | M.AIS_FLAGS_VALID_COG | M.AIS_FLAGS_VALID_VELOCITY
                 | M.AIS_FLAGS_VALID_DIMENSIONS | (M.AIS_FLAGS_VALID_NAME if spec.name else 0))
        return (spec.mmsi, int(round(lat * 1e7)), int(round(lon * 1e7)), _cdeg(course), _cdeg(course),
                min(int(round(speed * 100.0)), 65534), 0, 0, spec.ship_type,
                int(round(spec.bow)), int(round(spec.stern)), min(int(round(spec.port)), 255),
                min(int(round(spec.starboard)), 255), b"", _bytes(spec.name, 20), tslc, flags)

    def ais_messages(self, t: float, codec: Codec) -> list[bytes]:
        """AIS_VESSEL frames of the reports due at simulated time ``t`` (noisy; some lost)."""
        out = []
        p = self.params
        for i, (ship, rng) in enumerate(zip(self.ships, self.rngs, strict=False)):
            if t + 1e-9 < self.next_report[i]:
                continue
            st = ship.state(t, p.turning_window)
            self.next_report[i] = t + report_interval(st.speed, st.turning, p)
            # Draw the noise even for a lost report, so loss does not shift the other draws.
            dn, de = rng.normal(0.0, p.pos_std, 2) if p.pos_std > 0 else (0.0, 0.0)
            ds = rng.normal(0.0, p.sog_std) if p.sog_std > 0 else 0.0
            dc = math.radians(rng.normal(0.0, p.cog_std)) if p.cog_std > 0 else 0.0
            lost = p.loss > 0 and rng.random() < p.loss
            if lost:
                self.reports_lost += 1
                continue
            out.append(codec.encode("ais_vessel", *self._fields(
                ship.spec, st.north + dn, st.east + de, st.course + dc, max(0.0, st.speed + ds), 0)))
            self.reports_sent += 1
        return out

    def truth_messages(self, t: float, codec: Codec) -> list[bytes]:
        """AIS_VESSEL frames with every ship's exact state at ``t`` (truth component)."""
        out = []
        for ship in self.ships:
            st = ship.state(t, self.params.turning_window)
            out.append(codec.encode("ais_vessel", *self._fields(ship.spec, st.north, st.east, st.course, st.speed, 0)))
        return out

    def truth(self, t: float) -> list[dict[str, float]]:
        return [dict(mmsi=s.spec.mmsi, **vars(s.state(t, self.params.turning_window))) for s in self.ships]
