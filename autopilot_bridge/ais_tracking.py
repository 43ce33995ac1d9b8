"""AIS target tracking: one constant-velocity Kalman filter (filterpy) per MMSI.

AIS_VESSEL reports arrive every 2-10 s per ship (class A); between them the vessel computer
needs each target's position now and its prediction for planning. Each MMSI gets a linear
Kalman filter with state ``[north, east, v_north, v_east]`` (NED, m and m/s), a white-noise
acceleration process model (``accel_noise``) and the report's position (and, when valid, its
course and speed as a velocity) as the measurement.

Reports are checked before they touch a track, and every rejection is counted by reason:

* ``bad_mmsi``: not a 9-digit MMSI (ITU-R M.585: 100000000-999999999);
* ``bad_position``: latitude outside +-90 deg or longitude outside +-180 deg (AIS "not
  available" is 91 deg / 181 deg);
* ``impossible_speed``: speed over ground above ``max_speed`` (default 50 kn: faster than any
  ship AIS class A reports for);
* ``implausible_jump``: the reported position is farther from the track's prediction than the
  target could have moved at ``max_speed`` since its last report, plus the noise allowance;
* ``track_table_full``: a new MMSI when ``max_targets`` are tracked (an unknown-MMSI flood
  cannot push real targets out);
* ``truth``: the simulator's truth component (never used here).

A track is *confirmed* after ``confirm_reports`` accepted reports (a single spoofed report never
becomes an obstacle) and forgotten ``forget_after`` seconds after its last report.
"""

from __future__ import annotations

import math
from collections import Counter
from dataclasses import dataclass
from functools import cache
from typing import TYPE_CHECKING, TypedDict

import numpy as np

from common.params import param

if TYPE_CHECKING:
    from filterpy.kalman import KalmanFilter

    from common.geodesy import LocalFrame

KNOT = 1852.0 / 3600.0


@dataclass(frozen=True)
class TrackerParams:
    """The [tracking] section."""

    accel_noise: float = param("process noise: white acceleration of a target", "m/s^2", gt=0, default=0.05)
    pos_std: float = param("assumed AIS position noise per axis", "m", gt=0, default=3.0)
    vel_std: float = param("assumed noise of the velocity from AIS course and speed, per axis", "m/s", gt=0,
                           default=0.2)
    max_speed: float = param("faster reports are impossible (50 kn)", "m/s", gt=0, default=25.7)
    jump_allowance: float = param("extra distance allowed beyond max_speed * dt for the jump check", "m",
                                  ge=0, default=30.0)
    max_targets: int = param("most tracked MMSIs; reports of new ones are rejected when full", ge=1, default=32)
    confirm_reports: int = param("accepted reports before a track is used for avoidance", ge=1, default=2)
    forget_after: float = param("a track without report for this long is dropped", "s", gt=0, default=35.0)


@dataclass(frozen=True)
class AisReport:
    """One decoded AIS_VESSEL (SI, NED course); None for fields AIS marks as not available."""

    t: float                        # s, simulated time of reception
    mmsi: int
    lat: float                      # deg
    lon: float                      # deg
    course: float | None            # rad, clockwise from north (COG)
    speed: float | None             # m/s (SOG)
    bow: float                      # m, AIS dimension A
    stern: float                    # m, B
    port: float                     # m, C
    starboard: float                # m, D
    name: str = ""


@dataclass(frozen=True)
class Target:
    """A track's state at time ``t``: NED position (m), velocity (m/s), sizes (m)."""

    mmsi: int
    t: float
    north: float
    east: float
    vn: float
    ve: float
    pos_std: float                  # m, sqrt of the largest position covariance eigenvalue
    hull_radius: float              # m, circle about the reference point containing the hull
    reports: int
    last_report_t: float
    name: str = ""

    @property
    def speed(self) -> float:
        return math.hypot(self.vn, self.ve)

    @property
    def course(self) -> float:
        return math.atan2(self.ve, self.vn) % (2 * math.pi)


@cache
def _kalman_filter() -> type[KalmanFilter]:
    """filterpy's KalmanFilter, imported by the tracker's constructor (the vessel computer's set-up):
    filterpy imports scipy.stats (~0.6 s), which the configuration (hil.settings) need not pay."""
    from filterpy.kalman import KalmanFilter

    return KalmanFilter


class _Track:
    def __init__(self, r: AisReport, north: float, east: float, p: TrackerParams) -> None:
        kf = _kalman_filter()(dim_x=4, dim_z=4)
        vn, ve = _velocity(r)
        kf.x = np.array([north, east, vn or 0.0, ve or 0.0])
        kf.P = np.diag([p.pos_std ** 2, p.pos_std ** 2, (p.vel_std if vn is not None else p.max_speed) ** 2,
                        (p.vel_std if vn is not None else p.max_speed) ** 2])
        self.kf, self.t, self.last_report_t, self.reports = kf, r.t, r.t, 1
        self.report = r

    def predict_to(self, t: float, q: float) -> None:
        dt = t - self.t
        if dt <= 0:
            return
        kf = self.kf
        kf.F = np.array([[1, 0, dt, 0], [0, 1, 0, dt], [0, 0, 1, 0], [0, 0, 0, 1]], dtype=float)
        # Discrete white-noise acceleration (Bar-Shalom): per axis [[dt^4/4, dt^3/2], [dt^3/2, dt^2]] q^2.
        a, b, c = dt ** 4 / 4, dt ** 3 / 2, dt ** 2
        kf.Q = q * q * np.array([[a, 0, b, 0], [0, a, 0, b], [b, 0, c, 0], [0, b, 0, c]])
        kf.predict()
        self.t = t


def _velocity(r: AisReport) -> tuple[float | None, float | None]:
    if r.course is None or r.speed is None:
        return None, None
    return r.speed * math.cos(r.course), r.speed * math.sin(r.course)


class AisSummary(TypedDict):
    """AIS reports: targets tracked at the end, accepted, tracks opened and forgotten, refusals by reason."""

    tracked: int
    accepted: int
    new_tracks: int
    forgotten: int
    rejected: dict[str, int]


class AisTracker:
    """Tracks of every MMSI heard, with rejection counters (see the module docstring)."""

    def __init__(self, params: TrackerParams, geo: LocalFrame) -> None:
        _kalman_filter()  # imported now, not when the first ship is heard (in a frame)
        self.p, self.geo = params, geo
        self.tracks: dict[int, _Track] = {}
        self.rejected: Counter = Counter()
        self.accepted = 0
        self.forgotten = 0
        self.new_tracks = 0

    def reject(self, reason: str) -> None:
        self.rejected[reason] += 1

    def update(self, r: AisReport) -> bool:
        """Fold one report in; False (and counted) if it was rejected."""
        p = self.p
        if not 100_000_000 <= r.mmsi <= 999_999_999:
            self.reject("bad_mmsi")
            return False
        if not (math.isfinite(r.lat) and math.isfinite(r.lon) and abs(r.lat) <= 90.0 and abs(r.lon) <= 180.0):
            self.reject("bad_position")
            return False
        if r.speed is not None and not (math.isfinite(r.speed) and r.speed <= p.max_speed):
            self.reject("impossible_speed")
            return False
        north, east = self.geo.geodetic_to_sea_level(r.lat, r.lon)
        track = self.tracks.get(r.mmsi)
        if track is None:
            if len(self.tracks) >= p.max_targets:
                self.forget(r.t)
                if len(self.tracks) >= p.max_targets:
                    self.reject("track_table_full")
                    return False
            self.tracks[r.mmsi] = _Track(r, north, east, p)
            self.accepted += 1
            self.new_tracks += 1
            return True
        dt = max(r.t - track.last_report_t, 0.0)
        track.predict_to(max(r.t, track.t), p.accel_noise)
        px, py = track.kf.x[0], track.kf.x[1]
        if math.hypot(north - px, east - py) > p.max_speed * dt + p.jump_allowance + 3.0 * p.pos_std:
            self.reject("implausible_jump")
            return False
        vn, ve = _velocity(r)
        if vn is None:
            track.kf.update(np.array([north, east]), R=np.eye(2) * p.pos_std ** 2, H=np.eye(2, 4))
        else:
            track.kf.update(np.array([north, east, vn, ve]),
                            R=np.diag([p.pos_std ** 2, p.pos_std ** 2, p.vel_std ** 2, p.vel_std ** 2]), H=np.eye(4))
        track.last_report_t, track.reports, track.report = r.t, track.reports + 1, r
        self.accepted += 1
        return True

    def forget(self, t: float) -> int:
        """Drop tracks without a report for ``forget_after`` s; returns how many."""
        stale = [m for m, tr in self.tracks.items() if t - tr.last_report_t > self.p.forget_after]
        for m in stale:
            del self.tracks[m]
        self.forgotten += len(stale)
        return len(stale)

    def targets(self, t: float, confirmed_only: bool = True) -> list[Target]:
        """Every (confirmed) track predicted to ``t`` (the tracks themselves are not changed)."""
        out = []
        for m in sorted(self.tracks):
            tr = self.tracks[m]
            if confirmed_only and tr.reports < self.p.confirm_reports:
                continue
            dt = max(t - tr.t, 0.0)
            x = tr.kf.x
            F = np.array([[1, 0, dt, 0], [0, 1, 0, dt], [0, 0, 1, 0], [0, 0, 0, 1]], dtype=float)
            P = F @ tr.kf.P @ F.T
            r = tr.report
            out.append(Target(m, t, float(x[0] + x[2] * dt), float(x[1] + x[3] * dt), float(x[2]), float(x[3]),
                              float(math.sqrt(max(np.linalg.eigvalsh(P[:2, :2])))),
                              math.hypot(max(r.bow, r.stern), max(r.port, r.starboard)), tr.reports,
                              tr.last_report_t, r.name))
        return out

    def summary(self) -> AisSummary:
        return AisSummary(tracked=len(self.tracks), accepted=self.accepted, new_tracks=self.new_tracks,
                          forgotten=self.forgotten, rejected=dict(sorted(self.rejected.items())))
