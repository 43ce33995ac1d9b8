"""Write the files a marine user's tools write: CF netCDF current files (xarray or netCDF4 directly)."""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from pathlib import Path

import numpy as np

from common.geodesy import LocalFrame

# The default configuration's geodesy origin (configs/default.toml [geodesy]).
LAT0, LON0 = 38.92, 121.65


def metres_box(frame: LocalFrame, south: float, west: float, north: float, east: float) -> tuple[float, ...]:
    """(lat_min, lon_min, lat_max, lon_max) of a NED box (m), on the boat's WGS-84 tangent plane."""
    lat_min, lon_min = frame.sea_level_to_geodetic(south, west)
    lat_max, lon_max = frame.sea_level_to_geodetic(north, east)
    return lat_min, lon_min, lat_max, lon_max


def write_cf_current(path: Path, lat: np.ndarray, lon: np.ndarray, times: Sequence[str] | None,
                     u: Callable[[np.ndarray, np.ndarray, np.ndarray], np.ndarray],
                     v: Callable[[np.ndarray, np.ndarray, np.ndarray], np.ndarray]) -> Path:
    """A CMEMS-like file written with xarray: ``uo``/``vo`` (m s-1) with CF standard names on
    (time, latitude, longitude); ``u(t_hours, lat, lon)`` gives the values (t in hours from the first time)."""
    import pandas as pd
    import xarray as xr

    coords = {"latitude": ("latitude", lat, {"standard_name": "latitude", "units": "degrees_north", "axis": "Y"}),
              "longitude": ("longitude", lon, {"standard_name": "longitude", "units": "degrees_east", "axis": "X"})}
    dims: tuple[str, ...] = ("latitude", "longitude")
    if times is None:
        th = np.zeros(1)
    else:
        stamps = pd.to_datetime(list(times))
        th = np.asarray((stamps - stamps[0]).total_seconds()) / 3600.0
        coords["time"] = ("time", stamps, {"standard_name": "time", "axis": "T"})
        dims = ("time", *dims)
    T, LA, LO = np.meshgrid(th, lat, lon, indexing="ij")
    uu, vv = u(T, LA, LO), v(T, LA, LO)
    if times is None:
        uu, vv = uu[0], vv[0]
    ds = xr.Dataset({
        "uo": (dims, uu.astype("float32"), {"standard_name": "eastward_sea_water_velocity", "units": "m s-1"}),
        "vo": (dims, vv.astype("float32"), {"standard_name": "northward_sea_water_velocity", "units": "m s-1"}),
    }, coords=coords, attrs={"Conventions": "CF-1.8", "title": "test current"})
    ds.to_netcdf(path, engine="netcdf4")
    return path


def lonlat(frame: LocalFrame, x_east: float, y_north: float) -> list[float]:
    """[lon, lat] (GeoJSON order) of a point ``x`` m east and ``y`` m north of ``frame``'s origin."""
    lat, lon = frame.sea_level_to_geodetic(y_north, x_east)
    return [lon, lat]


def harbour_chart(frame: LocalFrame) -> dict:
    """A small harbour chart as GeoJSON (a FeatureCollection in longitude/latitude), drawn in metres
    from ``frame``'s origin: a quay along the south (0..20 m), a pier (60..70 m east, up to 90 m north),
    a mole drawn as a line (buffer 3 m) and three piles as points (the default buffer), in a
    200 m x 150 m water area whose corners are marked by two small buoys."""
    def ring(pts):
        return [lonlat(frame, x, y) for x, y in [*pts, pts[0]]]

    feats = [
        {"type": "Feature", "properties": {"name": "quay"},
         "geometry": {"type": "Polygon", "coordinates": [ring([(0, 0), (200, 0), (200, 20), (0, 20)])]}},
        {"type": "Feature", "properties": {"name": "pier"},
         "geometry": {"type": "Polygon", "coordinates": [ring([(60, 20), (70, 20), (70, 90), (60, 90)])]}},
        {"type": "Feature", "properties": {"name": "mole", "buffer": 3.0},
         "geometry": {"type": "LineString", "coordinates": [lonlat(frame, 120, 140), lonlat(frame, 120, 70)]}},
        {"type": "Feature", "properties": {"name": "piles"},
         "geometry": {"type": "MultiPoint", "coordinates": [lonlat(frame, 150, 40), lonlat(frame, 160, 40),
                                                             lonlat(frame, 170, 40)]}},
        {"type": "Feature", "properties": {"name": "buoy sw", "buffer": 0.2},
         "geometry": {"type": "Point", "coordinates": lonlat(frame, 0.2, 0.2)}},
        {"type": "Feature", "properties": {"name": "buoy ne", "buffer": 0.2},
         "geometry": {"type": "Point", "coordinates": lonlat(frame, 199.8, 149.8)}},
    ]
    return {"type": "FeatureCollection", "features": feats}


# A harbour whose basin is a hole cut out of the land, as charts drawn in a GIS have it, in metres from
# a frame's origin (x east, y north): (layer, name, geometry in metres, properties, cells it decides as
# (x, y, occupied)). Land 200 m x 150 m around a basin (20..180 m east, 20..130 m north) with an island
# in it (one MultiPolygon); a pier drawn in 3-D; a pile (an integer buffer); a self-intersecting
# bow-tie (both lobes are land); a GeometryCollection of a point and a line (buffer 1 m); an anchorage
# marked obstacle = false over open water; a feature without geometry and one with an empty geometry.
def basin_harbour() -> list[tuple[str, str, object, dict, list[tuple[float, float, bool]]]]:
    from shapely.geometry import GeometryCollection, LineString, MultiPolygon, Point, Polygon, box

    land = MultiPolygon([Polygon(box(0, 0, 200, 150).exterior.coords, [box(20, 20, 180, 130).exterior.coords]),
                         box(90, 60, 110, 90)])
    pier = Polygon([(40, 20, 1.5), (50, 20, 1.5), (50, 70, 1.5), (40, 70, 1.5)])
    return [
        ("land", "land", land, {}, [(10, 10, True), (190, 140, True), (100, 75, True),   # land, the island
                                    (30, 50, False), (120, 40, False), (60, 110, False)]),  # the basin: water
        ("piers", "pier", pier, {"obstacle": True}, [(45, 50, True), (52, 50, False)]),
        ("piers", "no geometry", None, {}, []),
        ("piers", "empty", Polygon(), {}, []),
        ("hazards", "pile", Point(150, 40), {"buffer": 2}, [(151.5, 40, True), (153, 40, False)]),
        ("hazards", "bow-tie", Polygon([(150, 60), (170, 80), (170, 60), (150, 80)]), {},
         [(152, 70, True), (168, 70, True), (160, 62, False)]),
        ("hazards", "collection", GeometryCollection([Point(30, 110), LineString([(60, 125), (80, 125)])]),
         {"buffer": 1.0}, [(30.8, 110.3, True), (70, 125.5, True), (70, 127.5, False)]),
        ("hazards", "anchorage", box(130, 100, 170, 125), {"obstacle": False}, [(150, 112, False)]),
    ]


def to_lonlat(geometry: object, frame: LocalFrame) -> object:
    """A geometry in metres from ``frame``'s origin (x east, y north; z kept) in longitude/latitude."""
    import shapely

    def move(xy: np.ndarray) -> np.ndarray:
        out = xy.copy()
        for i, row in enumerate(xy):
            out[i, 0], out[i, 1] = lonlat(frame, float(row[0]), float(row[1]))
        return out

    return shapely.transform(geometry, move, include_z=bool(shapely.has_z(geometry)))


def write_ogr_chart(path: Path, driver: str, features: Sequence[tuple], frame: LocalFrame,
                    crs: Mapping[str, int] | int = 4326, geometry_type: str = "Unknown", **options: object) -> Path:
    """Write ``features`` (as :func:`basin_harbour` gives them) with GDAL itself, through pyogrio's
    writer, one layer per layer name (``crs``: the EPSG code of every layer, or of each by name; the
    coordinates are transformed by PROJ as a GIS exports them). Fields ``name`` (text), ``buffer``
    (integer when every given value is whole, else real) and ``obstacle`` (boolean), null where a
    feature has none. ``options`` go to pyogrio (``layer_options``, ``dataset_options``)."""
    import warnings

    import pyogrio.raw
    import shapely
    from pyproj import Transformer

    for layer in dict.fromkeys(f[0] for f in features):
        epsg = crs if isinstance(crs, int) else crs[layer]
        t = Transformer.from_crs(4326, epsg, always_xy=True)

        def project(g: object, t: Transformer = t) -> object:
            return shapely.transform(g, lambda xy: np.column_stack(t.transform(xy[:, 0], xy[:, 1])))

        rows = [f for f in features if f[0] == layer]
        wkb = np.array([None if g is None else shapely.to_wkb(project(to_lonlat(g, frame)), output_dimension=3)
                        for _l, _n, g, _p, _c in rows], dtype=object)
        buffers = [p.get("buffer") for *_x, p, _c in rows]
        whole = all(b is None or float(b).is_integer() for b in buffers) and any(b is not None for b in buffers)
        obstacle = [p.get("obstacle") for *_x, p, _c in rows]
        data = [np.array([r[1] for r in rows], dtype=object),
                np.array([0 if b is None else b for b in buffers], dtype=np.int32 if whole else float),
                np.array([bool(o) for o in obstacle], dtype=bool)]
        masks = [None, np.array([b is None for b in buffers]), np.array([o is None for o in obstacle])]
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")    # pyogrio's notes on promoting types
            pyogrio.raw.write(path, wkb, field_data=data, fields=["name", "buffer", "obstacle"], field_mask=masks,
                              layer=layer, driver=driver, geometry_type=geometry_type, crs=f"EPSG:{epsg}",
                              append=path.exists(), **options)
    return path


Field = Callable[[float, np.ndarray, np.ndarray], np.ndarray]


def write_curvilinear_current(path: Path, frame: LocalFrame, east: Field, north: Field, *, layout: str = "roms",
                              centre: tuple[float, float] = (100.0, 120.0), angle_deg: float = 30.0,
                              shape: tuple[int, int] = (41, 45), spacing: float = 25.0,
                              seconds: Sequence[float] = (0.0, 3600.0, 7200.0),
                              land: Callable[[np.ndarray, np.ndarray], np.ndarray] | None = None,
                              grid_relative: bool = False) -> Path:
    """A curvilinear current file written with netCDF4 itself, as an ocean model's tools write one.

    The grid: ``shape`` = (eta, xi) nodes ``spacing`` m apart, its xi axis ``angle_deg`` counter-clockwise
    from east, centred ``centre`` = (north, east) m from ``frame``'s origin; each node's latitude/longitude
    from ``frame``. ``east(t_s, n, e)``/``north(...)`` give the earth-referenced velocity (m/s) at a node's
    NED position (m) at ``t_s`` s after the first time; ``land(n, e)`` True where a node is land.

    ``layout = "roms"``: ROMS's history file: ``u_eastward``/``v_northward`` (or, ``grid_relative``, only
    the grid's ``u``/``v`` at rho points with ``angle``) on (ocean_time, s_rho, eta_rho, xi_rho), ``s_rho``
    positive up (the surface level last; the levels below hold a decoy), ``lat_rho``/``lon_rho``,
    ``mask_rho``; land as fill values south of ``centre`` and only masked (a decoy 5 m/s) north of it; also the
    staggered ``u``/``v`` and their ``lat_u`` ... as ROMS writes them. ``layout = "cf"``: a model's CF file:
    ``uvel``/``vvel`` by standard name on (time, nj, ni), whose ``coordinates`` attribute names 2-D
    ``TLAT``/``TLONG`` (degrees), with a decoy ``ULAT``/``ULONG`` half a cell off written first; land NaN."""
    import netCDF4

    ny, nx = shape
    th = np.radians(angle_deg)
    y, x = np.meshgrid((np.arange(ny) - (ny - 1) / 2) * spacing, (np.arange(nx) - (nx - 1) / 2) * spacing,
                       indexing="ij")
    def place(dx: float, dy: float) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        n = centre[0] + (x + dx) * np.sin(th) + (y + dy) * np.cos(th)
        e = centre[1] + (x + dx) * np.cos(th) - (y + dy) * np.sin(th)
        ll = np.array([frame.sea_level_to_geodetic(a, b) for a, b in zip(n.ravel(), e.ravel(), strict=True)])
        return n, e, ll[:, 0].reshape(n.shape), ll[:, 1].reshape(n.shape)

    n, e, lat, lon = place(0.0, 0.0)
    is_land = np.zeros(shape, bool) if land is None else np.asarray(land(n, e), bool)
    ue = np.array([east(t, n, e) for t in seconds])
    vn = np.array([north(t, n, e) for t in seconds])
    fill = 1.0e37 if layout == "roms" else -999.0
    with netCDF4.Dataset(path, "w") as ds:
        ds.Conventions = "CF-1.4" if layout == "roms" else "CF-1.8"
        if layout == "roms":
            tdim, hdims = "ocean_time", ("eta_rho", "xi_rho")
            for name, size in (("ocean_time", None), ("s_rho", 3), ("eta_rho", ny), ("xi_rho", nx),
                               ("eta_u", ny), ("xi_u", nx - 1), ("eta_v", ny - 1), ("xi_v", nx)):
                ds.createDimension(name, size)
            t = ds.createVariable("ocean_time", "f8", ("ocean_time",))
            t.long_name, t.units, t.calendar = "time since initialization", "seconds since 2024-05-01 00:00:00", \
                "gregorian"
            t[:] = np.asarray(seconds) + 86400.0
            s = ds.createVariable("s_rho", "f8", ("s_rho",))
            s.long_name, s.positive, s.standard_name = "S-coordinate at RHO-points", "up", "ocean_s_coordinate_g2"
            s[:] = [-5 / 6, -0.5, -1 / 6]
            for grid, (dx, dy), dims in (("rho", (0.0, 0.0), hdims), ("u", (spacing / 2, 0.0), ("eta_u", "xi_u"))):
                la, lo = (lat, lon) if grid == "rho" else place(dx, dy)[2:]
                if grid == "u":
                    la, lo = la[:, :-1], lo[:, :-1]
                for name, values, units, std in ((f"lat_{grid}", la, "degree_north", "latitude"),
                                                 (f"lon_{grid}", lo, "degree_east", "longitude")):
                    var = ds.createVariable(name, "f8", dims)
                    var.long_name, var.units, var.standard_name = f"{std} of {grid.upper()}-points", units, std
                    var[:] = values
            m = ds.createVariable("mask_rho", "f8", hdims)
            m.long_name, m.flag_values, m.flag_meanings = "mask on RHO-points", np.array([0.0, 1.0]), "land water"
            m[:] = np.where(is_land, 0.0, 1.0)
            a = ds.createVariable("angle", "f8", hdims)
            a.long_name, a.units = "angle between XI-axis and EAST", "radians"
            a[:] = np.full(shape, th)
            if grid_relative:
                c, sn = np.cos(th), np.sin(th)
                fields = (("u", ue * c + vn * sn, "sea_water_x_velocity"),
                          ("v", -ue * sn + vn * c, "sea_water_y_velocity"))
            else:
                fields = (("u_eastward", ue, "eastward_sea_water_velocity"),
                          ("v_northward", vn, "northward_sea_water_velocity"))
                staggered = ds.createVariable("u", "f4", ("ocean_time", "s_rho", "eta_u", "xi_u"), fill_value=fill)
                staggered.standard_name, staggered.units = "sea_water_x_velocity_at_u_location", "meter second-1"
                staggered[:] = np.zeros((len(seconds), 3, ny, nx - 1))
            for name, values, std in fields:
                var = ds.createVariable(name, "f4", ("ocean_time", "s_rho", *hdims), fill_value=fill)
                var.long_name, var.units, var.standard_name = f"{name} momentum component", "meter second-1", std
                var.coordinates = "lon_rho lat_rho s_rho ocean_time"
                data = np.ma.masked_array(np.repeat(values[:, None], 3, axis=1).astype("f4"))
                data[:, :2] = 7.5                                    # deeper levels: not the surface
                half = is_land & (n < centre[0])                       # the south half
                data[:, :, half] = np.ma.masked                       # land as fill values ...
                data[:, :, is_land & ~half] = 5.0                     # ... or only in mask_rho
                var[:] = data
        else:
            tdim, hdims = "time", ("nj", "ni")
            for name, size in (("time", None), ("nj", ny), ("ni", nx)):
                ds.createDimension(name, size)
            t = ds.createVariable("time", "f8", ("time",))
            t.units, t.standard_name = "hours since 2024-05-01 00:00:00", "time"
            t[:] = np.asarray(seconds) / 3600.0
            _, _, ula, ulo = place(spacing / 2, spacing / 2)
            for name, values, units in (("ULAT", ula, "degrees_north"), ("ULONG", ulo, "degrees_east"),
                                        ("TLAT", lat, "degrees_north"), ("TLONG", lon, "degrees_east")):
                var = ds.createVariable(name, "f8", hdims)
                var.units = units
                var[:] = values
            for name, values, std in (("uvel", ue, "eastward_sea_water_velocity"),
                                      ("vvel", vn, "northward_sea_water_velocity")):
                var = ds.createVariable(name, "f4", (tdim, *hdims), fill_value=fill)
                var.units, var.standard_name, var.coordinates = "cm/s", std, "TLONG TLAT"
                var[:] = np.ma.masked_array(values * 100.0, mask=np.broadcast_to(is_land, values.shape))
    return path
