"""Write the files a marine user's tools write: CF netCDF current files (xarray or netCDF4 directly)."""

from __future__ import annotations

from collections.abc import Callable, Sequence
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
