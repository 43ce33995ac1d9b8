"""A regional or global current file is read only around the run (common/current_sources.py: ``reach``):
the nodes near the origin, across a 0/360 seam too, the same current there as the whole file gives,
a scenario's reach from its map, and a file too large even so refused in one line."""

from __future__ import annotations

import math

import numpy as np
import pytest

pytest.importorskip("xarray")

from support.world_files import write_cf_current  # noqa: E402

from common import current_sources  # noqa: E402
from common.current_sources import CurrentSourceError, load_file, read_netcdf  # noqa: E402
from common.geodesy import LocalFrame  # noqa: E402


def _smooth_east(t, la, lo):
    return 0.2 + 0.5 * np.sin(np.radians(lo)) + 0.0 * t      # smooth across the 0/360 seam


def _smooth_north(t, la, lo):
    return 0.1 + 0.3 * np.cos(np.radians(4.0 * la)) + 0.01 * t


def test_a_global_file_is_read_near_the_origin_only_and_across_its_seam(tmp_path):
    """A global 0..360 file at 0.25 deg, the origin at Greenwich (longitude -0.05 = 359.95)."""
    path = write_cf_current(tmp_path / "global.nc", np.arange(-80.0, 80.01, 0.25), np.arange(0.0, 360.0, 0.25),
                            ["2024-05-01T00:00", "2024-05-01T01:00"], _smooth_east, _smooth_north)
    frame = LocalFrame(51.48, -0.05)
    raw = read_netcdf(str(path), near=(frame.lat0, frame.lon0, 5_000.0))
    assert raw.lat.size <= 4 and raw.lon.size <= 6          # a handful of nodes, not 641 x 1440
    assert np.all(np.diff(raw.lon) > 0) and raw.lon.min() < -0.05 < raw.lon.max()   # put in order over the seam
    g = load_file(str(path), frame, reach=5_000.0)
    for north, east in ((0.0, 0.0), (800.0, -1200.0), (-1500.0, 900.0)):
        lat, lon = frame.sea_level_to_geodetic(north, east)
        ve, vn = g.velocity_at(north, east, 0.0)[1], g.velocity_at(north, east, 0.0)[0]
        # bilinear over 0.25 deg cells of a field with curvature ~0.5 (rad/deg)^2 deg^2: within 3e-5 m/s
        assert ve == pytest.approx(float(_smooth_east(0, lat, lon)), abs=1e-4)
        assert vn == pytest.approx(float(_smooth_north(0, lat, lon)), abs=1e-4)
    g.check_covers((0.0, 2000.0), (0.0, 2000.0), (0.0, 3600.0), what="the map")


def test_the_window_gives_the_current_the_whole_file_gives(tmp_path):
    """A regional file (2 x 2 deg at 0.02 deg): read whole and read within 8 km of the origin, the same
    current over a 3 km map (both resampled at the file's own spacing)."""
    frame = LocalFrame(38.92, 121.65)
    path = write_cf_current(tmp_path / "regional.nc", np.arange(37.9, 39.9, 0.02), np.arange(120.6, 122.6, 0.02), None,
                            lambda t, la, lo: 0.1 + 0.2 * (lo - 121.0), lambda t, la, lo: -0.3 + 0.1 * (la - 38.0))
    whole, near = load_file(str(path), frame), load_file(str(path), frame, reach=8_000.0)
    assert near.north_axis.size * near.east_axis.size < whole.north_axis.size * whole.east_axis.size / 50
    for north in np.linspace(0.0, 3000.0, 7):
        for east in np.linspace(0.0, 3000.0, 7):
            assert near.velocity_at(north, east, 0.0) == pytest.approx(whole.velocity_at(north, east, 0.0), abs=1e-6)


def test_a_curvilinear_file_is_windowed_too(tmp_path):
    from support.world_files import write_curvilinear_current

    frame = LocalFrame(38.92, 121.65)
    path = write_curvilinear_current(tmp_path / "roms.nc", frame, lambda t, n, e: 0.2 + 1e-5 * e,
                                     lambda t, n, e: -0.1 + 2e-5 * n, shape=(120, 140), spacing=100.0,
                                     centre=(0.0, 0.0))
    whole = read_netcdf(str(path))
    near = read_netcdf(str(path), near=(frame.lat0, frame.lon0, 1_500.0))
    assert near.lat.size < whole.lat.size / 5       # 44 x 44 of 120 x 140 nodes (the grid is turned 30 deg)
    a, b = load_file(str(path), frame), load_file(str(path), frame, reach=1_500.0)
    for north, east in ((0.0, 0.0), (500.0, -700.0), (-900.0, 400.0)):
        assert b.velocity_at(north, east, 0.0) == pytest.approx(a.velocity_at(north, east, 0.0), abs=1e-6)
        assert b.velocity_at(north, east, 0.0) == pytest.approx((-0.1 + 2e-5 * north, 0.2 + 1e-5 * east), abs=1e-6)


def test_too_many_values_to_read_is_one_line_before_reading(tmp_path, monkeypatch):
    path = write_cf_current(tmp_path / "long.nc", np.arange(38.0, 40.0, 0.1), np.arange(121.0, 123.0, 0.1),
                            [f"2024-05-01T{h:02d}:00" for h in range(24)], lambda t, la, lo: 0.1 + 0 * t,
                            lambda t, la, lo: 0.0 * t)
    monkeypatch.setattr(current_sources, "MAX_READ", 1000)
    with pytest.raises(CurrentSourceError) as err:
        read_netcdf(str(path), near=(38.92, 121.65, 20_000.0))
    assert "velocity values to read" in str(err.value) and "\n" not in str(err.value)


def test_a_scenario_reads_its_file_within_its_map_and_two_kilometres(tmp_path):
    from hil import scenario as scenarios
    from hil.config import CONFIG_DIR

    lat0, lon0 = 38.92, 121.65
    write_cf_current(tmp_path / "c.nc", np.arange(lat0 - 1.0, lat0 + 1.0, 0.05),
                     np.arange(lon0 - 1.0, lon0 + 1.0, 0.05), None,
                     lambda t, la, lo: 0.3 + 0 * la, lambda t, la, lo: 0.1 + 0 * la)
    (tmp_path / "s.toml").write_text(f"""name = "s"
description = "regional file"
kind = "fixed"
map = "{CONFIG_DIR / 'maps' / 'open_water.npy'}"
resolution = 0.5
start = [20.0, 60.0]
goal = [180.0, 60.0]

[current]
file = "c.nc"
""")
    scen = scenarios.load(str(tmp_path / "s.toml"))
    expected = math.ceil((math.hypot(scen.width, scen.height) + 2000.0) / 1000.0) * 1000.0
    assert scen.current.reach == expected
    assert scen.current_field().velocity_at(50.0, 50.0, 0.0) == pytest.approx((0.1, 0.3), abs=1e-6)


def test_a_grid_relative_curvilinear_file_is_turned_in_its_window(tmp_path):
    """ROMS's grid-relative u, v with the grid's angle: the angle is cut to the window with the velocity."""
    from support.world_files import write_curvilinear_current

    frame = LocalFrame(38.92, 121.65)
    path = write_curvilinear_current(tmp_path / "rel.nc", frame, lambda t, n, e: 0.2 + 0 * n,
                                     lambda t, n, e: -0.1 + 0 * n, shape=(120, 140), spacing=100.0,
                                     centre=(0.0, 0.0), grid_relative=True)
    for reach in (0.0, 1_500.0):
        g = load_file(str(path), frame, reach=reach)
        assert g.velocity_at(300.0, -200.0, 0.0) == pytest.approx((-0.1, 0.2), abs=1e-6)


@pytest.mark.parametrize("lon0, lons", [(179.95, np.arange(-180.0, 180.01, 0.25)),    # both -180 and 180
                                        (-0.05, np.arange(0.0, 360.01, 0.25))])       # both 0 and 360
def test_a_global_file_with_both_ends_of_its_seam_is_read_once_across_it(tmp_path, lon0, lons):
    path = write_cf_current(tmp_path / "g.nc", np.arange(-10.0, 10.01, 0.25), lons, None,
                            lambda t, la, lo: 0.2 + 0 * la, lambda t, la, lo: 0.1 + 0 * la)
    frame = LocalFrame(0.5, lon0)
    raw = read_netcdf(str(path), near=(frame.lat0, frame.lon0, 3_000.0))
    assert np.all(np.diff(raw.lon) > 0.2)            # the seam's meridian once
    g = load_file(str(path), frame, reach=3_000.0)
    assert g.north_axis.size <= 8 and g.east_axis.size <= 8      # at the file's spacing, not 512 nodes
    assert g.velocity_at(500.0, -500.0, 0.0) == pytest.approx((0.1, 0.2), abs=1e-6)


def test_a_large_file_far_from_the_run_is_refused_for_its_area_having_read_next_to_nothing(tmp_path, monkeypatch):
    path = write_cf_current(tmp_path / "far.nc", np.arange(10.0, 20.0, 0.05), np.arange(10.0, 20.0, 0.05), None,
                            lambda t, la, lo: 0.2 + 0 * la, lambda t, la, lo: 0.1 + 0 * la)
    monkeypatch.setattr(current_sources, "MAX_READ", 100)
    with pytest.raises(CurrentSourceError, match="area is empty around the origin"):
        load_file(str(path), LocalFrame(38.92, 121.65), reach=5_000.0)


def test_a_layout_no_check_foresaw_is_one_line_not_a_traceback(tmp_path, monkeypatch):
    path = write_cf_current(tmp_path / "c.nc", np.arange(38.0, 40.0, 0.1), np.arange(121.0, 123.0, 0.1), None,
                            lambda t, la, lo: 0.2 + 0 * la, lambda t, la, lo: 0.1 + 0 * la)

    def broken(*_args, **_kwargs):
        raise ValueError("operands could not be broadcast together\nwith shapes (3,44,44) (120,140)")

    monkeypatch.setattr(current_sources, "read_netcdf", broken)
    with pytest.raises(CurrentSourceError) as err:
        load_file(str(path), LocalFrame(38.92, 121.65), reach=5_000.0)
    said = "ValueError: operands could not be broadcast together"
    assert str(err.value) == f"{path}: not read as a current file ({said})"
