"""Current sources (common.current_sources): a CF netCDF file, a uniform current and eq. (13), the same
source in the simulator and in the planner's field; files that do not fit are refused in one line."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("xarray")
pytest.importorskip("netCDF4")

from support.world_files import LAT0, LON0, metres_box, write_cf_current  # noqa: E402

from common.current_sources import CurrentSourceError, GriddedCurrent, UniformCurrent, load_file  # noqa: E402
from common.geodesy import LocalFrame  # noqa: E402
from hil import scenario as scenarios  # noqa: E402
from hil.assembly.simulator import simulator_settings  # noqa: E402
from hil.config import CONFIG_DIR  # noqa: E402
from hil.errors import ConfigError  # noqa: E402
from hil.settings import load  # noqa: E402
from simulator.core import SimulatorCore  # noqa: E402

FRAME = LocalFrame(LAT0, LON0)
HOURS = ["2024-05-01T00:00:00", "2024-05-01T01:00:00", "2024-05-01T02:00:00", "2024-05-01T03:00:00"]


def _u(t, lat, lon):   # eastward: grows eastward and with time
    return 0.2 + 40.0 * (lon - LON0) + 0.05 * t


def _v(t, lat, lon):   # northward: grows northward
    return -0.1 + 30.0 * (lat - LAT0) + 0.0 * t


def _harbour_file(path: Path, south=-150.0, west=-150.0, north=350.0, east=400.0, times=HOURS, n=21) -> Path:
    la0, lo0, la1, lo1 = metres_box(FRAME, south, west, north, east)
    return write_cf_current(path, np.linspace(la0, la1, n), np.linspace(lo0, lo1, n), times, _u, _v)


def _expected(north, east, t_s):
    lat, lon = FRAME.sea_level_to_geodetic(north, east)
    return _v(t_s / 3600.0, lat, lon), _u(t_s / 3600.0, lat, lon)


def test_a_cf_file_is_read_by_standard_name_and_interpolated_in_space_and_time(tmp_path):
    g = load_file(str(_harbour_file(tmp_path / "c.nc")), FRAME)
    assert isinstance(g, GriddedCurrent)
    assert g.time_span() == (0.0, 3 * 3600.0)
    rng = np.random.default_rng(3)
    pts = rng.uniform([-100, -100, 0], [300, 350, 3 * 3600], (50, 3))
    vn, ve = g.velocity(pts[:, 0], pts[:, 1], pts[:, 2])
    for (n, e, t), a, b in zip(pts, vn, ve, strict=True):
        exp_n, exp_e = _expected(n, e, t)
        # a linear field in latitude/longitude: only float32 storage and the NED resampling differ
        assert (a, b) == pytest.approx((exp_n, exp_e), abs=1e-4)
        assert g.velocity_at(n, e, t) == pytest.approx((a, b), abs=1e-12)
    # between two hourly slices: linear in time
    assert g.velocity_at(0.0, 0.0, 1800.0)[1] == pytest.approx(0.2 + 0.025, abs=1e-4)


def test_start_time_shifts_the_run_onto_the_file(tmp_path):
    g = load_file(str(_harbour_file(tmp_path / "c.nc")), FRAME, start_time="2024-05-01T01:00:00Z")
    assert g.time_span() == (-3600.0, 7200.0)
    assert g.velocity_at(0.0, 0.0, 0.0)[1] == pytest.approx(0.25, abs=1e-4)


def test_named_variables_in_cm_per_s_with_depth_descending_latitude_and_0_360_longitude(tmp_path):
    """A HYCOM-like file written with netCDF4 itself: water_u/water_v without standard names, in
    cm/s, on (time, depth, lat, lon) with latitude north to south and longitudes 0..360."""
    import netCDF4

    la0, lo0, la1, lo1 = metres_box(FRAME, -150.0, -150.0, 350.0, 400.0)
    lat = np.linspace(la1, la0, 11)                # north to south
    lon = np.linspace(lo0, lo1, 13) + 360.0 * (LON0 < 0)
    path = tmp_path / "hycom.nc"
    with netCDF4.Dataset(path, "w") as ds:
        for name, size in (("time", None), ("depth", 2), ("lat", lat.size), ("lon", lon.size)):
            ds.createDimension(name, size)
        t = ds.createVariable("time", "f8", ("time",))
        t.units, t.calendar = "hours since 2000-01-01 00:00:00", "standard"
        t[:] = [215000.0, 215003.0]
        d = ds.createVariable("depth", "f4", ("depth",))
        d.units, d.positive = "m", "down"
        d[:] = [0.0, 10.0]
        ds.createVariable("lat", "f8", ("lat",))[:] = lat
        ds.createVariable("lon", "f8", ("lon",))[:] = lon
        for name, value in (("water_u", 30.0), ("water_v", -20.0)):
            var = ds.createVariable(name, "f4", ("time", "depth", "lat", "lon"), fill_value=-30000.0)
            var.units = "cm/s"
            data = np.full((2, 2, lat.size, lon.size), value, dtype="f4")
            data[:, 1] = 999.0                     # a deeper level: not the surface
            data[:, :, 0, 0] = -30000.0            # a land cell: still water
            var[:] = data
    g = load_file(str(path), FRAME, east_variable="water_u", north_variable="water_v")
    assert g.velocity_at(100.0, 100.0, 0.0) == pytest.approx((-0.2, 0.3), abs=1e-6)
    assert g.time_span() == (0.0, 3 * 3600.0)
    with pytest.raises(CurrentSourceError, match="no variable with standard_name"):
        load_file(str(path), FRAME)


def test_a_steady_file_has_no_time_limit(tmp_path):
    g = load_file(str(_harbour_file(tmp_path / "s.nc", times=None)), FRAME)
    assert g.time_span() == (-math.inf, math.inf)
    g.check_covers(t=(0.0, 1e6))
    assert g.velocity_at(0.0, 0.0, 5e5) == pytest.approx((-0.1, 0.2), abs=1e-4)


def _station_file(path: Path, layout: str) -> Path:
    """A moored ADCP's series as its tools write one: velocity on time alone, the position as one-value
    latitude/longitude (or as dimensions of size 1), 400 m east of the origin, hourly for 2 h."""
    import xarray as xr

    la, lo = FRAME.sea_level_to_geodetic(0.0, 400.0)
    times = np.array(HOURS[:3], dtype="datetime64[ns]")
    u, v = np.array([0.1, 0.3, -0.2]), np.array([0.0, 0.05, 0.1])
    attrs_u = {"standard_name": "eastward_sea_water_velocity", "units": "cm s-1"}
    attrs_v = {"standard_name": "northward_sea_water_velocity", "units": "cm s-1"}
    if layout == "scalar":
        ds = xr.Dataset({"u": (("time",), u * 100, attrs_u), "v": (("time",), v * 100, attrs_v)},
                        coords={"time": times, "lat": ((), la, {"units": "degrees_north"}),
                                "lon": ((), lo, {"units": "degrees_east"})})
    else:
        dims = ("time", "latitude", "longitude")
        ds = xr.Dataset({"u": (dims, (u * 100)[:, None, None], attrs_u),
                         "v": (dims, (v * 100)[:, None, None], attrs_v)},
                        coords={"time": times, "latitude": [la], "longitude": [lo]})
    ds.to_netcdf(path)
    return path


@pytest.mark.parametrize("layout", ["scalar", "size-1 dimensions"])
def test_a_single_stations_series_is_the_current_over_the_whole_map(tmp_path, layout):
    g = load_file(str(_station_file(tmp_path / "adcp.nc", layout)), FRAME)
    # half an hour: half-way between the first two samples, wherever the boat is
    assert g.velocity_at(-3000.0, 5000.0, 1800.0) == pytest.approx((0.025, 0.2), abs=1e-9)
    assert g.velocity_at(0.0, 0.0, 1800.0) == pytest.approx((0.025, 0.2), abs=1e-9)
    vn, ve = g.velocity(np.array([0.0, 2e4]), np.array([0.0, -2e4]), 5400.0)
    np.testing.assert_allclose(vn, [0.075, 0.075], atol=1e-9)
    np.testing.assert_allclose(ve, [0.05, 0.05], atol=1e-9)
    g.check_covers((-1e4, 1e4), (-1e4, 1e4), (0.0, 7200.0))       # any map; its two hours
    with pytest.raises(CurrentSourceError, match="does not cover the run's time"):
        g.check_covers(t=(0.0, 7300.0))


def test_a_station_far_from_the_origin_is_refused_in_one_line(tmp_path):
    import xarray as xr

    la, lo = FRAME.sea_level_to_geodetic(30_000.0, 0.0)              # 30 km north
    ds = xr.Dataset({"u": (("time",), [0.1, 0.2], {"standard_name": "eastward_sea_water_velocity"}),
                     "v": (("time",), [0.0, 0.1], {"standard_name": "northward_sea_water_velocity"})},
                    coords={"time": np.array(HOURS[:2], dtype="datetime64[ns]"), "lat": la, "lon": lo})
    ds.to_netcdf(tmp_path / "far.nc")
    with pytest.raises(CurrentSourceError, match="is 30 km from the origin; a station's current is used within 20 km"):
        load_file(str(tmp_path / "far.nc"), FRAME)


def test_an_upward_looking_adcp_gives_its_top_bin(tmp_path):
    """A bottom-mounted ADCP's bins are heights above the bed (``positive = "up"``), on a dimension of its
    own name: the top bin is the one nearest the surface."""
    import xarray as xr

    la, lo = FRAME.sea_level_to_geodetic(0.0, 0.0)
    east = np.array([[0.9, 0.6, 0.4, 0.2], [0.8, 0.5, 0.3, 0.1]])      # [time, bin]: slower towards the top
    ds = xr.Dataset({"u": (("time", "bin"), east, {"standard_name": "eastward_sea_water_velocity"}),
                     "v": (("time", "bin"), 0.5 * east, {"standard_name": "northward_sea_water_velocity"})},
                    coords={"time": np.array(HOURS[:2], dtype="datetime64[ns]"),
                            "bin": ("bin", [1.0, 3.0, 5.0, 7.0], {"positive": "up", "units": "m",
                                                                  "long_name": "height above the bed"}),
                            "latitude": la, "longitude": lo})
    ds.to_netcdf(tmp_path / "adcp.nc")
    g = load_file(str(tmp_path / "adcp.nc"), FRAME)
    assert g.velocity_at(10.0, -10.0, 0.0) == (0.1, 0.2)
    assert g.velocity_at(10.0, -10.0, 3600.0) == (0.05, 0.1)


def _calendar_file(path: Path, calendar: str, first: str) -> Path:
    import xarray as xr

    la0, lo0, la1, lo1 = metres_box(FRAME, -150.0, -150.0, 350.0, 400.0)
    lat, lon = np.linspace(la0, la1, 3), np.linspace(lo0, lo1, 3)
    east = np.array([0.1, 0.2, 0.4])[:, None, None] * np.ones((3, 3, 3))
    ds = xr.Dataset({"uo": (("time", "lat", "lon"), east, {"standard_name": "eastward_sea_water_velocity"}),
                     "vo": (("time", "lat", "lon"), -east, {"standard_name": "northward_sea_water_velocity"})},
                    coords={"time": ("time", [0.0, 1.0, 2.0],
                                     {"units": f"hours since {first}", "calendar": calendar}),
                            "lat": lat, "lon": lon})
    ds.to_netcdf(path)
    return path


def test_a_model_calendar_without_leap_days_is_read(tmp_path):
    path = str(_calendar_file(tmp_path / "noleap.nc", "noleap", "2023-03-01 00:00:00"))
    g = load_file(path, FRAME)
    assert g.time_span() == (0.0, 7200.0)
    assert g.velocity_at(0.0, 0.0, 5400.0) == pytest.approx((-0.3, 0.3), abs=1e-12)
    shifted = load_file(path, FRAME, start_time="2023-03-01T01:00:00Z")       # the run starts at the 2nd slice
    assert shifted.velocity_at(0.0, 0.0, 0.0) == pytest.approx((-0.2, 0.2), abs=1e-12)


def test_a_first_date_the_standard_calendar_lacks_is_refused_in_one_line(tmp_path):
    path = str(_calendar_file(tmp_path / "360.nc", "360_day", "2023-02-30 00:00:00"))
    with pytest.raises(CurrentSourceError, match="first date 2023-02-30 00:00:00 .calendar 360_day. is no date") as err:
        load_file(path, FRAME)
    assert "\n" not in str(err.value)


def test_a_scenario_with_a_stations_series_plans_with_it_everywhere(tmp_path):
    _station_file(tmp_path / "adcp.nc", "scalar")
    scen = scenarios.load(str(_scenario(tmp_path, 'file = "adcp.nc"\nfield_time = 3600.0\n')))
    f = scen.map_field()           # map frame: (x east, y north) -> (v_east, v_north)
    assert f(10.0, 10.0) == pytest.approx((0.3, 0.05), abs=1e-9) == f(190.0, 140.0)
    assert scen.planning_field().at(150.0, 120.0) == pytest.approx((0.3, 0.05), abs=1e-6)


def _write_bad(path: Path, kind: str) -> Path:
    import xarray as xr

    la0, lo0, la1, lo1 = metres_box(FRAME, -150.0, -150.0, 350.0, 400.0)
    lat, lon = np.linspace(la0, la1, 5), np.linspace(lo0, lo1, 5)
    attrs_u = {"standard_name": "eastward_sea_water_velocity", "units": "m s-1"}
    attrs_v = {"standard_name": "northward_sea_water_velocity", "units": "m s-1"}
    u = np.full((5, 5), 0.3)
    if kind == "text":
        path.write_text("not a netCDF file\n")
        return path
    if kind == "units":
        attrs_u["units"] = "knots per fortnight"
    if kind == "fast":
        u = np.full((5, 5), 30.0)
    if kind == "missing":
        u[:] = np.nan
    if kind == "row":
        lat, u = lat[:1], u[:1]
    if kind == "unplaced":   # 2-D positions that say nothing of being latitude/longitude
        LA, LO = np.meshgrid(lat, lon, indexing="ij")
        ds = xr.Dataset({"uo": (("y", "x"), u, attrs_u), "vo": (("y", "x"), u, attrs_v)},
                        coords={"yy": (("y", "x"), LA), "xx": (("y", "x"), LO)})
        ds.to_netcdf(path)
        return path
    ds = xr.Dataset({"uo": (("latitude", "longitude"), u, attrs_u),
                     "vo": (("latitude", "longitude"), u, attrs_v)},
                    coords={"latitude": lat, "longitude": lon})
    if kind == "novelocity":
        ds = ds.rename({"uo": "speed"}).drop_vars("vo")
        ds["speed"].attrs = {"units": "m s-1"}
    ds.to_netcdf(path)
    return path


@pytest.mark.parametrize("kind, message", [
    ("text", "cannot be read as netCDF"),
    ("units", "units .knots per fortnight. not understood"),
    ("fast", "42.4 m/s is not a sea current"),
    ("missing", "every velocity value is missing"),
    ("unplaced", "no latitude/longitude .1-D axes or a curvilinear grid's 2-D coordinates. and no single station"),
    ("row", "needs at least 2 latitudes and 2 longitudes, or one station \\(has 1 x 5\\)"),
    ("novelocity", "no variable with standard_name 'eastward_sea_water_velocity'"),
])
def test_unusable_files_are_refused_in_one_line(tmp_path, kind, message):
    with pytest.raises(CurrentSourceError, match=message) as err:
        load_file(str(_write_bad(tmp_path / f"{kind}.nc", kind)), FRAME)
    assert "\n" not in str(err.value)


SCENARIO = """name = "t"
description = "harbour with a current file"
kind = "fixed"
map = "{map}"
resolution = 0.5
start = [22.0, 40.0]
goal = [185.0, 140.0]
{extra}
"""


def _scenario(tmp_path: Path, current: str, extra: str = "") -> Path:
    p = tmp_path / "s.toml"
    p.write_text(SCENARIO.format(map=CONFIG_DIR / "maps" / "harbour.npy", extra=extra) + "[current]\n" + current)
    return p


def test_a_scenario_names_its_file_relative_to_itself_and_the_planner_gets_its_field(tmp_path):
    _harbour_file(tmp_path / "c.nc")
    scen = scenarios.load(str(_scenario(tmp_path, 'file = "c.nc"\nfield_time = 1800.0\n')))
    assert Path(scen.current.file) == (tmp_path / "c.nc").resolve()
    f = scen.map_field()           # map frame: (x east, y north) -> (v_east, v_north) at field_time
    for x, y in ((10.0, 10.0), (150.0, 120.0)):
        exp_n, exp_e = _expected(y, x, 1800.0)
        assert f(x, y) == pytest.approx((exp_e, exp_n), abs=1e-4)
    grid = scen.planning_field()   # the planner's eq. (12) field: the same numbers on its grid
    assert grid.at(150.0, 120.0) == pytest.approx(f(150.0, 120.0), abs=1e-4)


@pytest.mark.parametrize("box, current, message", [
    ((0.0, 0.0, 100.0, 400.0), 'file = "c.nc"\n', "does not cover the 200 m x 150 m map"),
    ((-150.0, -150.0, 350.0, 400.0), 'file = "c.nc"\nfield_time = 20000.0\n', "does not cover the run's time"),
    ((-150.0, -150.0, 350.0, 400.0), 'file = "c.nc"\nstart_time = "2024-06-01T00:00:00"\n',
     "does not cover the run's time"),
    ((-150.0, -150.0, 350.0, 400.0), 'file = "c.nc"\nstart_time = "yesterday"\n', "not an ISO 8601 time"),
    ((-150.0, -150.0, 350.0, 400.0), 'file = "none.nc"\n', "no such file"),
    ((-150.0, -150.0, 350.0, 400.0), 'file = "c.nc"\nuniform = [1.0, 0.0]\n', "not both"),
    ((-150.0, -150.0, 350.0, 400.0), 'uniform = [1.0]\n', "expected \\[east, north\\]"),
    ((-150.0, -150.0, 350.0, 400.0), 'uniform = [12.0, 0.0]\n', "must be <= 10.0"),
    ((-150.0, -150.0, 350.0, 400.0), 'uniform = [8.0, 8.0]\n', "is not a sea current"),
])
def test_a_current_that_does_not_fit_is_refused_in_one_line(tmp_path, box, current, message):
    s, w, n, e = box
    _harbour_file(tmp_path / "c.nc", south=s, west=w, north=n, east=e)
    with pytest.raises(ConfigError, match=message) as err:
        scenarios.load(str(_scenario(tmp_path, current)))
    assert "\n" not in str(err.value)


def test_the_run_time_is_checked_against_the_file(tmp_path):
    _harbour_file(tmp_path / "c.nc")
    scen = scenarios.load(str(_scenario(tmp_path, 'file = "c.nc"\n')))
    scen.check_current_time(3 * 3600.0)
    with pytest.raises(ConfigError, match="does not cover the run's time") as err:
        scen.check_current_time(4 * 3600.0)
    assert "\n" not in str(err.value)


def test_a_uniform_current_is_the_same_everywhere_for_the_planner(tmp_path):
    scen = scenarios.load(str(_scenario(tmp_path, "uniform = [1.0, -0.25]\n")))
    assert isinstance(scen.current_field(), UniformCurrent)
    grid = scen.planning_field()
    for x, y in ((0.0, 0.0), (199.0, 149.0), (80.0, 30.0)):
        assert grid.at(x, y) == pytest.approx((1.0, -0.25))


def test_eq13_stays_the_default_source():
    from common.current_field import CurrentField

    assert isinstance(scenarios.load("harbour").current_field(), CurrentField)


def _drift(cfg, seconds: float) -> tuple[float, float]:
    """Ground velocity (north, east) of an unpowered hull after ``seconds`` in the simulator."""
    core = SimulatorCore(simulator_settings(cfg))
    frames = int(round(seconds / core.frame_dt))
    for _ in range(frames):
        core.step()
    n0, e0 = core.state[0], core.state[1]
    for _ in range(int(round(2.0 / core.frame_dt))):
        core.step()
    return (core.state[0] - n0) / 2.0, (core.state[1] - e0) / 2.0


@pytest.mark.parametrize("kind", ["uniform", "file"])
def test_the_simulated_boat_drifts_with_the_same_current(tmp_path, kind):
    """An unpowered boat at rest picks up the current the scenario's planner plans with."""
    calm = ["waves.enabled=false", "current.enabled=true"]
    if kind == "uniform":
        overrides = [*calm, "current.uniform=[1.0, 0.0]"]      # the 1 m/s cross-current case
    else:
        path = _harbour_file(tmp_path / "c.nc", times=None)
        overrides = [*calm, f"current.file={str(path)!r}"]
    cfg = load(None, overrides)
    vn, ve = _drift(cfg, 60.0)
    source = SimulatorCore(simulator_settings(cfg)).current
    exp_n, exp_e = source.velocity_at(0.0, 0.0, 60.0)
    assert math.hypot(exp_n, exp_e) > 0.15
    # the drift carries the boat some metres: compare with the current where it is now
    assert (vn, ve) == pytest.approx((exp_n, exp_e), abs=0.03)


def test_one_time_slice_is_a_steady_current_and_units_are_read_as_written(tmp_path):
    import xarray as xr

    la0, lo0, la1, lo1 = metres_box(FRAME, -150.0, -150.0, 350.0, 400.0)
    lat, lon = np.linspace(la0, la1, 4), np.linspace(lo0, lo1, 4)
    for units, value, expected in (("meters per second", 0.3, 0.3), ("knots", 1.0, 0.514444), ("m s^-1", 0.2, 0.2)):
        ds = xr.Dataset({name: (("time", "lat", "lon"), np.full((1, 4, 4), value),
                                {"standard_name": f"{d}ward_sea_water_velocity", "units": units})
                         for name, d in (("u", "east"), ("v", "north"))},
                        coords={"time": np.array(["2024-05-01T00:00"], dtype="datetime64[ns]"),
                                "lat": ("lat", lat, {"units": "degrees_north"}),
                                "lon": ("lon", lon, {"units": "degrees_east"})})
        path = tmp_path / f"{value}.nc"
        ds.to_netcdf(path)
        g = load_file(str(path), FRAME)
        assert g.time_span() == (-math.inf, math.inf)
        assert g.velocity_at(10.0, 10.0, 1e5) == pytest.approx((expected, expected), abs=1e-9)


def test_the_scenarios_source_replaces_the_configurations(tmp_path):
    """A configured uniform current gives way to a scenario's file, and a configured file to a
    scenario's uniform current (both in one table is refused)."""
    _harbour_file(tmp_path / "c.nc")
    base = load(None, ["current.uniform=[0.5, 0.0]"]).current
    scen = scenarios.load(str(_scenario(tmp_path, 'file = "c.nc"\n')), base)
    assert isinstance(scen.current_field(), GriddedCurrent) and scen.current.uniform == ()
    base = load(None, [f"current.file={str(tmp_path / 'c.nc')!r}"]).current
    scen = scenarios.load(str(_scenario(tmp_path, "uniform = [0.0, 1.0]\n")), base)
    assert isinstance(scen.current_field(), UniformCurrent) and scen.current.file == ""
