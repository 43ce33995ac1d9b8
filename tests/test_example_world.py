"""Bring-your-own-world runs (issue 32): whole lockstep HIL runs (`hil run`, simulator and vessel computer
as real processes on UDP) on a vector chart with a current file: the committed example world `bay`,
and a chart and a current file written here as a user's tools would write them."""

from __future__ import annotations

import json
import math
from pathlib import Path

import pytest

pytest.importorskip("xarray")
pytest.importorskip("shapely")

from support.world_files import LAT0, LON0, harbour_chart, metres_box, write_cf_current  # noqa: E402

from common.geodesy import LocalFrame  # noqa: E402
from hil import example_world  # noqa: E402


def test_the_committed_example_world_is_what_its_generator_writes(tmp_path):
    import numpy as np
    import xarray as xr

    chart, nc = example_world.write(tmp_path)
    assert json.loads(chart.read_text()) == json.loads((example_world.WORLD_DIR / "bay.geojson").read_text())
    with xr.open_dataset(nc) as new, xr.open_dataset(example_world.WORLD_DIR / "currents.nc") as old:
        for name in ("uo", "vo", "latitude", "longitude", "time"):
            np.testing.assert_array_equal(new[name].values, old[name].values)
        assert old["uo"].attrs["standard_name"] == "eastward_sea_water_velocity"
        assert "BSD-3-Clause" in old.attrs["license"]


def _run(hil, tmp_path: Path, scenario: str, duration: float = 400.0) -> dict:
    out = tmp_path / "run"
    r = hil("run", "--scenario", scenario, "--duration", str(duration), "--out", str(out), "--no-plot", "--json",
            timeout=900)
    assert r.returncode == 0, r.stderr[-2000:]
    return json.loads(r.stdout)


def _current_seen(s: dict, north: float, east: float, tol: float, estimate_tol: float) -> None:
    """The run's ``current`` section: the truth the hull felt and the planner's field along the track near
    (north, east) m/s, and the vessel computer's own estimate (from ground velocity and thrust) near both."""
    c = s["current"]
    for part in ("felt", "planner_field"):
        assert (c[part]["mean_north_m_s"], c[part]["mean_east_m_s"]) == pytest.approx((north, east), abs=tol), part
    est, felt = c["estimate"], c["felt"]
    assert math.hypot(est["mean_north_m_s"] - felt["mean_north_m_s"],
                      est["mean_east_m_s"] - felt["mean_east_m_s"]) < estimate_tol


@pytest.mark.slow
def test_a_run_on_the_example_world_reaches_the_goal_without_collision(hil, tmp_path):
    s = _run(hil, tmp_path, "bay")
    assert s["reached_goal"] and s["collisions"] == 0 and s["min_clearance_m"] > 0.5
    # configs/worlds/bay/currents.nc: 0.3 m/s east and 0.05 m/s north at the start of its M2 cycle
    assert s["current"]["source"].startswith("file ") and s["current"]["source"].endswith("currents.nc")
    _current_seen(s, 0.05, 0.30, tol=0.01, estimate_tol=0.05)


@pytest.mark.slow
def test_a_users_chart_and_current_file_run_as_a_scenario(hil, tmp_path):
    """A GeoJSON chart and a CF netCDF current (0.4 m/s across the route, turning over an hour) that
    a user's tools would write; the chart reaches 40 m west and 30 m south of the configuration's
    origin, from which the scenario's positions in metres count."""
    import numpy as np

    origin = LocalFrame(LAT0, LON0)
    chart_frame = LocalFrame(*origin.sea_level_to_geodetic(-30.0, -40.0))
    (tmp_path / "harbour.geojson").write_text(json.dumps(harbour_chart(chart_frame)))
    la0, lo0, la1, lo1 = metres_box(origin, -80.0, -90.0, 170.0, 210.0)
    write_cf_current(tmp_path / "currents.nc", np.linspace(la0, la1, 9), np.linspace(lo0, lo1, 9),
                     ["2024-05-01T00:00:00", "2024-05-01T01:00:00"],
                     lambda t, la, lo: 0.0 * la + 0.1 * t, lambda t, la, lo: 0.0 * la + 0.4 - 0.2 * t)
    (tmp_path / "users.toml").write_text("""name = "users-harbour"
description = "a user's chart and current"
kind = "fixed"
map = "harbour.geojson"
resolution = 0.5
start = [-10.0, 20.0]
start_heading = 0.5
goal = [145.0, 100.0]

[current]
file = "currents.nc"
""")
    s = _run(hil, tmp_path, str(tmp_path / "users.toml"))
    assert s["reached_goal"] and s["collisions"] == 0
    # the file's 0.4 m/s north at its first hour (the planner's field_time 0), turning east by 0.1 m/s an
    # hour while the run lasts its few minutes
    _current_seen(s, 0.40, 0.0, tol=0.02, estimate_tol=0.08)


@pytest.mark.slow
def test_a_gdal_written_geopackage_harbour_with_a_basin_runs_as_a_scenario(hil, tmp_path):
    """A GeoPackage written by GDAL itself (pyogrio's writer): the land a multipolygon in UTM whose hole
    is the basin the whole run happens in (filled, the start would be inside the land), 3-D piers in
    longitude/latitude, hazards in China's national grid (a pile, a self-intersecting bow-tie, a
    geometry collection, an anchorage marked no obstacle where the goal is), nulls and an empty layer."""
    pytest.importorskip("pyogrio")
    pytest.importorskip("pyproj")
    from support.world_files import basin_harbour, write_ogr_chart

    write_ogr_chart(tmp_path / "basin.gpkg", "GPKG", basin_harbour(), LocalFrame(LAT0, LON0),
                    crs={"land": 32651, "piers": 4326, "hazards": 4549})
    (tmp_path / "basin.toml").write_text("""name = "basin"
description = "a GDAL-written GeoPackage harbour: the basin a hole in the land"
kind = "fixed"
map = "basin.gpkg"
resolution = 0.5
start = [30.0, 40.0]
start_heading = 1.5708
goal = [160.0, 112.0]
""")
    s = _run(hil, tmp_path, str(tmp_path / "basin.toml"), duration=300.0)
    assert s["reached_goal"] and s["collisions"] == 0 and s["min_clearance_m"] > 1.0


@pytest.mark.slow
def test_a_1_m_s_cross_current_is_crossed(hil, tmp_path):
    """A uniform 1 m/s current across an eastward route on open water (a third of the boat's top speed):
    she crabs along the route to the goal."""
    from hil.config import CONFIG_DIR

    (tmp_path / "cross.toml").write_text(f"""name = "cross-current"
description = "open water, 1 m/s current across the route"
kind = "fixed"
map = "{CONFIG_DIR / 'maps' / 'open_water.npy'}"
resolution = 0.5
start = [20.0, 60.0]
start_heading = 0.0
goal = [180.0, 60.0]

[current]
uniform = [0.0, 1.0]
""")
    s = _run(hil, tmp_path, str(tmp_path / "cross.toml"), duration=300.0)
    assert s["reached_goal"] and s["collisions"] == 0
    # the current is felt: she holds her track heading into it (measured: 0.21 rad RMS off the track's
    # course; 0.035 rad on the same scenario in still water)
    assert s["tracking"]["heading_error_rms_rad"] > 0.1
    assert s["current"]["source"] == "uniform [0, 1] m/s east, north"
    _current_seen(s, 1.0, 0.0, tol=1e-4, estimate_tol=0.1)
