"""Curvilinear current files (common.current_sources): a ROMS history file's layout (a grid turned against
north, lat_rho/lon_rho, mask_rho, u_eastward/v_northward or grid-relative u/v with angle, ocean_time,
s_rho) and a CF file whose ``coordinates`` attribute names 2-D latitude/longitude, written with netCDF4
itself (tests/support/world_files.py), read against the analytic field they were written from."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("xarray")
pytest.importorskip("netCDF4")

from support.world_files import LAT0, LON0, write_cf_current, write_curvilinear_current  # noqa: E402

from common.current_sources import CurrentSourceError, load_file  # noqa: E402
from common.geodesy import LocalFrame  # noqa: E402
from hil import scenario as scenarios  # noqa: E402
from hil.config import CONFIG_DIR  # noqa: E402
from hil.errors import ConfigError  # noqa: E402

FRAME = LocalFrame(LAT0, LON0)
RNG = np.random.default_rng(11)
# Water points (n, e, t): inside the default grid (41 x 45 nodes 25 m apart, xi 30 deg from east, centred
# 100 m north, 120 m east), at least 70 m from the land east of e = 450 m, over the file's two hours.
WATER = RNG.uniform([-100.0, -100.0, 0.0], [300.0, 380.0, 7200.0], (400, 3))


def _e_linear(t, n, e):   # eastward m/s, linear in NED metres and time
    return 0.2 + 4e-4 * e + 1e-4 * n + 0.05 * t / 3600.0


def _n_linear(t, n, e):
    return -0.1 + 3e-4 * n - 2e-4 * e + 0.0 * t


A, K = 0.3, 2.0 * math.pi / 1000.0     # m/s, rad/m: eddies of 1 km


def _e_wave(t, n, e):
    return 0.2 + A * np.sin(K * n) * np.cos(K * e)


def _n_wave(t, n, e):
    return -0.1 + A * np.cos(K * n) * np.sin(K * e)


# Interpolation error bound for the eddies (m/s). Their Hessian's norm is at most M = A K^2 (its eigenvalues
# are A K^2 (-sin Kn cos Ke +- cos Kn sin Ke)). Linear interpolation on a triangle errs by at most
# M/2 max|x_i - x|^2 (Taylor about x; the weights sum to 1 and reproduce x), with max|x_i - x| at most
# the cell's diagonal (25 m x sqrt 2); the NED grid's bilinear interpolation of those values (nodes at most
# 12.5 m apart, half the file's spacing) adds at most M/2 (2 x 12.5^2).
BOUND = 0.5 * A * K**2 * (2 * 25.0**2 + 2 * 12.5**2)        # 0.0092 m/s (3 % of A)


def _land(n, e):
    return e > 450.0


def _check(g, east, north, pts, tol):
    vn, ve = g.velocity(pts[:, 0], pts[:, 1], pts[:, 2])
    err_n = np.abs(vn - north(pts[:, 2], pts[:, 0], pts[:, 1]))
    err_e = np.abs(ve - east(pts[:, 2], pts[:, 0], pts[:, 1]))
    assert err_n.max() <= tol and err_e.max() <= tol, (err_n.max(), err_e.max())
    for (n, e, t), a, b in zip(pts[:40], vn, ve, strict=False):
        assert g.velocity_at(n, e, t) == pytest.approx((a, b), abs=1e-12)
    return max(err_n.max(), err_e.max())


@pytest.mark.parametrize("layout, grid_relative", [("roms", False), ("roms", True), ("cf", False)])
def test_a_turned_grid_reproduces_a_linear_field(tmp_path, layout, grid_relative):
    """Linear in metres: the triangles and the NED grid reproduce it; only float32 storage differs."""
    path = write_curvilinear_current(tmp_path / "c.nc", FRAME, _e_linear, _n_linear, layout=layout,
                                     grid_relative=grid_relative, land=_land)
    g = load_file(str(path), FRAME)
    assert g.time_span() == (0.0, 7200.0)
    _check(g, _e_linear, _n_linear, WATER, 1e-6)


def test_roms_land_reads_as_still_water(tmp_path):
    """Land by fill value (south of 100 m north) and by mask_rho alone (north of it, a decoy 5 m/s written)."""
    g = load_file(str(write_curvilinear_current(tmp_path / "c.nc", FRAME, _e_linear, _n_linear, land=_land)), FRAME)
    for lo, hi in ((-150.0, 0.0), (200.0, 300.0)):
        pts = RNG.uniform([lo, 520.0, 0.0], [hi, 600.0, 7200.0], (50, 3))
        vn, ve = g.velocity(pts[:, 0], pts[:, 1], pts[:, 2])
        assert np.all(vn == 0.0) and np.all(ve == 0.0)


@pytest.mark.parametrize("layout", ["roms", "cf"])
def test_eddies_are_read_within_the_interpolation_bound(tmp_path, layout):
    path = write_curvilinear_current(tmp_path / "c.nc", FRAME, _e_wave, _n_wave, layout=layout)
    err = _check(load_file(str(path), FRAME), _e_wave, _n_wave, WATER, BOUND)
    assert err > 1e-5     # the bound is not met trivially: the field is curved at this spacing


def test_a_rectilinear_and_a_curvilinear_file_give_the_same_current(tmp_path):
    curv = load_file(str(write_curvilinear_current(tmp_path / "curv.nc", FRAME, _e_wave, _n_wave)), FRAME)
    lat0, lon0 = FRAME.sea_level_to_geodetic(-300.0, -300.0)
    lat1, lon1 = FRAME.sea_level_to_geodetic(500.0, 550.0)

    def as_latlon(f):
        def g(t_h, lat, lon):
            ne = np.array([FRAME.geodetic_to_sea_level(a, b) for a, b in zip(lat.ravel(), lon.ravel(), strict=True)])
            return f(t_h * 3600.0, ne[:, 0].reshape(lat.shape), ne[:, 1].reshape(lat.shape))
        return g

    # 25 m apart, as the curvilinear file: the bilinear path errs by at most M/2 (2 x 25^2) twice over
    lat, lon = np.linspace(lat0, lat1, 33), np.linspace(lon0, lon1, 35)
    rect = load_file(str(write_cf_current(tmp_path / "rect.nc", lat, lon, None, as_latlon(_e_wave),
                                          as_latlon(_n_wave))), FRAME)
    vn_c, ve_c = curv.velocity(WATER[:, 0], WATER[:, 1], 0.0)
    vn_r, ve_r = rect.velocity(WATER[:, 0], WATER[:, 1], 0.0)
    bound_rect = 2 * 0.5 * A * K**2 * 2 * 25.0**2
    assert np.abs(vn_c - vn_r).max() <= BOUND + bound_rect
    assert np.abs(ve_c - ve_r).max() <= BOUND + bound_rect
    assert np.abs(vn_c - vn_r).max() < 0.1 * A          # and far closer than the field's own variation


SCENARIO = """name = "t"
description = "harbour with a curvilinear current file"
kind = "fixed"
map = "{map}"
resolution = 0.5
start = [22.0, 40.0]
goal = [185.0, 140.0]
[current]
file = "roms.nc"
field_time = 1800.0
"""


def _scenario(tmp_path: Path) -> str:
    p = tmp_path / "s.toml"
    p.write_text(SCENARIO.format(map=CONFIG_DIR / "maps" / "harbour.npy"))
    return str(p)


def test_a_scenario_with_a_roms_file_loads_and_plans_with_it(tmp_path):
    write_curvilinear_current(tmp_path / "roms.nc", FRAME, _e_linear, _n_linear, land=_land)
    scen = scenarios.load(_scenario(tmp_path))
    f = scen.map_field()            # map frame: (x east, y north) -> (v_east, v_north) at field_time
    for x, y in ((10.0, 10.0), (150.0, 120.0), (199.0, 149.0)):
        assert f(x, y) == pytest.approx((_e_linear(1800.0, y, x), _n_linear(1800.0, y, x)), abs=1e-6)
    assert scen.planning_field().at(150.0, 120.0) == pytest.approx(f(150.0, 120.0), abs=1e-6)
    scen.check_current_time(7200.0)
    with pytest.raises(ConfigError, match="does not cover the run's time"):
        scen.check_current_time(7300.0)


@pytest.mark.parametrize("shape, centre, message", [
    ((41, 45), (3000.0, 3000.0), "does not cover the 200 m x 150 m map .it covers north 2"),
    # a diamond (45 deg) 200 m across its sides, centred on the map: its bounding box holds the map, the
    # diamond not its corners
    ((9, 9), (75.0, 100.0), "does not cover the 200 m x 150 m map .* .not all of it: a curvilinear grid."),
])
def test_a_file_that_does_not_cover_the_map_is_refused_in_one_line(tmp_path, shape, centre, message):
    write_curvilinear_current(tmp_path / "roms.nc", FRAME, _e_linear, _n_linear, shape=shape, centre=centre,
                              angle_deg=45.0)
    with pytest.raises(ConfigError, match=message) as err:
        scenarios.load(_scenario(tmp_path))
    assert "\n" not in str(err.value)


def test_the_same_diamond_a_little_larger_covers_the_map(tmp_path):
    write_curvilinear_current(tmp_path / "roms.nc", FRAME, _e_linear, _n_linear, shape=(13, 13),
                              centre=(75.0, 100.0), angle_deg=45.0)
    assert scenarios.load(_scenario(tmp_path)).map_field() is not None


def _without_angle(path: Path) -> Path:
    import netCDF4

    with netCDF4.Dataset(path, "a") as ds:
        ds.renameVariable("angle", "theta")
    return path


def _staggered_only(path: Path) -> Path:
    """ROMS's u, v on their own points (eta_u, xi_u / eta_v, xi_v), without u_eastward/v_northward."""
    import netCDF4

    with netCDF4.Dataset(path, "w") as ds:
        for name, size in (("eta_u", 4), ("xi_u", 3), ("eta_v", 3), ("xi_v", 4)):
            ds.createDimension(name, size)
        for name, dims, std in (("u", ("eta_u", "xi_u"), "sea_water_x_velocity_at_u_location"),
                                ("v", ("eta_v", "xi_v"), "sea_water_y_velocity_at_v_location")):
            var = ds.createVariable(name, "f4", dims)
            var.standard_name = std
            var[:] = np.zeros((4, 3) if name == "u" else (3, 4))
    return path


@pytest.mark.parametrize("make, message", [
    (lambda p: write_curvilinear_current(p, FRAME, lambda t, n, e: 0 * n + 12.0, _n_linear),
     "a current of 12 m/s is not a sea current"),
    (lambda p: _without_angle(write_curvilinear_current(p, FRAME, _e_linear, _n_linear, grid_relative=True)),
     "u, v are grid-relative .standard_name sea_water_x_velocity.... and the file has no grid angle"),
    (_staggered_only, "u and v are on different dimensions .grid-relative u, v on staggered points"),
    (lambda p: write_curvilinear_current(p, FRAME, _e_linear, _n_linear, shape=(1, 5)),
     "a curvilinear grid needs at least 2 x 2 nodes"),
    # at the antipode: on the tangent plane it would lie right over the origin's area
    (lambda p: write_curvilinear_current(p, LocalFrame(-LAT0, LON0 - 180.0), _e_linear, _n_linear),
     "its curvilinear grid has no node within 1000 km of the origin"),
])
def test_unusable_curvilinear_files_are_refused_in_one_line(tmp_path, make, message):
    with pytest.raises(CurrentSourceError, match=message) as err:
        load_file(str(make(tmp_path / "c.nc")), FRAME)
    assert "\n" not in str(err.value)
