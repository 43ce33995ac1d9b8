"""The example world `configs/worlds/bay/`: a self-made harbour chart (GeoJSON) and a tidal current file
(CF netCDF), and the scenario `configs/scenarios/bay.toml` that uses them.

Self-made for this project (not a navigational chart, no survey data): shapes drawn in metres around
the configuration's origin (38.92 N, 121.65 E) and converted to WGS-84 with ``common.geodesy``; the
current is an M2 tidal stream (period 12.42 h) of 0.3 m/s amplitude along the harbour, a figure typical
of a sheltered harbour, plus a steady 0.05 m/s northward drift. Licence: the project's (BSD-3-Clause).

``python -m hil.example_world [DIR]`` writes the chart and the current file (default: the committed
folder); the scenario file is committed as written by hand.
"""

from __future__ import annotations

import json
import math
import sys
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from common.geodesy import LocalFrame
from hil.config import CONFIG_DIR

if TYPE_CHECKING:
    import xarray as xr

WORLD_DIR = CONFIG_DIR / "worlds" / "bay"
ORIGIN = (38.92, 121.65)           # deg: the map's south-west corner
EXTENT = (300.0, 200.0)            # m east, north
M2_PERIOD_S = 12.42 * 3600.0
TIDE_AMPLITUDE = 0.3               # m/s along the harbour (east-west)
DRIFT_NORTH = 0.05                 # m/s
START_TIME = "2024-05-01T00:00:00"
HOURS = 7                          # hourly slices: 6 h of run time


def _features() -> list[tuple[str, str, list, float | None]]:
    """(name, GeoJSON type, coordinates in map metres, buffer m or None) of the harbour's obstacles."""
    def box(x0: float, y0: float, x1: float, y1: float) -> list[list[tuple[float, float]]]:
        return [[(x0, y0), (x1, y0), (x1, y1), (x0, y1), (x0, y0)]]

    island = [(40.0 + 13.0 * math.cos(a), 165.0 + 10.0 * math.sin(a)) for a in np.linspace(0, 2 * math.pi, 13)]
    island[-1] = island[0]
    return [
        ("quay", "Polygon", box(0, 0, 300, 20), None),
        ("pier A", "Polygon", box(70, 20, 80, 85), None),
        ("pier B", "Polygon", box(150, 20, 158, 60), None),
        ("breakwater", "Polygon", box(115, 128, 300, 137), None),
        ("island", "Polygon", [island], None),
        ("mole", "LineString", [(200.0, 60.0), (235.0, 100.0)], 3.0),
        ("piles", "MultiPoint", [(112.0, 60.0), (118.0, 60.0), (124.0, 60.0)], 1.5),
    ]


def chart(frame: LocalFrame) -> dict:
    """The chart as a GeoJSON FeatureCollection (longitude/latitude, 7 decimals: ~1 cm)."""
    def ll(p: tuple[float, float]) -> list[float]:
        lat, lon = frame.sea_level_to_geodetic(p[1], p[0])
        return [round(lon, 7), round(lat, 7)]

    feats = []
    for name, kind, coords, buffer in _features():
        geo: list[list[list[float]]] | list[list[float]]
        if kind == "Polygon":
            geo = [[ll(p) for p in ring] for ring in coords]
        else:
            geo = [ll(p) for p in coords]
        props: dict = {"name": name}
        if buffer is not None:
            props["buffer"] = buffer
        feats.append({"type": "Feature", "properties": props, "geometry": {"type": kind, "coordinates": geo}})
    return {"type": "FeatureCollection", "name": "bay (self-made example harbour, BSD-3-Clause)", "features": feats}


def current_dataset(frame: LocalFrame) -> xr.Dataset:
    """The tidal current as an xarray Dataset with CF attributes (CMEMS-like layout)."""
    import pandas as pd
    import xarray as xr

    lat0, lon0 = frame.sea_level_to_geodetic(-100.0, -100.0)
    lat1, lon1 = frame.sea_level_to_geodetic(EXTENT[1] + 100.0, EXTENT[0] + 100.0)
    lat = np.round(np.linspace(lat0, lat1, 11), 7)
    lon = np.round(np.linspace(lon0, lon1, 13), 7)
    times = pd.date_range(START_TIME, periods=HOURS, freq="1h")
    t = np.arange(HOURS) * 3600.0
    east = TIDE_AMPLITUDE * np.cos(2 * math.pi * t / M2_PERIOD_S)
    u = np.broadcast_to(east[:, None, None], (HOURS, lat.size, lon.size)).astype("float32")
    v = np.full((HOURS, lat.size, lon.size), DRIFT_NORTH, dtype="float32")
    return xr.Dataset(
        {"uo": (("time", "latitude", "longitude"), u,
                {"standard_name": "eastward_sea_water_velocity", "units": "m s-1"}),
         "vo": (("time", "latitude", "longitude"), v,
                {"standard_name": "northward_sea_water_velocity", "units": "m s-1"})},
        coords={"time": ("time", times, {"standard_name": "time", "axis": "T"}),
                "latitude": ("latitude", lat, {"standard_name": "latitude", "units": "degrees_north"}),
                "longitude": ("longitude", lon, {"standard_name": "longitude", "units": "degrees_east"})},
        attrs={"Conventions": "CF-1.8", "title": "bay: M2 tidal stream, self-made example",
               "license": "BSD-3-Clause (the usv-hil project's)",
               "source": "hil/example_world.py (synthetic: no measurement or model output)"})


def write(folder: Path = WORLD_DIR) -> tuple[Path, Path]:
    """Write ``bay.geojson`` and ``currents.nc`` into ``folder``."""
    folder.mkdir(parents=True, exist_ok=True)
    frame = LocalFrame(*ORIGIN)
    chart_path = folder / "bay.geojson"
    chart_path.write_text(json.dumps(chart(frame), indent=1) + "\n")
    nc_path = folder / "currents.nc"
    current_dataset(frame).to_netcdf(nc_path, engine="netcdf4",
                                     encoding={"time": {"units": "hours since 2024-05-01 00:00:00", "dtype": "f8"}})
    return chart_path, nc_path


if __name__ == "__main__":
    for p in write(Path(sys.argv[1]) if len(sys.argv) > 1 else WORLD_DIR):
        print(p)
