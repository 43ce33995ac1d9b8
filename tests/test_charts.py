"""Vector charts as scenario maps (hil.charts): GeoJSON and shapefiles, in longitude/latitude or a
projected CRS, rasterised onto the planning grid, the run's origin at the map's corner, bad charts
refused in one line."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("shapely")

from support.world_files import LAT0, LON0, harbour_chart  # noqa: E402

from common.geodesy import LocalFrame  # noqa: E402
from hil import charts  # noqa: E402
from hil import scenario as scenarios  # noqa: E402
from hil.config import CONFIG_DIR  # noqa: E402
from hil.errors import ConfigError  # noqa: E402

FRAME = LocalFrame(LAT0, LON0)


def _chart(tmp_path: Path, doc: dict | None = None, name: str = "harbour.geojson") -> Path:
    p = tmp_path / name
    p.write_text(json.dumps(doc if doc is not None else harbour_chart(FRAME)))
    return p


def _cell(grid: charts.ChartGrid, x: float, y: float) -> bool:
    return bool(grid.occ[int(y / grid.resolution), int(x / grid.resolution)])


def test_a_geojson_chart_is_rasterised_around_its_south_west_corner(tmp_path):
    grid = charts.rasterise(_chart(tmp_path), 0.5, FRAME)
    assert grid.origin == pytest.approx((LAT0, LON0), abs=1e-6)   # the bound of a curved parallel: mm
    assert grid.occ.shape == (300, 400)                   # 150 m x 200 m (the chart's bounds) at 0.5 m
    assert _cell(grid, 100.0, 10.0) and _cell(grid, 65.0, 80.0)          # quay, pier
    assert _cell(grid, 122.4, 100.0) and not _cell(grid, 124.0, 100.0)  # the mole: a line grown by 3 m
    assert _cell(grid, 151.5, 40.0) and not _cell(grid, 153.0, 40.0)    # a pile: a point grown by 2 m
    assert not _cell(grid, 40.0, 60.0) and not _cell(grid, 100.0, 120.0)  # open water
    # every cell the geometry touches: the pier's west edge (x = 60 m) marks the cell west of it too
    assert _cell(grid, 59.8, 50.0) and not _cell(grid, 58.9, 50.0)


def test_a_shapefile_gives_the_same_grid_as_the_geojson(tmp_path):
    pyogrio = pytest.importorskip("pyogrio")
    import shapely
    from shapely.geometry import shape

    doc = harbour_chart(FRAME)
    geoms = [shape(f["geometry"]) for f in doc["features"]]
    buffers = np.array([f["properties"].get("buffer", np.nan) for f in doc["features"]], dtype=float)
    # a shapefile holds one geometry type: polygons in one file, the rest grown in the GeoJSON's way
    poly = [i for i, g in enumerate(geoms) if g.geom_type == "Polygon"]
    for name, idx in (("polygons.shp", poly),):
        pyogrio.raw.write(tmp_path / name, shapely.to_wkb(np.array([geoms[i] for i in idx], dtype=object)),
                          field_data=[buffers[idx]], fields=["buffer"], geometry_type="Polygon", crs="EPSG:4326",
                          driver="ESRI Shapefile")
    shp = charts.rasterise(tmp_path / "polygons.shp", 0.5, FRAME, extent=(0.0, 0.0, 200.0, 150.0))
    only_polygons = {"type": "FeatureCollection", "features": [doc["features"][i] for i in poly]}
    gj = charts.rasterise(_chart(tmp_path, only_polygons, "p.geojson"), 0.5, FRAME, extent=(0.0, 0.0, 200.0, 150.0))
    assert shp.occ.sum() > 1000
    np.testing.assert_array_equal(shp.occ, gj.occ)


def _utm(geoms: list, epsg: int) -> list:
    """The geometries (longitude/latitude) in UTM metres, as a GIS would export them (PROJ)."""
    import shapely
    from pyproj import Transformer

    t = Transformer.from_crs(4326, epsg, always_xy=True)
    return [shapely.transform(g, lambda xy: np.column_stack(t.transform(xy[:, 0], xy[:, 1]))) for g in geoms]


def _polygons(doc: dict) -> tuple[list, dict]:
    from shapely.geometry import shape

    idx = [i for i, f in enumerate(doc["features"]) if f["geometry"]["type"] == "Polygon"]
    return ([shape(doc["features"][i]["geometry"]) for i in idx],
            {"type": "FeatureCollection", "features": [doc["features"][i] for i in idx]})


UTM_ZONE = int((FRAME.lon0 + 180.0) // 6.0) + 1
UTM_EPSG = (32600 if FRAME.lat0 >= 0 else 32700) + UTM_ZONE   # WGS 84 / UTM, the chart's own zone
EXTENT = (0.0, 0.0, 200.0, 150.0)


def test_a_projected_shapefile_is_transformed_to_longitude_latitude(tmp_path):
    pyogrio = pytest.importorskip("pyogrio")
    pytest.importorskip("pyproj")
    import shapely

    geoms, only_polygons = _polygons(harbour_chart(FRAME))
    utm = _utm(geoms, UTM_EPSG)
    assert utm[0].bounds[0] > 1000.0                                      # metres, not degrees
    pyogrio.raw.write(tmp_path / "utm.shp", shapely.to_wkb(np.array(utm, dtype=object)), field_data=[],
                      fields=[], geometry_type="Polygon", crs=f"EPSG:{UTM_EPSG}", driver="ESRI Shapefile")
    assert (tmp_path / "utm.prj").exists()
    shp = charts.rasterise(tmp_path / "utm.shp", 0.5, FRAME, extent=EXTENT)
    gj = charts.rasterise(_chart(tmp_path, only_polygons, "p.geojson"), 0.5, FRAME, extent=EXTENT)
    assert shp.occ.sum() > 1000
    np.testing.assert_array_equal(shp.occ, gj.occ)


def test_a_geojson_of_2008_with_a_projected_crs_member_is_transformed(tmp_path):
    pytest.importorskip("pyproj")
    from shapely.geometry import mapping

    geoms, only_polygons = _polygons(harbour_chart(FRAME))
    doc = {"type": "FeatureCollection",
           "crs": {"type": "name", "properties": {"name": f"urn:ogc:def:crs:EPSG::{UTM_EPSG}"}},
           "features": [{"type": "Feature", "properties": {}, "geometry": mapping(g)} for g in _utm(geoms, UTM_EPSG)]}
    projected = charts.rasterise(_chart(tmp_path, doc, "utm.geojson"), 0.5, FRAME, extent=EXTENT)
    lonlat = charts.rasterise(_chart(tmp_path, only_polygons, "p.geojson"), 0.5, FRAME, extent=EXTENT)
    assert projected.occ.sum() > 1000
    np.testing.assert_array_equal(projected.occ, lonlat.occ)


def test_a_crs_proj_does_not_know_and_a_file_without_one_in_metres_are_refused(tmp_path):
    pyogrio = pytest.importorskip("pyogrio")
    pytest.importorskip("pyproj")
    import shapely
    from shapely.geometry import box

    doc = {"type": "FeatureCollection", "crs": {"type": "name", "properties": {"name": "EPSG:999999"}},
           "features": [{"type": "Feature", "properties": {},
                         "geometry": {"type": "Point", "coordinates": [500000.0, 4300000.0]}}]}
    with pytest.raises(ConfigError, match="coordinates in EPSG:999999, a coordinate reference system PROJ "
                                          "does not know") as err:
        charts.rasterise(_chart(tmp_path, doc, "unknown.geojson"), 1.0, FRAME)
    assert "\n" not in str(err.value)
    with pytest.warns(UserWarning, match="'crs' was not provided"):   # a shapefile without its .prj
        pyogrio.raw.write(tmp_path / "noprj.shp", shapely.to_wkb(np.array([box(500000, 4300000, 500100, 4300100)])),
                          field_data=[], fields=[], geometry_type="Polygon", driver="ESRI Shapefile")
    assert not (tmp_path / "noprj.prj").exists()
    with pytest.raises(ConfigError, match="not longitude/latitude degrees; give the file its coordinate "
                                          "reference system") as err:
        charts.rasterise(tmp_path / "noprj.shp", 1.0, FRAME)
    assert "\n" not in str(err.value)


def _point_with_crs(crs: object, x: float = 500000.0, y: float = 4300000.0) -> dict:
    return {"type": "FeatureCollection", "crs": crs,
            "features": [{"type": "Feature", "properties": {}, "geometry": {"type": "Point", "coordinates": [x, y]}}]}


@pytest.mark.parametrize("crs, x, y, message", [
    ({"type": "name", "properties": None}, 500000.0, 4300000.0, "a 'crs' member that does not name"),
    ({"type": "link", "properties": {"href": "data.crs", "type": "proj4"}}, 500000.0, 4300000.0,
     "a 'crs' member that does not name"),
    ({"type": "name", "properties": {"name": "EPSG:4978"}}, 500000.0, 4300000.0, "a geocentric .x, y, z. system"),
    ({"type": "name", "properties": {"name": 'LOCAL_CS["arbitrary",UNIT["metre",1]]'}}, 10.0, 20.0,
     "PROJ does not know or cannot take to WGS-84"),
    ({"type": "name", "properties": {"name": "ESRI:102003"}}, 500000.0, 5500000.0,
     "coordinates outside the area where ESRI:102003 is defined"),
])
def test_a_crs_that_cannot_give_longitude_latitude_is_refused_in_one_line(tmp_path, crs, x, y, message):
    pytest.importorskip("pyproj")
    with pytest.raises(ConfigError, match=message) as err:
        charts.rasterise(_chart(tmp_path, _point_with_crs(crs, x, y), "c.geojson"), 1.0, FRAME)
    assert "\n" not in str(err.value)


def test_crs84_named_as_ogc_writes_it_is_longitude_latitude(tmp_path):
    la, lo = FRAME.sea_level_to_geodetic(20.0, 30.0)
    doc = {**_point_with_crs({"type": "name", "properties": {"name": "CRS:84"}}, lo, la)}
    doc["features"][0]["properties"] = {"buffer": 2.0}
    grid = charts.rasterise(_chart(tmp_path, doc, "c.geojson"), 0.5, FRAME, extent=(0.0, 0.0, 60.0, 40.0))
    assert _cell(grid, 30.0, 20.0) and not _cell(grid, 34.0, 20.0)


@pytest.mark.parametrize("doc, message", [
    ("not json", "not a GeoJSON file"),
    ({"type": "FeatureCollection", "features": []}, "the chart has no features"),
    ({"type": "Point", "coordinates": [500000.0, 4300000.0]}, "not longitude/latitude degrees"),
    ({"type": "Feature", "properties": {"buffer": -1}, "geometry": {"type": "Point", "coordinates": [121.65, 38.92]}},
     "buffer must be a number of metres"),
    ({"type": "Feature", "properties": {}, "geometry": {"type": "Polygon", "coordinates": [[[1, 2]]]}},
     "bad geometry"),
])
def test_bad_charts_are_refused_in_one_line(tmp_path, doc, message):
    p = tmp_path / "bad.geojson"
    p.write_text(doc if isinstance(doc, str) else json.dumps(doc))
    with pytest.raises(ConfigError, match=message) as err:
        charts.rasterise(p, 1.0, FRAME)
    assert "\n" not in str(err.value)


def test_a_grid_too_large_is_refused(tmp_path):
    with pytest.raises(ConfigError, match="choose a coarser resolution"):
        charts.rasterise(_chart(tmp_path), 0.04, FRAME)


SCENARIO = """name = "chart"
description = "a harbour from a GeoJSON chart"
kind = "fixed"
map = "harbour.geojson"
resolution = 0.5
start = [30.0, 50.0]
goal = [185.0, 130.0]
uncharted = [[100.0, 60.0, 3.0]]
"""


# The chart drawn 40 m west and 30 m south of the configuration's origin: its south-west bound is there.
SHIFTED = LocalFrame(*FRAME.sea_level_to_geodetic(-30.0, -40.0))
# SCENARIO's positions in metres from the configuration's origin, for the shifted chart
SHIFTED_SCENARIO = (SCENARIO.replace("start = [30.0, 50.0]", "start = [-10.0, 20.0]")
                    .replace("goal = [185.0, 130.0]", "goal = [145.0, 100.0]")
                    .replace("[[100.0, 60.0, 3.0]]", "[[60.0, 30.0, 3.0]]"))


def test_positions_in_metres_count_from_the_configurations_origin(tmp_path):
    """The grid starts at the chart's south-west bound; the run's NED origin moves there, and the
    scenario's positions in metres (from the configuration's origin) move with it."""
    _chart(tmp_path, harbour_chart(SHIFTED))
    (tmp_path / "s.toml").write_text(SHIFTED_SCENARIO)
    scen = scenarios.load(str(tmp_path / "s.toml"))
    assert scen.occ.shape == (300, 400)
    assert (scen.geodesy.lat0, scen.geodesy.lon0) == pytest.approx((SHIFTED.lat0, SHIFTED.lon0), abs=1e-6)
    assert scen.geodesy.positions_origin == (LAT0, LON0)
    assert scen.start == pytest.approx((30.0, 50.0), abs=0.01) and scen.goal == pytest.approx((185.0, 130.0), abs=0.01)
    assert scen.uncharted[0] == pytest.approx((100.0, 60.0, 3.0), abs=0.01)
    truth = scen.truth_occ()      # the true world: the same grid plus the uncharted disc
    assert truth[int(60 / 0.5), int(100 / 0.5)] and not scen.occ[int(60 / 0.5), int(100 / 0.5)]
    assert np.array_equal(truth & ~scen.occ, truth ^ scen.occ)
    # every process of a run gets this origin through --set geodesy.* (hil.console.load_settings)
    from hil.settings import load

    over = charts.geodesy_overrides(str(tmp_path / "s.toml"), load().geodesy)
    assert over == [f"geodesy.lat0={scen.geodesy.lat0!r}", f"geodesy.lon0={scen.geodesy.lon0!r}",
                    f"geodesy.positions_origin=[{LAT0!r}, {LON0!r}]"]
    moved = load(None, over).geodesy        # what the run's processes load: the same scenario, the same lines
    assert charts.geodesy_overrides(str(tmp_path / "s.toml"), moved) == over
    again = scenarios.load(str(tmp_path / "s.toml"), geodesy=moved)
    assert again.start == scen.start and np.array_equal(again.occ, scen.occ)


def test_an_extent_in_metres_from_the_origin_sets_the_grid(tmp_path):
    _chart(tmp_path, harbour_chart(SHIFTED))
    (tmp_path / "s.toml").write_text(SHIFTED_SCENARIO + "extent = [-50.0, -40.0, 170.0, 130.0]\n")
    scen = scenarios.load(str(tmp_path / "s.toml"))
    assert scen.occ.shape == (340, 440)
    assert scen.start == pytest.approx((40.0, 60.0), abs=0.01)      # -10, 20 m from the origin; grid from -50, -40
    # the quay's south-west corner (-40, -30 m from the origin) is 10 m east and 10 m north of the grid's
    assert scen.occ[int(10.5 / 0.5), int(10.5 / 0.5)] and not scen.occ[int(9.0 / 0.5), int(9.0 / 0.5)]


def test_the_default_extent_is_the_charts_bounds_and_points_are_checked(tmp_path):
    from hil.settings import load

    _chart(tmp_path)
    (tmp_path / "s.toml").write_text(SCENARIO)
    scen = scenarios.load(str(tmp_path / "s.toml"))
    assert (scen.width, scen.height) == (200.0, 150.0)
    assert charts.geodesy_overrides("harbour", load().geodesy) == []
    (tmp_path / "s.toml").write_text(SCENARIO.replace("goal = [185.0, 130.0]", "goal = [65.0, 60.0]"))
    with pytest.raises(ConfigError, match="goal: \\(65, 60[.0-9]*\\) m is inside an obstacle"):
        scenarios.load(str(tmp_path / "s.toml"))
    grid_map = f'map = "{CONFIG_DIR}/maps/harbour.npy"'
    (tmp_path / "s.toml").write_text(SCENARIO.replace('map = "harbour.geojson"', grid_map)
                                     + "extent = [0.0, 0.0, 10.0, 10.0]\n")
    with pytest.raises(ConfigError, match="only for a chart map"):
        scenarios.load(str(tmp_path / "s.toml"))


def test_the_settings_of_a_chart_scenario_carry_its_origin(tmp_path):
    import argparse

    from hil.console import load_settings

    _chart(tmp_path, harbour_chart(SHIFTED))
    (tmp_path / "s.toml").write_text(SHIFTED_SCENARIO)
    args = argparse.Namespace(config=None, overrides=[], scenario=str(tmp_path / "s.toml"))
    cfg = load_settings(args)
    assert (cfg.geodesy.lat0, cfg.geodesy.lon0) == pytest.approx((SHIFTED.lat0, SHIFTED.lon0), abs=1e-6)
    assert cfg.geodesy.positions_origin == (LAT0, LON0)
    assert len(args.overrides) == 3
    load_settings(args)
    assert len(args.overrides) == 3      # once only


def test_a_geometry_collection_grows_its_points_and_lines(tmp_path):
    coll = {"type": "Feature", "properties": {"buffer": 2.0}, "geometry": {"type": "GeometryCollection", "geometries": [
        {"type": "Point", "coordinates": [LON0, LAT0]},
        {"type": "LineString", "coordinates": [list(reversed(FRAME.sea_level_to_geodetic(40.0, 0.0))),
                                               list(reversed(FRAME.sea_level_to_geodetic(40.0, 30.0)))]}]}}
    grid = charts.rasterise(_chart(tmp_path, coll), 0.5, FRAME)
    assert _cell(grid, 1.0, 1.0) and not _cell(grid, 2.5, 2.5)        # the point (the corner), grown by 2 m
    assert _cell(grid, 15.0, 41.5) and _cell(grid, 15.0, 38.5) and not _cell(grid, 15.0, 37.0)  # the line, +-2 m


def test_a_feature_marked_as_no_obstacle_is_skipped(tmp_path):
    doc = harbour_chart(FRAME)
    ring = [list(reversed(FRAME.sea_level_to_geodetic(n, e))) for n, e in ((25, 5), (25, 50), (140, 50), (140, 5),
                                                                          (25, 5))]
    water = {"type": "Feature", "properties": {"name": "basin", "obstacle": False},
             "geometry": {"type": "Polygon", "coordinates": [ring]}}
    doc["features"].append(water)
    grid = charts.rasterise(_chart(tmp_path, doc), 0.5, FRAME)
    assert not _cell(grid, 30.0, 60.0)                # open water inside the 'basin' polygon
    assert _cell(grid, 100.0, 10.0)                   # the quay still is land


# --- Charts as other tools write them: GDAL's own writers through pyogrio -------------------------------

def _check_cells(grid: charts.ChartGrid, features: list) -> int:
    """Assert every cell the features decide (see support.world_files.basin_harbour); how many were checked."""
    checked = [(name, x, y, occupied) for _l, name, _g, _p, cells in features for x, y, occupied in cells]
    wrong = [(name, x, y, occupied) for name, x, y, occupied in checked if _cell(grid, x, y) != occupied]
    assert not wrong, f"cells (feature, x, y, should be occupied) that are not: {wrong}"
    return len(checked)


BASIN_EXTENT = (0.0, 0.0, 200.0, 150.0)
CGCS2000_GK_120E = 4549     # CGCS2000 / 3-degree Gauss-Kruger CM 120E: China's national grid, north-first axes


def test_a_geopackage_of_several_layers_in_several_crs_as_gdal_writes_it(tmp_path):
    """Land with a basin cut out of it (a hole: water) and an island in UTM, 3-D piers with a null and an
    empty geometry in longitude/latitude, hazards (a pile with an integer buffer, a bow-tie, a geometry
    collection, an anchorage that is no obstacle) in a national grid, and an empty layer."""
    pytest.importorskip("pyogrio")
    pytest.importorskip("pyproj")
    from support.world_files import basin_harbour, write_ogr_chart

    feats = basin_harbour()
    path = write_ogr_chart(tmp_path / "harbour.gpkg", "GPKG", feats, FRAME,
                           crs={"land": UTM_EPSG, "piers": 4326, "hazards": CGCS2000_GK_120E})
    write_ogr_chart(path, "GPKG", [("empty", "x", None, {}, [])], FRAME)   # a layer of one feature without geometry
    import pyogrio

    assert {str(n) for n, _t in pyogrio.list_layers(path)} == {"land", "piers", "hazards", "empty"}
    assert pyogrio.read_info(path, layer="land")["crs"] == f"EPSG:{UTM_EPSG}"
    grid = charts.rasterise(path, 0.5, FRAME, extent=BASIN_EXTENT)
    assert _check_cells(grid, feats) == 17
    # the default extent: the land's bounds, its south-west corner the origin
    whole = charts.rasterise(path, 0.5, FRAME)
    assert whole.occ.shape == (300, 400) and whole.origin == pytest.approx((LAT0, LON0), abs=1e-6)


def _without(feats: list, *names: str) -> list:
    return [f for f in feats if f[1] not in names]


@pytest.mark.parametrize("name, driver, crs, options, left_out", [
    ("rfc7946.geojson", "GeoJSON", UTM_EPSG, {"layer_options": {"RFC7946": "YES"}}, ()),  # GDAL reprojects to lon/lat
    ("crs-member.geojson", "GeoJSON", UTM_EPSG, {"layer_options": {"RFC7946": "NO"}}, ()),   # 2008: a crs member
    ("harbour.fgb", "FlatGeobuf", UTM_EPSG, {"layer_options": {"SPATIAL_INDEX": "NO"}}, ()),
    # GDAL's KML writers refuse an empty polygon and a self-intersecting one
    ("libkml.kml", "LIBKML", 4326, {}, ("empty", "bow-tie")),
    ("kml.kml", "KML", 4326, {}, ("empty", "bow-tie")),
])
def test_a_chart_gdal_writes_in_one_file_gives_the_harbour(tmp_path, name, driver, crs, options, left_out):
    pytest.importorskip("pyogrio")
    pytest.importorskip("pyproj")
    from support.world_files import basin_harbour, write_ogr_chart

    feats = _without(basin_harbour(), *left_out)
    if driver in ("GeoJSON", "FlatGeobuf"):          # one layer per file
        feats = [("harbour", *f[1:]) for f in feats]
    path = write_ogr_chart(tmp_path / name, driver, feats, FRAME, crs=crs, **options)
    if name == "crs-member.geojson":
        assert json.loads(path.read_text())["crs"]["properties"]["name"] == f"urn:ogc:def:crs:EPSG::{UTM_EPSG}"
    grid = charts.rasterise(path, 0.5, FRAME, extent=BASIN_EXTENT)
    assert _check_cells(grid, feats) == (14 if "bow-tie" in left_out else 17)


def test_a_kmz_of_one_layer_is_read(tmp_path):
    pytest.importorskip("pyogrio")
    from support.world_files import basin_harbour, write_ogr_chart

    feats = [f for f in basin_harbour() if f[0] == "land"]
    path = write_ogr_chart(tmp_path / "land.kmz", "LIBKML", feats, FRAME)
    assert charts.is_chart(path)
    assert _check_cells(charts.rasterise(path, 0.5, FRAME, extent=BASIN_EXTENT), feats) == 6


def test_a_polygon_shapefile_with_upper_case_integer_fields(tmp_path):
    """A shapefile in UTM (.prj) holding the land with its hole, the pier and the bow-tie, and the
    anchorage marked OBSTACLE = 0 in an integer field, as tools that write upper-case names do."""
    pyogrio = pytest.importorskip("pyogrio")
    pytest.importorskip("pyproj")
    import shapely
    from support.world_files import basin_harbour, to_lonlat

    feats = [f for f in basin_harbour() if f[2] is not None and f[2].geom_type in ("Polygon", "MultiPolygon")
             and not f[2].is_empty]
    utm = _utm([shapely.force_2d(to_lonlat(f[2], FRAME)) for f in feats], UTM_EPSG)
    obstacle = np.array([0 if f[3].get("obstacle") is False else 1 for f in feats], dtype=np.int32)
    pyogrio.raw.write(tmp_path / "harbour.shp", shapely.to_wkb(np.array(utm, dtype=object)),
                      field_data=[obstacle, np.zeros(len(feats), dtype=np.int32)], fields=["OBSTACLE", "BUFFER"],
                      geometry_type="MultiPolygon", crs=f"EPSG:{UTM_EPSG}", driver="ESRI Shapefile")
    assert (tmp_path / "harbour.prj").exists()
    grid = charts.rasterise(tmp_path / "harbour.shp", 0.5, FRAME, extent=BASIN_EXTENT)
    assert _check_cells(grid, feats) == 12


def _header_only_s57_cell(path: Path) -> Path:
    """What GDAL's S-57 driver writes when asked for a land area: the cell's header (DSID) alone."""
    import pyogrio.raw
    import shapely
    from shapely.geometry import box

    land = np.array([shapely.to_wkb(box(LON0, LAT0, LON0 + 0.001, LAT0 + 0.001))], dtype=object)
    with pytest.raises(Exception, match="CreateLayer.. not supported"):
        pyogrio.raw.write(path, land, field_data=[], fields=[], layer="LNDARE", driver="S57",
                          geometry_type="Polygon", crs="EPSG:4326")
    return path


def test_an_s57_cell_gdal_writes_holds_no_obstacle_layer_and_is_refused(tmp_path):
    """GDAL's S-57 driver creates a cell (its DSID record) but has no CreateLayer: pyogrio cannot write
    an object class into it (a cell with features needs its vector primitives and their linkages,
    which only ogr2ogr from another S-57 cell supplies). What it writes is read by the S-57 reader
    and refused in one line: no obstacle layer."""
    pyogrio = pytest.importorskip("pyogrio")
    path = _header_only_s57_cell(tmp_path / "TEST0001.000")
    assert [str(n) for n, _t in pyogrio.list_layers(path)] == ["DSID"]
    with pytest.raises(ConfigError, match="the chart has no features") as err:
        charts.rasterise(path, 0.5, FRAME)
    assert "\n" not in str(err.value)


@pytest.mark.parametrize("props, message", [
    ({"obstacle": "perhaps"}, "obstacle property must be true or false .got 'perhaps'."),
    ({"obstacle": 2}, "obstacle property must be true or false"),
    ({"buffer": "three"}, "buffer must be a number of metres in 0..1000 .got 'three'."),
    ({"BUFFER": 2000}, "buffer must be a number of metres"),
])
def test_obstacle_and_buffer_values_that_mean_nothing_are_refused_in_one_line(tmp_path, props, message):
    doc = {"type": "Feature", "properties": props, "geometry": {"type": "Point", "coordinates": [LON0, LAT0]}}
    with pytest.raises(ConfigError, match=message) as err:
        charts.rasterise(_chart(tmp_path, doc), 0.5, FRAME)
    assert "\n" not in str(err.value)


def test_obstacle_and_buffer_as_text_and_in_any_case(tmp_path):
    """KML's ExtendedData and many GIS exports give text; a shapefile's fields are often upper case."""
    def point(x: float, props: dict) -> dict:
        return {"type": "Feature", "properties": props,
                "geometry": {"type": "Point", "coordinates": list(reversed(FRAME.sea_level_to_geodetic(20.0, x)))}}

    doc = {"type": "FeatureCollection", "features": [
        point(10.0, {"Obstacle": "No"}), point(20.0, {"obstacle": "false"}), point(30.0, {"OBSTACLE": 0}),
        point(40.0, {"obstacle": "yes", "Buffer": "3"}), point(50.0, {"obstacle": ""}),
        point(0.0, {"buffer": 0.2}), point(60.0, {"buffer": 0.2})]}
    grid = charts.rasterise(_chart(tmp_path, doc), 0.5, FRAME, extent=(0.0, 0.0, 60.0, 40.0))
    assert not _cell(grid, 10.0, 20.0) and not _cell(grid, 20.0, 20.0) and not _cell(grid, 30.0, 20.0)
    assert _cell(grid, 42.5, 20.0) and not _cell(grid, 43.9, 20.0)      # grown by its text "3"
    assert _cell(grid, 50.0, 20.0) and _cell(grid, 51.5, 20.0)           # empty text: an obstacle, the default 2 m


def test_invalid_polygons_are_repaired_as_drawn(tmp_path):
    """Both lobes of a bow-tie are land (buffer(0) keeps one); overlapping parts of one multipolygon are
    land once, not a hole; a polygon drawn flat marks the cells its line touches."""
    from support.world_files import lonlat

    def ring(pts: list) -> list:
        return [lonlat(FRAME, x, y) for x, y in [*pts, pts[0]]]

    def feature(kind: str, coordinates: list) -> dict:
        return {"type": "Feature", "properties": {}, "geometry": {"type": kind, "coordinates": coordinates}}

    doc = {"type": "FeatureCollection", "features": [
        feature("Polygon", [ring([(0, 0), (20, 20), (20, 0), (0, 20)])]),
        feature("MultiPolygon", [[ring([(30, 0), (45, 0), (45, 15), (30, 15)])],
                                 [ring([(35, 5), (50, 5), (50, 20), (35, 20)])]]),
        feature("Polygon", [ring([(0, 30), (50, 30), (0, 30)])]),
    ]}
    grid = charts.rasterise(_chart(tmp_path, doc), 0.5, FRAME, extent=(0.0, 0.0, 50.0, 40.0))
    assert _cell(grid, 2.0, 10.0) and _cell(grid, 18.0, 10.0) and not _cell(grid, 10.0, 2.0)   # the lobes, the gap
    assert _cell(grid, 40.0, 10.0) and _cell(grid, 32.0, 2.0) and _cell(grid, 48.0, 18.0)     # the overlap is land
    assert _cell(grid, 25.0, 30.2) and not _cell(grid, 25.0, 31.5)                            # the flat polygon


def test_a_collection_inside_a_collection_and_3d_coordinates(tmp_path):
    from support.world_files import lonlat

    nested = {"type": "Point", "coordinates": [*lonlat(FRAME, 7, 7), 5.0]}
    doc = {"type": "Feature", "properties": {}, "geometry": {"type": "GeometryCollection", "geometries": [
        {"type": "GeometryCollection", "geometries": [nested]}, {"type": "Point", "coordinates": [LON0, LAT0, 5.0]}]}}
    grid = charts.rasterise(_chart(tmp_path, doc), 0.5, FRAME, extent=(0.0, 0.0, 10.0, 10.0))
    assert _cell(grid, 1.0, 1.0) and not _cell(grid, 2.5, 2.5)      # the outer point, grown by chart_buffer (2 m)
    assert _cell(grid, 8.0, 8.0) and not _cell(grid, 9.5, 9.5)      # the nested one too


def test_features_far_beyond_the_extent_are_cut_before_they_grow_and_mark_the_same_cells(tmp_path, monkeypatch):
    """A coast running kilometres past the map, a long boom (a line) and a buoy whose buffer reaches in
    from outside: with the cut to the extent (hil/charts.py: _cut) the grid is cell for cell the grid
    of the whole geometry."""
    from support.world_files import lonlat

    coast = [lonlat(FRAME, x, 30.0 + 8.0 * np.sin(x / 37.0)) for x in np.arange(-3000.0, 3000.0, 2.0)]
    ring = coast + [lonlat(FRAME, 3000.0, -2000.0), lonlat(FRAME, -3000.0, -2000.0), coast[0]]
    doc = {"type": "FeatureCollection", "features": [
        {"type": "Feature", "properties": {"name": "coast"}, "geometry": {"type": "Polygon", "coordinates": [ring]}},
        {"type": "Feature", "properties": {"name": "boom", "buffer": 1.5},
         "geometry": {"type": "LineString", "coordinates": [lonlat(FRAME, -900.0, 120.0), lonlat(FRAME, 60.0, 121.0)]}},
        {"type": "Feature", "properties": {"name": "buoy", "buffer": 4.0},
         "geometry": {"type": "Point", "coordinates": lonlat(FRAME, 202.5, 100.0)}},
        {"type": "Feature", "properties": {"name": "far island"},
         "geometry": {"type": "Polygon", "coordinates": [[lonlat(FRAME, x, y) for x, y in (
             (2000.0, 900.0), (2050.0, 900.0), (2050.0, 950.0), (2000.0, 900.0))]]}},
    ]}
    path = tmp_path / "coast.geojson"
    path.write_text(json.dumps(doc))
    extent = (0.0, 0.0, 200.0, 150.0)
    cut = charts.rasterise(path, 0.5, FRAME, extent)
    monkeypatch.setattr(charts, "_cut", lambda g, box, margin: g)
    whole = charts.rasterise(path, 0.5, FRAME, extent)
    assert cut.occ.shape == (300, 400)
    np.testing.assert_array_equal(cut.occ, whole.occ)
    assert cut.occ[int(100 / 0.5), -1] and cut.occ[int(120 / 0.5), 0] and cut.occ[0, 0]   # buoy, boom, coast
    assert not cut.occ[int(140 / 0.5), int(100 / 0.5)]


def test_a_zipped_shapefile_gives_the_grid_of_the_shapefile(tmp_path):
    """A shapefile with its sidecar files in a folder of a zip archive, as a download holds it, beside a
    README: read from the archive by GDAL, the same grid cell for cell."""
    import zipfile

    pytest.importorskip("pyogrio")
    pytest.importorskip("pyproj")
    from support.world_files import basin_harbour, write_ogr_chart

    feats = [("harbour", *f[1:]) for f in basin_harbour()      # a shapefile holds one kind of geometry
             if f[2] is not None and f[2].geom_type in ("Polygon", "MultiPolygon") and not f[2].is_empty]
    shp = write_ogr_chart(tmp_path / "harbour.shp", "ESRI Shapefile", feats, FRAME, crs=UTM_EPSG,
                          geometry_type="MultiPolygon")
    archive = tmp_path / "download.zip"
    with zipfile.ZipFile(archive, "w") as z:
        for part in sorted(tmp_path.glob("harbour.*")):
            z.write(part, f"coast/{part.name}")
        z.writestr("coast/README.txt", "a chart")
    plain = charts.rasterise(shp, 0.5, FRAME, extent=BASIN_EXTENT)
    zipped = charts.rasterise(archive, 0.5, FRAME, extent=BASIN_EXTENT)
    np.testing.assert_array_equal(zipped.occ, plain.occ)
    assert _check_cells(zipped, feats) == 12      # every cell the features decide


def test_an_enc_download_is_opened_at_its_cell(tmp_path):
    """An ENC as a chart office's zip holds it (ENC_ROOT/CATALOG.031 and the cell in a folder of its own):
    the cell is found and read by the S-57 reader (GDAL writes only a cell's header, so it is refused,
    in one line, for holding no obstacle layer, as the same cell unzipped is)."""
    import zipfile

    pytest.importorskip("pyogrio")
    cell = _header_only_s57_cell(tmp_path / "TEST0001.000")
    archive = tmp_path / "TEST0001.zip"
    with zipfile.ZipFile(archive, "w") as z:
        z.writestr("ENC_ROOT/CATALOG.031", b"catalogue")
        z.write(cell, "ENC_ROOT/TEST0001/TEST0001.000")
    with pytest.raises(ConfigError, match="the chart has no features") as err:
        charts.rasterise(archive, 0.5, FRAME)
    assert "\n" not in str(err.value)


@pytest.mark.parametrize("members, message", [
    ({"a/one.shp": b"", "b/two.geojson": b"{}"}, "exactly one chart file.*it holds a/one.shp, b/two.geojson"),
    ({"notes.txt": b"no chart here"}, "exactly one chart file.*it holds none"),
    (None, "cannot be read as a zip archive"),
])
def test_a_zip_without_exactly_one_chart_is_refused_in_one_line(tmp_path, members, message):
    import zipfile

    archive = tmp_path / "charts.zip"
    if members is None:
        archive.write_bytes(b"PK not really a zip")
    else:
        with zipfile.ZipFile(archive, "w") as z:
            for name, data in members.items():
                z.writestr(name, data)
    with pytest.raises(ConfigError, match=message) as err:
        charts.rasterise(archive, 0.5, FRAME)
    assert "\n" not in str(err.value)
