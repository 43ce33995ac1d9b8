"""Flat-earth (local tangent plane) conversion between NED metres and WGS-84 coordinates.

The local frame has its origin at (lat0, lon0, alt0) and axes north, east, down of the tangent
plane at the origin. Conversion goes through ECEF, so it is exact (no small-angle approximation):
NED -> geodetic -> NED round-trips to micrometres. For a boat the horizontal position matters:
:meth:`LocalFrame.sea_level_to_geodetic` finds the point on the ellipsoid at height ``alt0``
whose north/east coordinates are the given ones (the tangent plane dips below the sea surface
by ~ d^2 / 2R, 7.8 m at 10 km, so "down" is solved for, not assumed 0).

The functions are compiled by numba (the simulator converts a position every other frame, on the
lockstep loop's critical path); each compiled function computes what its Python source does, bit
for bit (tests/test_geodesy.py holds them against ``.py_func``).
"""

from __future__ import annotations

import math

from numba import njit

# WGS-84 ellipsoid (NIMA TR8350.2).
WGS84_A = 6378137.0
WGS84_F = 1.0 / 298.257223563
WGS84_E2 = WGS84_F * (2.0 - WGS84_F)
WGS84_B = WGS84_A * (1.0 - WGS84_F)
_EP2 = WGS84_E2 / (1.0 - WGS84_E2)


@njit(cache=True)
def geodetic_to_ecef(lat_deg: float, lon_deg: float, h: float) -> tuple[float, float, float]:
    """ECEF metres of a geodetic point (degrees, ellipsoidal height in metres)."""
    lat, lon = math.radians(lat_deg), math.radians(lon_deg)
    sl, cl = math.sin(lat), math.cos(lat)
    n = WGS84_A / math.sqrt(1.0 - WGS84_E2 * sl * sl)
    return ((n + h) * cl * math.cos(lon), (n + h) * cl * math.sin(lon), (n * (1.0 - WGS84_E2) + h) * sl)


@njit(cache=True)
def ecef_to_geodetic(x: float, y: float, z: float) -> tuple[float, float, float]:
    """Geodetic (lat deg, lon deg, h m) of an ECEF point; iterated to sub-micrometre."""
    lon = math.atan2(y, x)
    # sqrt, not hypot: CPython's and the C library's hypot differ in the last bit, so the compiled
    # function would not equal its source; ** 3.0 is pow() in both.
    p = math.sqrt(x * x + y * y)
    # Bowring's initial guess, then fixed-point refinement (converges in 2-3 iterations near the surface).
    theta = math.atan2(z * WGS84_A, p * WGS84_B)
    lat = math.atan2(z + _EP2 * WGS84_B * math.sin(theta) ** 3.0, p - WGS84_E2 * WGS84_A * math.cos(theta) ** 3.0)
    h = 0.0
    for _ in range(4):
        sl = math.sin(lat)
        n = WGS84_A / math.sqrt(1.0 - WGS84_E2 * sl * sl)
        h = p / math.cos(lat) - n if abs(lat) < 1.4 else z / sl - n * (1.0 - WGS84_E2)
        lat = math.atan2(z, p * (1.0 - WGS84_E2 * n / (n + h)))
    return math.degrees(lat), math.degrees(lon), h


@njit(cache=True)
def _ned_to_geodetic(o: tuple, r: tuple, n: float, e: float, d: float) -> tuple[float, float, float]:
    x = o[0] + r[0][0] * n + r[1][0] * e + r[2][0] * d
    y = o[1] + r[0][1] * n + r[1][1] * e + r[2][1] * d
    z = o[2] + r[0][2] * n + r[1][2] * e + r[2][2] * d
    return ecef_to_geodetic(x, y, z)


@njit(cache=True)
def _sea_level_to_geodetic(o: tuple, r: tuple, alt0: float, n: float, e: float) -> tuple[float, float]:
    d = (n * n + e * e) / (2.0 * WGS84_A)  # curvature drop, refined below
    for _ in range(3):
        lat, lon, h = _ned_to_geodetic(o, r, n, e, d)
        # Near the origin "down" is almost along the local vertical: Newton step on h(d).
        d += h - alt0
    lat, lon, _ = _ned_to_geodetic(o, r, n, e, d)
    return lat, lon


class LocalFrame:
    """NED tangent plane at (lat0 deg, lon0 deg, alt0 m above the ellipsoid)."""

    def __init__(self, lat0: float, lon0: float, alt0: float = 0.0) -> None:
        self.lat0, self.lon0, self.alt0 = lat0, lon0, alt0
        self._o = geodetic_to_ecef(float(lat0), float(lon0), float(alt0))
        lat, lon = math.radians(lat0), math.radians(lon0)
        sl, cl, so, co = math.sin(lat), math.cos(lat), math.sin(lon), math.cos(lon)
        # Rows: unit vectors north, east, down expressed in ECEF.
        self._r = ((-sl * co, -sl * so, cl), (-so, co, 0.0), (-cl * co, -cl * so, -sl))
        self.sea_level_to_geodetic(0.0, 0.0)   # compiled (or loaded from numba's cache) here, not in a frame

    def ned_to_geodetic(self, n: float, e: float, d: float) -> tuple[float, float, float]:
        """(lat deg, lon deg, h m) of the point n, e, d metres from the origin."""
        return _ned_to_geodetic(self._o, self._r, float(n), float(e), float(d))

    def geodetic_to_ned(self, lat: float, lon: float, h: float) -> tuple[float, float, float]:
        """(n, e, d) metres of a geodetic point in this frame."""
        x, y, z = geodetic_to_ecef(float(lat), float(lon), float(h))
        dx, dy, dz = x - self._o[0], y - self._o[1], z - self._o[2]
        r = self._r
        return tuple(row[0] * dx + row[1] * dy + row[2] * dz for row in r)

    def sea_level_to_geodetic(self, n: float, e: float) -> tuple[float, float]:
        """(lat deg, lon deg) of the point at height alt0 whose tangent-plane north/east are n, e."""
        return _sea_level_to_geodetic(self._o, self._r, float(self.alt0), float(n), float(e))

    def geodetic_to_sea_level(self, lat: float, lon: float) -> tuple[float, float]:
        """(n, e) metres of a point given by latitude/longitude at height alt0."""
        n, e, _ = self.geodetic_to_ned(lat, lon, self.alt0)
        return n, e
