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
