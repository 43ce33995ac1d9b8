"""Seeded sensor models: GPS, IMU, compass and DVL, producing MAVLink message fields.

Each sensor owns its numpy Generator (spawned from ``sim.seed``, see :func:`sensor_rngs`), so
adding a sensor leaves the other streams unchanged. Noise is white Gaussian with the configured
standard deviations; the gyro bias is drawn once per run and then random-walks.
"""

from __future__ import annotations

import math
from collections import deque
from typing import TYPE_CHECKING

import numpy as np

from common.geodesy import LocalFrame

if TYPE_CHECKING:
    from simulator.config import CompassParams, DvlParams, GpsParams, ImuParams

G = 9.80665  # m/s^2, standard gravity
UINT16_UNKNOWN = 65535

# Order of the spawned streams: append new ones at the end (keeps the earlier streams unchanged).
STREAMS = ("gps", "imu", "compass", "dvl", "waves", "gps_events", "rangefinder",
           "gps_satellites")  # append only: keeps the others


def sensor_rngs(seed: int) -> dict[str, np.random.Generator]:
    """One independent Generator per stream name, all derived from ``seed``."""
    children = np.random.SeedSequence(seed).spawn(len(STREAMS))
    return {name: np.random.default_rng(c) for name, c in zip(STREAMS, children, strict=False)}


class Normals:
    """Standard normal draws from a Generator, fetched in blocks (per-call numpy overhead is ~1 us)."""

    def __init__(self, rng: np.random.Generator, block: int = 4096) -> None:
        self.rng, self.block = rng, block
        self._buf: list[float] = []
        self._i = 0

    def __call__(self) -> float:
        if self._i >= len(self._buf):
            self._buf = self.rng.standard_normal(self.block).tolist()
            self._i = 0
        self._i += 1
        return self._buf[self._i - 1]


class Uniforms(Normals):
    def __call__(self) -> float:
        if self._i >= len(self._buf):
            self._buf = self.rng.random(self.block).tolist()
            self._i = 0
        self._i += 1
        return self._buf[self._i - 1]


def wrap_2pi(a: float) -> float:
    return a % (2.0 * math.pi)


class Imu:
    """HIL_SENSOR accelerometer and gyro fields (body FRD axes, boat level)."""

    def __init__(self, p: ImuParams, rng: np.random.Generator, period: float) -> None:
        self.p, self.period, self.n = p, period, Normals(rng)
        self.gyro_bias = [p.gyro_bias * self.n() for _ in range(3)]
        self.accel_bias = [p.accel_bias * self.n() for _ in range(3)]

    def measure(self, r: float, ax: float, ay: float) -> tuple[float, ...]:
        """(xacc, yacc, zacc m/s^2 specific force; xgyro, ygyro, zgyro rad/s).

        Specific force f = a - g in body axes; z is down, so a boat at rest reads zacc = -g.
        """
        p, n = self.p, self.n
        if p.gyro_bias_walk > 0:
            w = p.gyro_bias_walk * math.sqrt(self.period)
            self.gyro_bias = [b + w * n() for b in self.gyro_bias]
        gb, ab = self.gyro_bias, self.accel_bias
        return (ax + ab[0] + p.accel_std * n(), ay + ab[1] + p.accel_std * n(), -G + ab[2] + p.accel_std * n(),
                gb[0] + p.gyro_std * n(), gb[1] + p.gyro_std * n(), r + gb[2] + p.gyro_std * n())


class Compass:
    """Magnetometer (gauss, body axes) from the heading: horizontal field towards magnetic north.

    The field in NED is H (cos d, sin d, 0) with declination d; rotated into the body frame of a
    level boat: xmag = H cos(psi - d), ymag = -H sin(psi - d), zmag = 0 (inclination ignored), so
    heading = atan2(-ymag, xmag) + d.
    """

    def __init__(self, p: CompassParams, rng: np.random.Generator) -> None:
        self.p, self.n = p, Normals(rng)

    def measure(self, psi: float) -> tuple[float, float, float]:
        a = psi + self.p.heading_std * self.n() - self.p.declination
        h = self.p.field_strength
        return h * math.cos(a), -h * math.sin(a), 0.0


class Satellites:
    """The number of satellites the receiver tracks: a seeded birth-death process round ``mean``.

    Satellites rise and set one at a time (a GNSS satellite stays above the horizon for hours, and a
    multi-constellation receiver tracks a few dozen, so the count changes every minute or two): an
    event every ``interval`` s on average (Poisson), a rise with probability 1/2 - (n - mean)/8 (so
    the count reverts to the mean), within mean +- 4 and never below 4 (the fewest for a 3-D fix).
    """

    SPREAD = 4

    def __init__(self, mean: int, interval: float, rng: np.random.Generator, frame_dt: float) -> None:
        self.mean, self.u = mean, Uniforms(rng)
        self.lo, self.hi = max(4, mean - self.SPREAD), max(4, mean + self.SPREAD)
        self.p_event = frame_dt / interval if interval > 0 else 0.0
        self.count = min(max(mean + int(self.u() * 3) - 1, self.lo), self.hi)   # mean - 1 .. mean + 1

    def advance(self) -> None:
        """One frame: maybe a satellite rises or sets."""
        if self.p_event and self.u() < self.p_event:
            rise = self.u() < 0.5 - (self.count - self.mean) / 8.0
            self.count = min(max(self.count + (1 if rise else -1), self.lo), self.hi)


class Gps:
    """HIL_GPS fields: delayed, noisy position/velocity, dropouts (fix_type 0, no satellites) and glitches."""

    def __init__(self, p: GpsParams, rng: np.random.Generator, events: np.random.Generator,
                 frame: LocalFrame, frame_dt: float, satellites: np.random.Generator | None = None) -> None:
        self.p, self.frame, self.frame_dt = p, frame, frame_dt
        self.n, self.u = Normals(rng), Uniforms(events)
        self.satellites = Satellites(int(getattr(p, "satellites", 12)), float(getattr(p, "satellite_interval", 90.0)),
                                     satellites if satellites is not None else np.random.default_rng(0), frame_dt)
        self.delay_frames = int(round(p.latency / frame_dt))
        self.history: deque = deque(maxlen=self.delay_frames + 1)
        self.random_dropout_until = -1.0
        self.fixes = self.glitches = self.dropout_fixes = 0

    def record(self, t: float, x: float, y: float, vn: float, ve: float) -> None:
        """Remember the truth of every frame (for the latency); also draws random dropouts."""
        self.history.append((x, y, vn, ve))
        self.satellites.advance()
        if self.p.dropout_rate > 0 and t >= self.random_dropout_until:
            if self.u() < self.p.dropout_rate * self.frame_dt:
                self.random_dropout_until = t + self.p.dropout_duration

    def in_dropout(self, t: float) -> bool:
        if t < self.random_dropout_until:
            return True
        return any(start <= t < start + dur for start, dur in self.p.dropouts)

    def measure(self, t: float, alt0: float) -> dict[str, int]:
        """Keyword arguments of hil_gps_encode (without time_usec) for the fix output at ``t``."""
        p = self.p
        if self.in_dropout(t):
            self.dropout_fixes += 1
            return dict(fix_type=0, lat=0, lon=0, alt=0, eph=UINT16_UNKNOWN, epv=UINT16_UNKNOWN,
                        vel=UINT16_UNKNOWN, vn=0, ve=0, vd=0, cog=UINT16_UNKNOWN, satellites_visible=0)
        self.fixes += 1
        x, y, vn, ve = self.history[0]  # the oldest kept sample is `latency` old
        x += p.pos_std * self.n()
        y += p.pos_std * self.n()
        if p.glitch_probability > 0 and self.u() < p.glitch_probability:
            self.glitches += 1
            a = 2.0 * math.pi * self.u()
            x += p.glitch_magnitude * math.cos(a)
            y += p.glitch_magnitude * math.sin(a)
        vn += p.vel_std * self.n()
        ve += p.vel_std * self.n()
        lat, lon = self.frame.sea_level_to_geodetic(x, y)
        speed = math.hypot(vn, ve)
        return dict(fix_type=3, lat=int(round(lat * 1e7)), lon=int(round(lon * 1e7)), alt=int(round(alt0 * 1000)),
                    eph=min(UINT16_UNKNOWN - 1, int(round(100 * p.pos_std))),
                    epv=min(UINT16_UNKNOWN - 1, int(round(200 * p.pos_std))),
                    vel=min(UINT16_UNKNOWN - 1, int(round(100 * speed))),
                    vn=int(round(100 * vn)), ve=int(round(100 * ve)), vd=0,
                    cog=int(round(math.degrees(wrap_2pi(math.atan2(ve, vn))) * 100)) % 36000,
                    satellites_visible=self.satellites.count)


class Dvl:
    """Bottom-lock body velocity (m/s, FRD) with white noise."""

    def __init__(self, p: DvlParams, rng: np.random.Generator) -> None:
        self.p, self.n = p, Normals(rng)

    def measure(self, u: float, v: float) -> tuple[float, float, float]:
        s = self.p.vel_std
        return u + s * self.n(), v + s * self.n(), s * self.n()
