"""Flat-earth NED <-> WGS-84: exact round trip, and distances against Vincenty's inverse formula."""

from __future__ import annotations

import math

import numpy as np
import pytest

from common.geodesy import WGS84_A, WGS84_F, LocalFrame, ecef_to_geodetic, geodetic_to_ecef


def vincenty_inverse(lat1, lon1, lat2, lon2):
    """Geodesic distance (m) on WGS-84 (Vincenty 1975), written here independently of the code under test."""
    a, f = WGS84_A, WGS84_F
    b = a * (1 - f)
    L = math.radians(lon2 - lon1)
    U1 = math.atan((1 - f) * math.tan(math.radians(lat1)))
    U2 = math.atan((1 - f) * math.tan(math.radians(lat2)))
    sU1, cU1, sU2, cU2 = math.sin(U1), math.cos(U1), math.sin(U2), math.cos(U2)
    lam = L
    for _ in range(200):
        sl, cl = math.sin(lam), math.cos(lam)
        s_sigma = math.hypot(cU2 * sl, cU1 * sU2 - sU1 * cU2 * cl)
        if s_sigma == 0:
            return 0.0
        c_sigma = sU1 * sU2 + cU1 * cU2 * cl
        sigma = math.atan2(s_sigma, c_sigma)
        s_alpha = cU1 * cU2 * sl / s_sigma
        c2_alpha = 1 - s_alpha ** 2
        c2sm = c_sigma - 2 * sU1 * sU2 / c2_alpha if c2_alpha else 0.0
        C = f / 16 * c2_alpha * (4 + f * (4 - 3 * c2_alpha))
        lam_prev = lam
        lam = L + (1 - C) * f * s_alpha * (sigma + C * s_sigma * (c2sm + C * c_sigma * (-1 + 2 * c2sm ** 2)))
        if abs(lam - lam_prev) < 1e-13:
            break
    u2 = c2_alpha * (a * a - b * b) / (b * b)
    A = 1 + u2 / 16384 * (4096 + u2 * (-768 + u2 * (320 - 175 * u2)))
    B = u2 / 1024 * (256 + u2 * (-128 + u2 * (74 - 47 * u2)))
    ds = B * s_sigma * (c2sm + B / 4 * (c_sigma * (-1 + 2 * c2sm ** 2)
                                        - B / 6 * c2sm * (-3 + 4 * s_sigma ** 2) * (-3 + 4 * c2sm ** 2)))
    return b * A * (sigma - ds)


@pytest.mark.parametrize("lat0,lon0", [(38.92, 121.65), (0.0, 0.0), (-60.0, -150.0), (70.0, 20.0)])
def test_distance_from_origin_matches_vincenty_to_2cm_at_10km(lat0, lon0):
    f = LocalFrame(lat0, lon0, 0.0)
    for bearing in np.linspace(0, 2 * math.pi, 12, endpoint=False):
        n, e = 10_000 * math.cos(bearing), 10_000 * math.sin(bearing)
        lat, lon = f.sea_level_to_geodetic(n, e)
        assert abs(vincenty_inverse(lat0, lon0, lat, lon) - 10_000.0) < 0.02


def test_round_trips_to_micrometres():
    f = LocalFrame(38.92, 121.65, 12.0)
    rng = np.random.default_rng(0)
    for n, e, d in rng.uniform(-10_000, 10_000, (50, 3)):
        lat, lon, h = f.ned_to_geodetic(n, e, d)
        assert f.geodetic_to_ned(lat, lon, h) == pytest.approx((n, e, d), abs=1e-6)
        lat, lon = f.sea_level_to_geodetic(n, e)
        assert f.geodetic_to_sea_level(lat, lon) == pytest.approx((n, e), abs=1e-6)
        assert f.ned_to_geodetic(*f.geodetic_to_ned(lat, lon, 12.0))[2] == pytest.approx(12.0, abs=1e-6)


def test_ecef_known_points():
    assert geodetic_to_ecef(0.0, 0.0, 0.0) == pytest.approx((WGS84_A, 0.0, 0.0))
    assert geodetic_to_ecef(90.0, 0.0, 0.0)[2] == pytest.approx(WGS84_A * (1 - WGS84_F))
    lat, lon, h = ecef_to_geodetic(*geodetic_to_ecef(45.0, 10.0, 100.0))
    assert (lat, lon, h) == pytest.approx((45.0, 10.0, 100.0), abs=1e-9)


def test_origin_and_axes():
    f = LocalFrame(38.92, 121.65, 0.0)
    assert f.sea_level_to_geodetic(0.0, 0.0) == pytest.approx((38.92, 121.65))
    lat, lon = f.sea_level_to_geodetic(100.0, 0.0)
    assert lat > 38.92 and lon == pytest.approx(121.65, abs=1e-9)  # north is north
    lat, lon = f.sea_level_to_geodetic(0.0, 100.0)
    assert lon > 121.65  # east is east


def test_map_and_ned_frames_convert_both_ways():
    import math

    from common.frames import map_to_ned, map_to_ned_path, ned_to_map

    # The chart's x east 30 m, y north 10 m, heading north (pi/2 from east) is NED (10, 30), psi 0.
    assert map_to_ned(30.0, 10.0, math.pi / 2) == (10.0, 30.0, 0.0)
    assert ned_to_map(*map_to_ned(3.0, -4.0, 0.3)) == pytest.approx((3.0, -4.0, 0.3))
    assert ned_to_map(1.0, 2.0) == (2.0, 1.0) and map_to_ned(2.0, 1.0) == (1.0, 2.0)
    assert map_to_ned_path([[1.0, 2.0], [3.0, 4.0]]).tolist() == [[2.0, 1.0], [4.0, 3.0]]


def test_compiled_conversions_compute_what_their_source_does():
    """The conversions are compiled by numba; each must give, bit for bit, what its Python source
    gives (sqrt and pow are the same in both; CPython's hypot is not the C library's)."""
    from common.geodesy import _ned_to_geodetic, _sea_level_to_geodetic

    rng = np.random.default_rng(7)
    points = zip(rng.uniform(-89.9, 89.9, 4000), rng.uniform(-180, 180, 4000), rng.normal(0, 2000, 4000), strict=True)
    for lat, lon, h in points:
        xyz = geodetic_to_ecef.py_func(lat, lon, h)
        assert geodetic_to_ecef(lat, lon, h) == xyz
        assert ecef_to_geodetic(*xyz) == ecef_to_geodetic.py_func(*xyz)
    for lat0, lon0, alt0 in [(31.2, 121.5, 0.0), (-45.0, 170.0, 10.0), (89.0, -3.0, 0.0)]:
        f = LocalFrame(lat0, lon0, alt0)
        for n, e in rng.normal(0, 5000, (500, 2)):
            n, e = float(n), float(e)
            assert _ned_to_geodetic(f._o, f._r, n, e, 3.0) == _ned_to_geodetic.py_func(f._o, f._r, n, e, 3.0)
            assert f.sea_level_to_geodetic(n, e) == _sea_level_to_geodetic.py_func(f._o, f._r, float(alt0), n, e)
