"""Vector charts as scenario maps: GeoJSON, shapefiles and the other formats GDAL reads, rasterised
onto the planning grid.

A chart holds obstacles in WGS-84 longitude/latitude: polygons (land, piers, breakwaters) as they
are; lines and points (a mole drawn as a line, piles and buoys) grown by a buffer in metres, the
feature's own ``buffer`` property or the scenario's ``chart_buffer``. Every feature is an obstacle
but one whose ``obstacle`` property is false; of an S-57 cell, the obstacle layers
(:data:`S57_OBSTACLE_LAYERS`: land, shoreline constructions, obstructions, pontoons ...).

The grid covers the chart's bounds, or ``extent`` = [west, south, east, north] in metres from the
origin of the scenario's positions (the configuration's ``[geodesy]`` origin, or the scenario's
``origin``). Its south-west corner becomes the run's NED origin (``[geodesy] lat0/lon0``: see
:func:`geodesy_overrides`), so the map's metres, the simulator's and the GPS's agree; positions the
scenario gives in metres are moved onto it (``hil.scenario``). Each vertex goes to
metres through the exact tangent-plane conversion (``common.geodesy``); buffers are taken in metres;
a cell is an obstacle when the geometry comes within half a cell's diagonal of its centre (every
cell the geometry touches, so obstacles are never thinned). The simulator's true world (its range
sensor and collision judge) is this same grid plus the scenario's uncharted discs.

Readers. GeoJSON (RFC 7946: always longitude/latitude) is read by the standard library and shapely.
Other files go through pyogrio (GDAL): shapefiles (.shp with .dbf/.shx, and .prj when present),
GeoPackage (every layer), KML/KMZ, FlatGeobuf and S-57 ENC cells (.000: the obstacle layers only; no
S-57 cell with features has been read here: GDAL cannot write one); any of these zipped, one chart to
an archive (a shapefile with its sidecar files, an ENC cell as a chart office's download holds it:
:func:`_zipped_chart`), read from the archive by GDAL. A layer in another coordinate
reference system (a shapefile's .prj in UTM, a GeoPackage layer in a national grid, a GeoJSON of the
2008 specification with a ``crs`` member) is transformed to WGS-84 longitude/latitude by pyproj
(PROJ) before anything else; a file without a CRS must already be in longitude/latitude degrees, and
one whose CRS PROJ does not know is refused in one line.

Geometry as users' tools write it. Holes stay water (a basin cut out of the land); multipolygons,
collections (nested ones too) are taken part by part; Z and M coordinates are dropped; a feature
without geometry or with an empty one is no obstacle (the rest of the file is read); curves are
linearised by GDAL. An invalid polygon (a self-intersecting bow-tie, overlapping parts of one
multipolygon) is repaired as drawn (:func:`_repaired`: shells less holes, both lobes of a bow-tie
land) rather than refused. The ``obstacle`` and ``buffer`` fields are found in any case
(``OBSTACLE``), ``obstacle`` may be a boolean, 0/1 or text (false/no/n/f/0, true/yes/y/t/1), ``buffer``
a number or a number as text (KML's ExtendedData); other values are refused in one line.
"""

from __future__ import annotations

import json
import math
import os
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from common.geodesy import LocalFrame
from hil.errors import ConfigError

if TYPE_CHECKING:
    from collections.abc import Callable, Mapping

    from shapely.geometry.base import BaseGeometry  # shapely is untyped: Any to mypy

    from simulator.config import GeodesyParams

# S-57 object classes that are obstacles to a boat (IHO S-57 Appendix A): an ENC cell's other layers
# (depth areas, fairways, lights ...) cover the water itself and are not read.
S57_OBSTACLE_LAYERS = frozenset({"LNDARE", "SLCONS", "OBSTRN", "PONTON", "HULKES", "PILPNT", "MORFAC", "WRECKS",
                                 "UWTROC", "DRYDOC", "FLODOC", "GATCON", "DAMCON", "CAUSWY", "PYLONS", "BRIDGE"})
# CRS names that already mean longitude/latitude on WGS-84 (or a datum within ~1 m of it: NAD83, ETRS89).
LONLAT_CRS = frozenset({"EPSG:4326", "OGC:CRS84", "CRS:84", "EPSG:4269", "EPSG:4258", "urn:ogc:def:crs:OGC:1.3:CRS84",
                        "urn:ogc:def:crs:EPSG::4326", "urn:ogc:def:crs:OGC::CRS84"})
CHART_SUFFIXES = (".geojson", ".json", ".shp", ".gpkg", ".kml", ".kmz", ".fgb", ".000", ".zip")
MAX_CELLS = 16_000_000   # 4000 x 4000 cells: a planning grid the planner and the simulator hold in memory


def is_chart(path: str | Path) -> bool:
    """Whether a scenario's ``map`` names a vector chart (not a .npy/.png grid)."""
    return Path(path).suffix.lower() in CHART_SUFFIXES


@dataclass(frozen=True)
class ChartFeature:
    """One obstacle: a shapely geometry in longitude/latitude degrees and its buffer (m, None: the default)."""

    geometry: BaseGeometry
    buffer: float | None


@dataclass(frozen=True)
class ChartGrid:
    """A rasterised chart: ``occ`` bool [rows (north), cols (east)], True = obstacle; ``origin``
    (lat, lon) degrees of the south-west corner; ``resolution`` m/cell."""

    occ: np.ndarray
    origin: tuple[float, float]
    resolution: float


def _field(props: Mapping[str, object] | None, name: str) -> object:
    """A property by name, in any case (``buffer``, ``BUFFER``: a shapefile's fields are often upper case)."""
    if not props:
        return None
    if name in props:
        return props[name]
    return next((v for k, v in props.items() if isinstance(k, str) and k.lower() == name), None)


def _buffer_of(props: Mapping[str, object] | None, source: str) -> float | None:
    b = _field(props, "buffer")
    refused = f"{source}: a feature's buffer must be a number of metres in 0..1000 (got {b!r})"
    if isinstance(b, str):      # KML's ExtendedData, a text field: "3", "2.5"
        if not b.strip():
            return None
        try:
            b = float(b)
        except ValueError:
            raise ConfigError(refused) from None
    if b is None or (isinstance(b, (float, np.floating)) and math.isnan(b)):
        return None     # no value: the default (a null in a GeoPackage, NaN from a float column)
    if isinstance(b, (bool, np.bool_)) or not isinstance(b, (int, float, np.number)) or not 0 <= b <= 1000:
        raise ConfigError(refused)
    return float(b)


_NO = frozenset({"false", "f", "no", "n", "0"})
_YES = frozenset({"true", "t", "yes", "y", "1", ""})


def _is_obstacle(props: Mapping[str, object] | None, source: str) -> bool:
    """The feature's ``obstacle`` property: false, 0, "false"/"no"/"n"/"f"/"0" (any case) make it no obstacle;
    true, 1, their words, an empty text or no value at all an obstacle; anything else is refused."""
    v = _field(props, "obstacle")
    if v is None or isinstance(v, (bool, np.bool_)):
        return v is None or bool(v)
    if isinstance(v, (int, np.integer)) and v in (0, 1):
        return bool(v)
    if isinstance(v, (float, np.floating)) and (math.isnan(v) or v in (0.0, 1.0)):
        return math.isnan(v) or bool(v)
    if isinstance(v, str) and v.strip().lower() in _NO | _YES:
        return v.strip().lower() not in _NO
    raise ConfigError(f"{source}: a feature's obstacle property must be true or false (got {v!r})")


def _read_geojson(path: Path) -> list[ChartFeature]:
    from shapely.geometry import shape

    try:
        doc = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise ConfigError(f"{path}: not a GeoJSON file ({exc})") from None
    if not isinstance(doc, dict) or "type" not in doc:
        raise ConfigError(f"{path}: not a GeoJSON object (no 'type')")
    if doc["type"] == "FeatureCollection":
        items = doc.get("features")
        if not isinstance(items, list):
            raise ConfigError(f"{path}: a FeatureCollection without a 'features' list")
    elif doc["type"] == "Feature":
        items = [doc]
    else:
        items = [{"type": "Feature", "geometry": doc, "properties": {}}]
    to_lonlat = None
    crs = doc.get("crs")   # GeoJSON 2008's CRS member (RFC 7946 dropped it): {"type": "name", ...}
    if crs is not None:
        props = crs.get("properties") if isinstance(crs, dict) else None
        name = props.get("name") if isinstance(props, dict) and crs.get("type") == "name" else None
        if not isinstance(name, str):
            raise ConfigError(f"{path}: a 'crs' member that does not name a coordinate reference system "
                              '(expected {"type": "name", "properties": {"name": "EPSG:..."}}); '
                              "remove it if the file is in WGS-84 longitude/latitude")
        to_lonlat = _to_lonlat(name, str(path)) if name not in LONLAT_CRS else None
    out = []
    for i, f in enumerate(items):
        if not isinstance(f, dict) or not isinstance(f.get("geometry"), dict):
            continue   # a feature without geometry (allowed by RFC 7946) is no obstacle
        try:
            geom = shape(f["geometry"])
        except Exception as exc:  # shapely raises several kinds for malformed coordinates
            raise ConfigError(f"{path}: feature {i}: bad geometry ({type(exc).__name__}: {exc})") from None
        props = f.get("properties") if isinstance(f.get("properties"), dict) else None
        if not _is_obstacle(props, f"{path}: feature {i}"):
            continue   # marked as no obstacle (a water area, a label)
        if to_lonlat is not None:
            geom = to_lonlat(geom)
        out.append(ChartFeature(geom, _buffer_of(props, f"{path}: feature {i}")))
    return out


def _to_lonlat(crs: str, where: str) -> Callable[[BaseGeometry], BaseGeometry]:
    """A function taking a geometry in ``crs`` (as GDAL or a GeoJSON names it) to WGS-84 longitude/latitude
    degrees, by PROJ's transformation between the two; ConfigError in one line for a CRS PROJ does not know."""
    import shapely
    from pyproj import CRS, Transformer
    from pyproj.exceptions import CRSError, ProjError

    export = "export the chart in WGS-84 longitude/latitude (EPSG:4326)"
    try:
        source = CRS.from_user_input(crs)
        if source.is_geocentric:
            raise ConfigError(f"{where}: coordinates in {crs}, a geocentric (x, y, z) system, not a map's; {export}")
        transformer = Transformer.from_crs(source, CRS.from_epsg(4326), always_xy=True)
    except (CRSError, ProjError):   # unknown, or known but not transformable to WGS-84 (a CAD drawing's LOCAL_CS)
        raise ConfigError(f"{where}: coordinates in {crs}, a coordinate reference system PROJ does not know "
                          f"or cannot take to WGS-84; {export}") from None

    def move(xy: np.ndarray) -> np.ndarray:
        lon, lat = transformer.transform(xy[:, 0], xy[:, 1])
        if not (np.all(np.isfinite(lon)) and np.all(np.isfinite(lat))):
            raise ConfigError(f"{where}: coordinates outside the area where {crs} is defined "
                              f"(e.g. {float(xy[0, 0]):g}, {float(xy[0, 1]):g}); {export}")
        return np.column_stack((lon, lat))

    def convert(geom: BaseGeometry) -> BaseGeometry:
        return shapely.transform(geom, move)
    return convert


def _zipped_chart(path: Path) -> tuple[Path, str]:
    """The one chart inside a zip archive (a shapefile with its sidecar files, an ENC cell as NOAA's
    downloads hold it, a GeoPackage ...): its name inside, for messages and its format, and the path GDAL
    reads it by (``/vsizip/``). None or several: ConfigError naming them."""
    import zipfile

    try:
        with zipfile.ZipFile(path) as z:
            names = [n for n in z.namelist() if not n.endswith("/")]
    except (zipfile.BadZipFile, OSError) as exc:
        raise ConfigError(f"{path}: cannot be read as a zip archive ({exc})") from None
    inner = [n for n in names if Path(n).suffix.lower() in CHART_SUFFIXES and Path(n).suffix.lower() != ".zip"
             and not Path(n).name.startswith(".")]
    if len(inner) != 1:
        found = ", ".join(inner[:6]) + (" ..." if len(inner) > 6 else "") if inner else "none"
        raise ConfigError(f"{path}: a zipped chart must hold exactly one chart file "
                          f"({', '.join(CHART_SUFFIXES[:-1])}); it holds {found}")
    return path / inner[0], f"/vsizip/{path.resolve()}/{inner[0]}"


def _read_ogr(path: Path, source: str | None = None) -> list[ChartFeature]:
    """The features of a file GDAL reads; ``source``: what GDAL opens when it is not ``path`` itself (a file
    inside a zip archive, ``path`` then naming it for messages)."""
    src = str(path) if source is None else source
    try:
        import pyogrio
        import pyogrio.raw
        import shapely
    except ImportError:  # pragma: no cover - dependencies of the project
        raise ConfigError(f"{path}: reading this chart format needs pyogrio (pip install pyogrio)") from None
    try:
        layers = [str(name) for name, gtype in pyogrio.list_layers(src) if gtype is not None]
        if path.suffix.lower() == ".000":
            layers = [name for name in layers if name.upper() in S57_OBSTACLE_LAYERS]
    except Exception as exc:  # pyogrio's DataSourceError and friends
        raise ConfigError(f"{path}: cannot be read as a chart ({str(exc).splitlines()[0]})") from None
    out: list[ChartFeature] = []
    for layer in layers:
        where = f"{path}: layer {layer}"
        try:
            meta, _fids, wkb, fields = pyogrio.raw.read(src, layer=layer, force_2d=True)
        except Exception as exc:
            raise ConfigError(f"{where}: cannot be read ({str(exc).splitlines()[0]})") from None
        crs = meta.get("crs")
        to_lonlat = _to_lonlat(str(crs), where) if crs and crs not in LONLAT_CRS else None
        names = [str(n) for n in meta.get("fields", [])]
        for i, g in enumerate(wkb):
            if g is None:
                continue   # a feature without geometry (a label, a record): no obstacle
            props = {n: fields[k][i] for k, n in enumerate(names) if n.lower() in ("obstacle", "buffer")}
            if not _is_obstacle(props, f"{where}: feature {i}"):
                continue
            buffer = _buffer_of(props, f"{where}: feature {i}")
            try:
                geom = shapely.from_wkb(g)
            except Exception as exc:  # shapely.errors.GEOSException: e.g. a curve (CIRCULARSTRING) GEOS cannot hold
                raise ConfigError(f"{where}: feature {i}: geometry shapely cannot read ({str(exc).splitlines()[0]}); "
                                  "export curves as straight segments (linearised)") from None
            out.append(ChartFeature(geom if to_lonlat is None else to_lonlat(geom), buffer))
    return out


_CACHE: dict[tuple, list[ChartFeature]] = {}


def read_chart(path: str | Path) -> list[ChartFeature]:
    """The chart's features (longitude/latitude); ConfigError in one line on a bad file."""
    p = Path(path)
    try:
        key = (str(p.resolve()), os.stat(p).st_mtime_ns)
    except OSError:
        raise ConfigError(f"map: no such chart {p}") from None
    if key not in _CACHE:
        if p.suffix.lower() == ".zip":
            feats = _read_ogr(*_zipped_chart(p))
        else:
            feats = _read_geojson(p) if p.suffix.lower() in (".geojson", ".json") else _read_ogr(p)
        feats = [f for f in feats if not f.geometry.is_empty]
        if not feats:
            raise ConfigError(f"{p}: the chart has no features")
        for f in feats:
            lon0, lat0, lon1, lat1 = f.geometry.bounds
            if not (-180 <= lon0 <= lon1 <= 360 and -89 <= lat0 <= lat1 <= 89):
                named = " (a shapefile's .prj)" if p.suffix.lower() == ".shp" else ""
                raise ConfigError(f"{p}: coordinates ({lon0:g}, {lat0:g}) are not longitude/latitude degrees; "
                                  f"give the file its coordinate reference system{named} or "
                                  "export it in WGS-84 (EPSG:4326)")
        _CACHE[key] = feats
    return _CACHE[key]


def chart_bounds(features: list[ChartFeature]) -> tuple[float, float, float, float]:
    """(lon_min, lat_min, lon_max, lat_max) of every feature."""
    b = np.array([f.geometry.bounds for f in features])
    return float(b[:, 0].min()), float(b[:, 1].min()), float(b[:, 2].max()), float(b[:, 3].max())


def grid_corner(path: str | Path, positions: LocalFrame, extent: tuple[float, ...] = ()) -> tuple[float, float]:
    """(lat, lon) of the map's south-west corner: ``extent``'s [west, south] metres from the positions'
    origin when given, else the chart's south-west bound."""
    if extent:
        return positions.sea_level_to_geodetic(float(extent[1]), float(extent[0]))
    lon0, lat0, _lon1, _lat1 = chart_bounds(read_chart(path))
    return lat0, lon0


def to_metres(geometry: BaseGeometry, frame: LocalFrame) -> BaseGeometry:
    """A longitude/latitude geometry in map metres (x east, y north) of ``frame``."""
    import shapely

    def convert(coords: np.ndarray) -> np.ndarray:
        out = np.empty_like(coords)
        for i, (lon, lat) in enumerate(coords):
            n, e = frame.geodetic_to_sea_level(float(lat), float(lon))
            out[i] = (e, n)
        return out

    return shapely.transform(geometry, convert)


def _parts(geometry: BaseGeometry) -> list[BaseGeometry]:
    """The single points, lines and polygons of a geometry, collections within collections opened; empty
    parts (a GeoPackage's POLYGON EMPTY, a null member) left out."""
    import shapely

    out = []
    for g in shapely.get_parts(geometry):
        if g.geom_type in ("GeometryCollection", "MultiPoint", "MultiLineString", "MultiPolygon"):
            out.extend(_parts(g))
        elif not g.is_empty:
            out.append(g)
    return out


def _repaired(polygon: BaseGeometry) -> BaseGeometry:
    """A polygon or multipolygon made valid, as drawn: the union of its shells less the union of its holes
    (GEOS's make_valid, method "structure": a bow-tie's two lobes are both land, overlapping parts of a
    multipolygon are land once, a hole stays water), plus any zero-area part (a spike, a polygon drawn
    flat) kept as the line it is, marking the cells it touches. A valid polygon is returned as it is."""
    import shapely

    if polygon.is_valid:
        return polygon
    fixed = shapely.make_valid(polygon, method="structure", keep_collapsed=True)
    flat = [p for p in shapely.get_parts(shapely.make_valid(polygon)) if p.geom_type not in ("Polygon", "MultiPolygon")]
    return shapely.union_all([fixed, *flat]) if flat else fixed


def _cut(g: BaseGeometry, box: tuple[float, float, float, float] | None, margin: float) -> BaseGeometry:
    """``g`` (valid, metres) cut to ``box`` (x0, y0, x1, y1) widened by ``margin`` m; ``g`` without a box."""
    if box is None:
        return g
    import shapely

    x0, y0, x1, y1 = box
    gx0, gy0, gx1, gy1 = shapely.bounds(g)
    if gx0 >= x0 - margin and gy0 >= y0 - margin and gx1 <= x1 + margin and gy1 <= y1 + margin:
        return g
    return shapely.clip_by_rect(g, x0 - margin, y0 - margin, x1 + margin, y1 + margin)


def rasterise(path: str | Path, resolution: float, positions: LocalFrame, extent: tuple[float, ...] = (),
              default_buffer: float = 2.0) -> ChartGrid:
    """The chart at ``path`` on a grid of ``resolution`` m (see the module's docstring); ``extent``
    [west, south, east, north] in metres of ``positions`` (the scenario's metres), or the chart's bounds."""
    import shapely

    feats = read_chart(path)
    lat0, lon0 = grid_corner(path, positions, extent)
    frame = LocalFrame(lat0, lon0, positions.alt0)
    # With an extent, each part is cut to it before it is grown (a coastline of a whole region costs what
    # the map's piece of it does): the cut lies a cell, the part's buffer and a metre outside the grid, so
    # every cell the part or its buffer touches is marked as without the cut.
    box = None if not extent else (0.0, 0.0, float(extent[2] - extent[0]), float(extent[3] - extent[1]))
    shapes = []
    for f in feats:
        b = default_buffer if f.buffer is None else f.buffer
        for g in _parts(to_metres(f.geometry, frame)):   # a collection's members one by one
            if g.geom_type in ("Point", "LineString", "LinearRing"):
                if b <= 0:
                    raise ConfigError(f"{path}: points and lines need a buffer > 0 m (chart_buffer or a "
                                      "'buffer' property)")
                g = _cut(g, box, b + 2.0 * resolution + 1.0).buffer(b)
            else:
                g = _repaired(g)
                grow = b if b > 0 and f.buffer is not None else 0.0
                g = _cut(g, box, grow + 2.0 * resolution + 1.0)
                if grow > 0:
                    g = g.buffer(grow)
            if not g.is_empty:
                shapes.append(g)
    if not shapes:
        shapes.append(shapely.Point())
    world = shapely.union_all(shapes)
    if extent:
        width, height = float(extent[2] - extent[0]), float(extent[3] - extent[1])
    else:
        _x0, _y0, width, height = world.bounds
    if not (width > 0 and height > 0):
        raise ConfigError(f"{path}: the map's extent is empty ({width:g} m x {height:g} m east and north of "
                          f"the origin {lat0:.6f}, {lon0:.6f})")
    # (a bound less than 1 % of a cell past a whole cell adds no cell: the growth below still marks it)
    cols, rows = int(math.ceil(width / resolution - 0.01)), int(math.ceil(height / resolution - 0.01))
    if rows * cols > MAX_CELLS:
        raise ConfigError(f"{path}: {width:.0f} m x {height:.0f} m at {resolution:g} m is {cols} x {rows} cells "
                          f"(at most {MAX_CELLS:,}); choose a coarser resolution or a smaller extent")
    # Every cell the geometry touches: grow it by half a cell's diagonal and test the centres.
    grown = world.buffer(resolution * math.sqrt(0.5))
    shapely.prepare(grown)
    ys, xs = (np.mgrid[0:rows, 0:cols] + 0.5) * resolution
    occ = shapely.contains_xy(grown, xs.ravel(), ys.ravel()).reshape(rows, cols)
    return ChartGrid(occ, (lat0, lon0), float(resolution))


def geodesy_overrides(scenario: str | None, geodesy: GeodesyParams) -> list[str]:
    """``--set`` overrides that put the NED origin at a chart scenario's map corner and keep the origin
    of its positions in metres (``geodesy.positions_origin``): [] for other scenarios, and for a
    scenario that does not load (the command reports that itself). ``geodesy``: the configuration's
    ``[geodesy]``; the same lines again when it already holds them (a run's processes)."""
    if not scenario:
        return []
    from hil import scenario as scenarios
    from hil.errors import UsageError

    try:
        spec = scenarios.load_spec(scenario)
        if spec.kind != "fixed" or not is_chart(spec.map):
            return []
        positions = scenarios.positions_frame(spec, geodesy)
        lat0, lon0 = grid_corner(scenarios.resolve_file(spec, spec.map), positions, spec.extent)
    except (ConfigError, UsageError):
        return []
    return [f"geodesy.lat0={lat0!r}", f"geodesy.lon0={lon0!r}",
            f"geodesy.positions_origin=[{positions.lat0!r}, {positions.lon0!r}]"]
