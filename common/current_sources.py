"""Sea-current sources: the analytic eq. (13), a uniform current, and a gridded current read from a file.

Every source answers the same two questions in the local NED frame (metres from the
configuration's geodesy origin, seconds of run time):

* ``velocity_at(north, east, t) -> (v_north, v_east)`` m/s, plain floats (the simulator's hot path);
* ``velocity(north, east, t) -> (v_north, v_east)`` numpy arrays (the planner's sampled field).

:func:`make_current` picks the source from a ``[current]`` table (``simulator.config.CurrentParams``):
``enabled = false`` -> none; ``file = "x.nc"`` -> :class:`GriddedCurrent`; ``uniform = [east, north]``
-> :class:`UniformCurrent`; otherwise the meandering jet of eq. (13)
(:class:`common.current_field.CurrentField`). The simulator and the planner both build theirs here,
so the boat feels the current the planner plans with.

Files. A netCDF file (read with xarray; netCDF-4/HDF5 through the netCDF4 library, netCDF-3 through
scipy) with the eastward and northward velocity found by CF ``standard_name``
(``eastward_sea_water_velocity`` / ``northward_sea_water_velocity``, or their ``surface_`` and
``_assuming_no_tide`` variants) or by the names given in ``east_variable`` / ``north_variable``, on 1-D
latitude and longitude coordinates (degrees north/east), or on a curvilinear grid (two dimensions of
its own, eta x xi, with 2-D latitude/longitude found by the velocity's CF ``coordinates`` attribute,
``standard_name``, units or usual names: ROMS's ``lat_rho``/``lon_rho``, NEMO's ``nav_lat``/``nav_lon``),
and optionally time and depth (the level nearest the surface is used: the highest of a coordinate that
is ``positive = "up"``). Grid-relative velocity (``sea_water_x_velocity``/``..._y_...``, ROMS's u, v at
rho points) is turned east/north by the grid's ``angle`` (radians from east to xi, counter-clockwise:
ROMS's convention); ROMS's ``mask_rho`` marks land. Units ``m s-1`` (as
variously spelt), ``cm s-1`` or knots; missing values (land in ocean-model output) read as still water.
A single station's series (a moored ADCP: latitude and longitude of one value each, as variables or as
dimensions of size 1) is taken as the current over the whole map, varying in time only, if it lies
within ``STATION_MAX_DISTANCE`` of the origin. The run's t = 0 is the file's time ``start_time`` (ISO
8601, UTC; default: the file's first time); a file with one time slice is a steady current. On loading,
each time slice is resampled onto a regular NED grid (each node's latitude and longitude from the exact
tangent-plane conversion of ``common.geodesy``, the file bilinearly interpolated there; a curvilinear
file's nodes converted to NED metres the same way and its cells' triangles interpolated linearly,
:func:`_cell_triangles`); queries then interpolate bilinearly in space and linearly in time, clamped at
the edges.
:meth:`GriddedCurrent.check_covers` refuses, in one line, a file that does not cover a map or a run's
time span.
"""

from __future__ import annotations

import bisect
import math
import os
from dataclasses import dataclass
from typing import TYPE_CHECKING, Protocol

import numpy as np
import numpy.typing as npt

from common.current_params import CurrentParams

if TYPE_CHECKING:
    import xarray as xr
from common.geodesy import LocalFrame

EAST_NAMES = ("eastward_sea_water_velocity", "surface_eastward_sea_water_velocity",
              "eastward_sea_water_velocity_assuming_no_tide", "baroclinic_eastward_sea_water_velocity")
NORTH_NAMES = ("northward_sea_water_velocity", "surface_northward_sea_water_velocity",
               "northward_sea_water_velocity_assuming_no_tide", "baroclinic_northward_sea_water_velocity")
# after lower-casing and spelling out (see _scale): "meters per second" -> "m/s", "m s^-1" -> "m s-1"
_UNITS = {"m s-1": 1.0, "m/s": 1.0, "m.s-1": 1.0, "m s**-1": 1.0, "m/second": 1.0, "ms-1": 1.0, "mps": 1.0,
          "cm s-1": 0.01, "cm/s": 0.01, "cm.s-1": 0.01, "cm s**-1": 0.01, "centim/second": 0.01, "centim s-1": 0.01,
          "kn": 0.514444, "knot": 0.514444, "knots": 0.514444, "kt": 0.514444}
MAX_SPEED = 10.0        # m/s: faster than any tidal race (Saltstraumen ~ 11 m/s is the one known exception)
MAX_NODES = 512         # per axis of the resampled NED grid
MAX_VALUES = 20_000_000  # time slices x nodes: a larger file must be cut down first
MAX_READ = 50_000_000   # time slices x file nodes read from disk (u and v each, after the reach's window)
M_PER_DEG_MIN = 110_000.0   # m per degree of latitude, rounded down (110,574 m at the equator): windows err wide
# m: a single station's current is taken as the current of a harbour-sized area around it; a station farther
# from the origin than this is surely another place's (a tidal stream changes over a few km along a coast).
STATION_MAX_DISTANCE = 20_000.0
# m: a curvilinear grid's nodes farther from the origin than this (great circle) are left out: a tangent
# plane is no map of them (beyond a quarter of the globe they would fold back over the origin's area).
CURVILINEAR_REACH = 1_000_000.0


# Latitude and longitude, wherever they are looked for (a grid's axes, a curvilinear grid's 2-D
# coordinates, a station's position): the usual names (lower-cased; ROMS's lat_rho, NEMO's nav_lat) and
# the CF units of degrees north/east; a CF standard_name equal to the key also counts.
_POSITION: dict[str, tuple[tuple[str, ...], tuple[str, ...]]] = {
    "latitude": (("lat", "latitude", "lat_rho", "nav_lat"), ("degrees_north", "degree_north", "degree_N", "degrees_N")),
    "longitude": (("lon", "longitude", "lon_rho", "nav_lon"), ("degrees_east", "degree_east", "degree_E", "degrees_E")),
}
# Grid-relative velocity (along a curvilinear grid's xi and eta lines: ROMS's u, v), by CF standard_name prefix.
X_PREFIX, Y_PREFIX = "sea_water_x_velocity", "sea_water_y_velocity"
# A grid's angle from east to its xi axis (ROMS's ``angle``, radians, counter-clockwise): name or standard_name.
ANGLE_NAMES = ("angle", "angle_of_rotation_from_east_to_x")
_OTHER_AXIS_NAMES = {"time": ("time", "t", "ocean_time"), "depth": ("depth", "z", "lev", "level", "deptht", "s_rho")}


class CurrentSourceError(ValueError):
    """A current file or table that cannot be used: the message is one line for the user."""


class CurrentSource(Protocol):
    """A current in the NED frame."""

    def velocity_at(self, north: float, east: float, t: float) -> tuple[float, float]: ...

    def velocity(self, north: npt.ArrayLike, east: npt.ArrayLike,
                 t: npt.ArrayLike) -> tuple[np.ndarray, np.ndarray]: ...


class UniformCurrent:
    """The same current everywhere and always: ``east``, ``north`` in m/s."""

    def __init__(self, east: float, north: float) -> None:
        if not (math.isfinite(east) and math.isfinite(north)) or math.hypot(east, north) > MAX_SPEED:
            raise CurrentSourceError(f"current.uniform: [{east:g}, {north:g}] m/s is not a sea current "
                                     f"(finite, at most {MAX_SPEED:g} m/s)")
        self.east, self.north = float(east), float(north)

    def velocity_at(self, north: float, east: float, t: float) -> tuple[float, float]:
        return self.north, self.east

    def velocity(self, north: npt.ArrayLike, east: npt.ArrayLike, t: npt.ArrayLike) -> tuple[np.ndarray, np.ndarray]:
        shape = np.broadcast_shapes(np.shape(north), np.shape(east), np.shape(t))
        return np.full(shape, self.north), np.full(shape, self.east)


@dataclass(frozen=True)
class RawCurrentGrid:
    """A file's surface current as read: ``u``/``v`` (east/north, m/s) [time, lat, lon], or on a curvilinear
    grid [time, eta, xi] with ``lat``/``lon`` 2-D [eta, xi] (degrees; NaN where a node has no position);
    ``times`` in seconds since the Unix epoch (None: a steady field, one slice)."""

    lat: np.ndarray
    lon: np.ndarray
    times: np.ndarray | None
    u: np.ndarray
    v: np.ndarray


def _find_velocity(ds: xr.Dataset, names: tuple[str, ...], given: str, which: str, path: str) -> xr.DataArray:
    if given:
        if given not in ds.variables:
            raise CurrentSourceError(f"{path}: no variable {given!r} ({which}_variable); it has: "
                                     f"{', '.join(map(str, ds.data_vars))}")
        return ds[given]
    for name in names:
        for var in ds.data_vars.values():
            if var.attrs.get("standard_name") == name:
                return var
    prefix = X_PREFIX if which == "east" else Y_PREFIX   # grid-relative (ROMS's u, v): rotated by the grid's angle
    for var in ds.data_vars.values():
        if _grid_relative(var, prefix):
            return var
    raise CurrentSourceError(f"{path}: no variable with standard_name {names[0]!r}; name it with "
                             f"current.{which}_variable (variables: {', '.join(map(str, ds.data_vars))})")


def _axis(ds: xr.Dataset, var: xr.DataArray, kind: str) -> str | None:
    """The name of ``var``'s dimension that is latitude, longitude, time or depth (CF attributes or usual names)."""
    names = _POSITION[kind][0] if kind in _POSITION else _OTHER_AXIS_NAMES[kind]
    units = _POSITION[kind][1] if kind in _POSITION else ()
    cf_axis = {"latitude": "Y", "longitude": "X", "time": "T", "depth": "Z"}[kind]
    for dim in var.dims:
        c = ds[dim] if dim in ds.variables else None
        attrs = c.attrs if c is not None else {}
        if (attrs.get("standard_name") == kind or attrs.get("units") in units or attrs.get("axis") == cf_axis
                or (kind == "time" and c is not None and np.issubdtype(c.dtype, np.datetime64))
                or (kind == "depth" and str(attrs.get("positive", "")).lower() in ("up", "down"))):
            return str(dim)
    for dim in var.dims:
        if str(dim).lower() in names and (dim in ds.variables or kind == "depth"):
            return str(dim)
    return None


def _station(ds: xr.Dataset, kind: str) -> float | None:
    """A single station's latitude or longitude (degrees): a variable of one value that is one (CF
    attributes or usual names), as a moored ADCP's time series gives its position; None if none."""
    for name, var in ds.variables.items():
        if var.size == 1 and _is_position(kind, name, var.attrs):
            try:
                return float(np.asarray(var.values, dtype=float).ravel()[0])
            except (TypeError, ValueError):
                continue   # a name or a label, not the position
    return None


def _is_position(kind: str, name: object, attrs: dict) -> bool:
    """Whether a variable of this name and these attributes is latitude (``kind``) or longitude."""
    names, units = _POSITION[kind]
    return attrs.get("standard_name") == kind or attrs.get("units") in units or str(name).lower() in names


def _grid_2d(ds: xr.Dataset, var: xr.DataArray) -> tuple[str, str] | None:
    """The names of the 2-D latitude and longitude of ``var``'s curvilinear grid, on two of its dimensions:
    those its CF ``coordinates`` attribute names first, then any variable (CF attributes or usual names)."""
    listed = str(var.attrs.get("coordinates") or var.encoding.get("coordinates") or "").split()
    candidates = [n for n in listed if n in ds.variables] + [str(n) for n in ds.variables if n not in listed]
    found: dict[str, str] = {}
    for kind in ("latitude", "longitude"):
        for name in candidates:
            c = ds[name]
            if c.ndim == 2 and set(c.dims) <= set(var.dims) and _is_position(kind, name, c.attrs):
                found[kind] = name
                break
    if len(found) < 2 or set(ds[found["latitude"]].dims) != set(ds[found["longitude"]].dims):
        return None
    return found["latitude"], found["longitude"]


def _grid_relative(var: xr.DataArray, prefix: str) -> bool:
    return str(var.attrs.get("standard_name", "")).startswith(prefix)


def _angle(ds: xr.Dataset, horizontal: tuple[str, str], path: str,
           window: dict[str, slice | np.ndarray]) -> np.ndarray | None:
    """A grid's angle (radians) from east to its xi axis on the ``horizontal`` dimensions, read within
    ``window`` (isel), or None."""
    for name, var in ds.variables.items():
        if (str(name).lower() in ANGLE_NAMES or var.attrs.get("standard_name") in ANGLE_NAMES) \
                and set(var.dims) == set(horizontal):
            units = str(var.attrs.get("units", "radians")).strip().lower()
            scale = math.pi / 180.0 if units.startswith("degree") else 1.0
            if not (units.startswith("degree") or units in ("radians", "radian", "rad", "1", "")):
                raise CurrentSourceError(f"{path}: {name}: units {var.attrs.get('units')!r} not understood "
                                         "(expected radians or degrees)")
            return np.asarray(var.transpose(*horizontal).isel(window).values, dtype=float) * scale
    return None


def _land_mask(ds: xr.Dataset, horizontal: tuple[str, str], window: dict[str, slice | np.ndarray]) -> np.ndarray | None:
    """True on land, from a ROMS ``mask_rho`` or a CF ``sea_binary_mask`` (0 = land) on the grid, read within
    ``window`` (isel), or None."""
    for name, var in ds.variables.items():
        if (str(name).lower() == "mask_rho" or var.attrs.get("standard_name") == "sea_binary_mask") \
                and set(var.dims) == set(horizontal):
            return np.asarray(var.transpose(*horizontal).isel(window).values, dtype=float) == 0.0
    return None


def _scale(var: xr.DataArray, path: str) -> float:
    units = " ".join(str(var.attrs.get("units", "m s-1")).strip().lower().replace("^", "").split())
    units = units.replace("metres", "m").replace("meters", "m").replace("metre", "m").replace("meter", "m")
    units = units.replace(" per second", "/s").replace("second-1", "s-1").replace("sec-1", "s-1")
    if units not in _UNITS:
        raise CurrentSourceError(f"{path}: {var.name}: units {var.attrs.get('units')!r} not understood "
                                 "(expected m s-1, cm s-1 or knots)")
    return _UNITS[units]


def read_netcdf(path: str, east_variable: str = "", north_variable: str = "",
                near: tuple[float, float, float] | None = None) -> RawCurrentGrid:
    """Read a file's surface current (see the module's docstring); CurrentSourceError in one line.
    ``near`` = (latitude deg, longitude deg, reach m): read only the file's nodes within ``reach`` of that
    point (with one node of the file's spacing beyond, for the interpolation at the window's edge), so
    that a regional or global file costs what the run's area of it does."""
    try:
        import xarray as xr
    except ImportError:  # pragma: no cover - a dependency of the project
        raise CurrentSourceError("reading current files needs xarray (pip install xarray netCDF4)") from None
    if not os.path.isfile(path):
        raise CurrentSourceError(f"current.file: no such file {path}")
    try:
        ds = xr.open_dataset(path)
    except Exception as exc:  # xarray raises many kinds for an unreadable file
        raise CurrentSourceError(f"{path}: cannot be read as netCDF ({type(exc).__name__}: "
                                 f"{str(exc).splitlines()[0] if str(exc) else ''})") from None
    with ds:
        u_var = _find_velocity(ds, EAST_NAMES, east_variable, "east", path)
        v_var = _find_velocity(ds, NORTH_NAMES, north_variable, "north", path)
        rotate = _grid_relative(u_var, X_PREFIX) or _grid_relative(v_var, Y_PREFIX)
        if rotate and not (_grid_relative(u_var, X_PREFIX) and _grid_relative(v_var, Y_PREFIX)):
            raise CurrentSourceError(f"{path}: {u_var.name} and {v_var.name}: one grid-relative and one "
                                     "eastward/northward component")
        if u_var.dims != v_var.dims:
            staggered = " (grid-relative u, v on staggered points, as ROMS's: give u_eastward/v_northward)"
            raise CurrentSourceError(f"{path}: {u_var.name} and {v_var.name} are on different dimensions"
                                     f"{staggered if rotate else ''}")
        dims = {k: _axis(ds, u_var, k) for k in ("latitude", "longitude", "time", "depth")}
        # 1-D axes that are latitude and longitude by name, units or standard_name make a rectilinear grid; else
        # 2-D latitude/longitude on two of the velocity's dimensions make a curvilinear one.
        rectilinear = all(dims[k] is not None and _is_position(k, dims[k], ds[dims[k]].attrs)
                          for k in ("latitude", "longitude"))
        grid2d = None if rectilinear else _grid_2d(ds, u_var)
        horizontal = ("", "")
        if grid2d is not None:
            horizontal = (str(ds[grid2d[0]].dims[0]), str(ds[grid2d[0]].dims[1]))   # (eta, xi)
            dims["latitude"], dims["longitude"] = horizontal
            if dims["depth"] in horizontal:
                dims["depth"] = None
        station = None
        if dims["latitude"] is None and dims["longitude"] is None:
            la, lo = _station(ds, "latitude"), _station(ds, "longitude")
            station = None if la is None or lo is None else (la, lo)
        if (dims["latitude"] is None or dims["longitude"] is None) and station is None:
            raise CurrentSourceError(f"{path}: {u_var.name}: no latitude/longitude (1-D axes or a curvilinear "
                                     "grid's 2-D coordinates) and no single station's position (dims: "
                                     f"{', '.join(map(str, u_var.dims))})")
        sel: dict[str, int] = {}
        if dims["depth"] is not None:
            z = ds[dims["depth"]] if dims["depth"] in ds.variables else None
            depth = np.asarray(z.values if z is not None else np.arange(u_var.sizes[dims["depth"]]), dtype=float)
            # The level nearest the surface: the highest of a coordinate that is positive up (a model's z <= 0,
            # an upward-looking ADCP's height above the bed), else the shallowest depth.
            up = z is not None and str(z.attrs.get("positive", "")).lower() == "up"
            sel[dims["depth"]] = int(np.nanargmax(depth)) if up else int(np.nanargmin(np.abs(depth)))
        for dim in u_var.dims:
            if dim not in dims.values() and dim not in sel:
                if u_var.sizes[dim] != 1:
                    raise CurrentSourceError(f"{path}: {u_var.name}: dimension {dim!r} of size {u_var.sizes[dim]} "
                                             "is neither latitude, longitude, time nor depth")
                sel[str(dim)] = 0
        order = [d for d in (dims["time"], dims["latitude"], dims["longitude"]) if d is not None]
        window: dict[str, slice | np.ndarray] = {}
        lon_window: np.ndarray | None = None      # rectilinear: the window's longitudes, made increasing
        if near is not None and station is None:
            if grid2d is not None:
                window = _curvilinear_window(ds[grid2d[0]].transpose(*horizontal).values,
                                             ds[grid2d[1]].transpose(*horizontal).values, horizontal, near)
            else:
                window, lon_window = _rectilinear_window(ds[dims["latitude"]].values, ds[dims["longitude"]].values,
                                                         (str(dims["latitude"]), str(dims["longitude"])), near)
        read = math.prod(len(range(u_var.sizes[d])[w]) if isinstance(w, slice) else len(w) for d, w in window.items())
        read *= math.prod(u_var.sizes[d] for d in order if d not in window)
        if read > MAX_READ:
            raise CurrentSourceError(f"{path}: {read:,} velocity values to read (at most {MAX_READ:,}): cut the "
                                     "file to the run's time (and area) first")
        u = np.asarray(u_var.isel({**sel, **window}).transpose(*order).values, dtype=float) * _scale(u_var, path)
        v = np.asarray(v_var.isel({**sel, **window}).transpose(*order).values, dtype=float) * _scale(v_var, path)
        if rotate:
            if grid2d is None or (angle := _angle(ds, horizontal, path, window)) is None:
                raise CurrentSourceError(f"{path}: {u_var.name}, {v_var.name} are grid-relative (standard_name "
                                         f"{X_PREFIX}...) and the file has no grid angle on their grid to turn "
                                         "them east/north by; give eastward/northward velocity")
            # ROMS's convention (its angle: from east to the xi axis, counter-clockwise; its u2rho/rotate
            # step in the post-processing of u_eastward/v_northward): east = u cos a - v sin a,
            # north = u sin a + v cos a.
            ca, sa = np.cos(angle), np.sin(angle)
            u, v = u * ca - v * sa, u * sa + v * ca
        if station is not None:   # one station: its series as a 1 x 1 grid
            u, v = u[..., None, None], v[..., None, None]
            lat, lon = np.array([station[0]]), np.array([station[1]])
        elif grid2d is not None:
            lat = np.asarray(ds[grid2d[0]].transpose(*horizontal).isel(window).values, dtype=float)
            lon = np.asarray(ds[grid2d[1]].transpose(*horizontal).isel(window).values, dtype=float)
            land = _land_mask(ds, horizontal, window)
            if land is not None:
                u, v = np.where(land, np.nan, u), np.where(land, np.nan, v)
        else:
            lat_name = str(dims["latitude"])
            lat = np.asarray(ds[lat_name].isel({lat_name: window[lat_name]}).values if lat_name in window
                             else ds[lat_name].values, dtype=float)
            lon = (lon_window if lon_window is not None else np.asarray(ds[dims["longitude"]].values, dtype=float))
        times = None
        if dims["time"] is not None:
            tv = ds[dims["time"]].values
            if tv.dtype == object and tv.size and hasattr(tv.flat[0], "calendar"):
                times = _cftime_seconds(tv, path)
            elif not np.issubdtype(tv.dtype, np.datetime64):
                raise CurrentSourceError(f"{path}: time: not decodable as dates (a CF 'units' of "
                                         "'seconds since ...' is needed)")
            else:
                times = tv.astype("datetime64[ns]").astype(np.int64) / 1e9
            if times.size == 1:       # one time slice: a snapshot, taken as steady
                times, u, v = None, u[0], v[0]
    if times is None:
        u, v = u[None], v[None]
    return _checked(RawCurrentGrid(lat, lon, times, u, v), path)


def _degrees_of(reach: float, lat: float) -> tuple[float, float]:
    """``reach`` m as degrees of latitude and of longitude at latitudes up to ``lat`` (deg), erring wide."""
    dlat = reach / M_PER_DEG_MIN
    worst = min(abs(lat) + dlat, 89.9)
    return dlat, reach / (M_PER_DEG_MIN * math.cos(math.radians(worst)))


def _wrapped(lon: np.ndarray, lon0: float) -> np.ndarray:
    """Longitudes as degrees east of ``lon0`` in [-180, 180) (a 0..360 file against a -180..180 origin)."""
    return (np.asarray(lon, dtype=float) - lon0 + 180.0) % 360.0 - 180.0


def _axis_window(values: np.ndarray, half_width: float) -> np.ndarray:
    """Indices of a 1-D axis (offsets from the window's centre, deg) within ``half_width`` of it, widened
    by one spacing of the axis on each side; the two nearest when fewer would remain (a file far from the
    run: the coverage check then refuses it, having read next to nothing)."""
    finite = values[np.isfinite(values)]
    step = float(np.median(np.abs(np.diff(np.sort(finite))))) if finite.size > 1 else 0.0
    idx = np.flatnonzero(np.abs(values) <= half_width + 1.5 * step)
    if idx.size >= 2:
        return idx
    return np.sort(np.argsort(np.abs(np.nan_to_num(values, nan=np.inf)), kind="stable")[:2])


def _rectilinear_window(lat: np.ndarray, lon: np.ndarray, names: tuple[str, str], near: tuple[float, float, float]
                        ) -> tuple[dict[str, slice | np.ndarray], np.ndarray | None]:
    """The isel window of a rectilinear file near ``near`` = (lat deg, lon deg, reach m), and its
    longitudes as an increasing axis (a window across the file's seam at 0/360 or +-180 is put in order)."""
    lat0, lon0, reach = near
    dlat, dlon = _degrees_of(reach, lat0)
    rows = _axis_window(np.asarray(lat, dtype=float) - lat0, dlat)
    out: dict[str, slice | np.ndarray] = {names[0]: slice(int(rows[0]), int(rows[-1]) + 1)}
    if dlon >= 180.0:
        return out, None
    east = _wrapped(lon, lon0)
    cols = _axis_window(east, dlon)
    if cols.size == east.size:
        return out, None
    cols = cols[np.argsort(east[cols], kind="stable")]
    # A global file holding both ends of its seam (-180 and 180, 0 and 360) has the same meridian twice.
    cols = cols[np.concatenate(([True], np.diff(east[cols]) > 1e-9))]
    out[names[1]] = cols
    return out, lon0 + east[cols]


def _curvilinear_window(lat: np.ndarray, lon: np.ndarray, dims: tuple[str, str], near: tuple[float, float, float]
                        ) -> dict[str, slice | np.ndarray]:
    """The isel window (index ranges on the grid's two dimensions) of the nodes of a curvilinear grid near
    ``near`` = (lat deg, lon deg, reach m), one row and column of cells beyond; none when no node is near
    (the coverage check then refuses the file)."""
    lat0, lon0, reach = near
    dlat, dlon = _degrees_of(reach, lat0)
    inside = (np.abs(np.asarray(lat, dtype=float) - lat0) <= dlat) & (np.abs(_wrapped(lon, lon0)) <= dlon)
    if not inside.any():
        return {}
    out: dict[str, slice | np.ndarray] = {}
    for axis, dim in enumerate(dims):
        hit = np.flatnonzero(inside.any(axis=1 - axis))
        out[dim] = slice(max(int(hit[0]) - 1, 0), min(int(hit[-1]) + 2, inside.shape[axis]))
    return out


def _cftime_seconds(dates: np.ndarray, path: str) -> np.ndarray:
    """Times of a non-standard CF calendar (``noleap``, ``360_day`` ..., decoded by xarray as cftime dates)
    as seconds since the Unix epoch: the first date taken on the standard calendar, the others by their
    intervals in the file's own calendar (what the model stepped through)."""
    from datetime import UTC, datetime

    d0 = dates.flat[0]
    try:
        first = datetime(d0.year, d0.month, d0.day, d0.hour, d0.minute, d0.second, tzinfo=UTC).timestamp()
    except ValueError:
        raise CurrentSourceError(f"{path}: time: its first date {d0} (calendar {d0.calendar}) is no date of the "
                                 "standard calendar; cut the file to start on one") from None
    return np.array([first + (d - d0).total_seconds() for d in dates.ravel()], dtype=float)


def _checked(g: RawCurrentGrid, path: str) -> RawCurrentGrid:
    lat, lon, u, v, times = g.lat, g.lon, g.u, g.v, g.times
    if lat.ndim == 2:
        return _checked_values(_checked_curvilinear(g, path), path)
    if (lat.size < 2 or lon.size < 2) and not (lat.size == 1 and lon.size == 1):
        raise CurrentSourceError(f"{path}: needs at least 2 latitudes and 2 longitudes, or one station "
                                 f"(has {lat.size} x {lon.size})")
    if not (np.all(np.isfinite(lat)) and np.all(np.isfinite(lon)) and np.all(np.abs(lat) <= 90)
            and np.all(np.abs(lon) <= 360)):
        raise CurrentSourceError(f"{path}: latitude/longitude values are not degrees")
    if np.all(np.diff(lat) < 0):   # north to south, as many model files are
        lat, u, v = lat[::-1].copy(), u[:, ::-1], v[:, ::-1]
    if np.all(np.diff(lon) < 0):
        lon, u, v = lon[::-1].copy(), u[:, :, ::-1], v[:, :, ::-1]
    for name, axis in (("latitude", lat), ("longitude", lon)):
        if not np.all(np.diff(axis) > 0):
            raise CurrentSourceError(f"{path}: {name} is not monotonic")
    return _checked_values(RawCurrentGrid(lat, lon, times, u, v), path)


def _checked_curvilinear(g: RawCurrentGrid, path: str) -> RawCurrentGrid:
    """A curvilinear grid's positions: degrees where given (a node without one, NaN, is left out)."""
    lat, lon = g.lat, g.lon
    if lat.shape[0] < 2 or lat.shape[1] < 2:
        raise CurrentSourceError(f"{path}: a curvilinear grid needs at least 2 x 2 nodes (has {lat.shape[0]} x "
                                 f"{lat.shape[1]})")
    placed = np.isfinite(lat) & np.isfinite(lon)
    if not placed.any() or np.any(np.abs(lat[placed]) > 90) or np.any(np.abs(lon[placed]) > 360):
        raise CurrentSourceError(f"{path}: latitude/longitude values are not degrees")
    return RawCurrentGrid(np.where(placed, lat, np.nan), np.where(placed, lon, np.nan), g.times, g.u, g.v)


def _checked_values(g: RawCurrentGrid, path: str) -> RawCurrentGrid:
    """Times increasing; missing velocity (land) as still water; no impossible speed."""
    lat, lon, u, v, times = g.lat, g.lon, g.u, g.v, g.times
    if times is not None:
        if not np.all(np.diff(times) > 0):
            raise CurrentSourceError(f"{path}: time is not increasing")
    finite = np.isfinite(u) & np.isfinite(v)
    if not finite.any():
        raise CurrentSourceError(f"{path}: every velocity value is missing")
    u, v = np.where(finite, u, 0.0), np.where(finite, v, 0.0)
    speed = float(np.max(np.hypot(u, v)))
    if speed > MAX_SPEED:
        raise CurrentSourceError(f"{path}: a current of {speed:.3g} m/s is not a sea current (units?)")
    return RawCurrentGrid(lat, lon, times, np.ascontiguousarray(u), np.ascontiguousarray(v))


def _ned_axes(north: tuple[float, float], east: tuple[float, float], step: tuple[float, float], slices: int,
              source: str) -> tuple[np.ndarray, np.ndarray]:
    """The resampled grid's north and east axes (m) over ``north`` x ``east``, nodes ``step`` (north, east) m
    apart or farther (at most ``MAX_NODES`` a side); too many values for ``slices`` time slices: one line."""
    nn = int(min(MAX_NODES, max(2, math.ceil((north[1] - north[0]) / max(step[0], 1e-3)) + 1)))
    ne = int(min(MAX_NODES, max(2, math.ceil((east[1] - east[0]) / max(step[1], 1e-3)) + 1)))
    if slices * nn * ne > MAX_VALUES:
        raise CurrentSourceError(f"{source}: {slices} time slices of {nn} x {ne} nodes is too large; cut the "
                                 "file to the area and time of the run first")
    return np.linspace(north[0], north[1], nn), np.linspace(east[0], east[1], ne)


def _bilinear(axis_y: np.ndarray, axis_x: np.ndarray, grid: np.ndarray, y: np.ndarray, x: np.ndarray) -> np.ndarray:
    """``grid[..., iy, ix]`` interpolated at (y, x) (arrays of one shape), clamped to the axes."""
    def weights(axis: np.ndarray, q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        q = np.clip(q, axis[0], axis[-1])
        i = np.clip(np.searchsorted(axis, q, side="right") - 1, 0, axis.size - 2)
        return i, (q - axis[i]) / (axis[i + 1] - axis[i])

    iy, fy = weights(axis_y, y)
    ix, fx = weights(axis_x, x)
    return (grid[..., iy, ix] * (1 - fy) * (1 - fx) + grid[..., iy, ix + 1] * (1 - fy) * fx
            + grid[..., iy + 1, ix] * fy * (1 - fx) + grid[..., iy + 1, ix + 1] * fy * fx)


def _cell_triangles(pn: np.ndarray, pe: np.ndarray, placed: np.ndarray, north_axis: np.ndarray,
                    east_axis: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Where the nodes of a regular NED grid (``north_axis`` x ``east_axis``, m) fall in a curvilinear grid
    whose nodes are at ``pn``, ``pe`` (m) [eta, xi]: each cell with four placed corners split into two
    triangles along its diagonal, each NED node linearly interpolated in the triangle that holds it.
    Returns the three file nodes (flat indices into [eta, xi]; -1: the NED node is in no cell) and their
    weights (summing to 1), each [NED node (row-major), 3]."""
    ny, nx = pn.shape
    ids = np.arange(ny * nx).reshape(ny, nx)
    a, b, c, d = ids[:-1, :-1].ravel(), ids[:-1, 1:].ravel(), ids[1:, 1:].ravel(), ids[1:, :-1].ravel()
    tri = np.concatenate([np.stack([a, b, c], axis=1), np.stack([a, c, d], axis=1)])
    tri = tri[placed.ravel()[tri].all(axis=1)]
    tn, te = pn.ravel()[tri], pe.ravel()[tri]                        # [triangle, corner] m
    rows, cols = north_axis.size, east_axis.size
    n0, dn = float(north_axis[0]), float(north_axis[1] - north_axis[0])
    e0, de = float(east_axis[0]), float(east_axis[1] - east_axis[0])
    # The NED nodes in each triangle's bounding box, all triangles' at once.
    r0 = np.clip(np.ceil((tn.min(axis=1) - n0) / dn - 1e-9), 0, rows - 1).astype(np.int64)
    r1 = np.clip(np.floor((tn.max(axis=1) - n0) / dn + 1e-9), 0, rows - 1).astype(np.int64)
    c0 = np.clip(np.ceil((te.min(axis=1) - e0) / de - 1e-9), 0, cols - 1).astype(np.int64)
    c1 = np.clip(np.floor((te.max(axis=1) - e0) / de + 1e-9), 0, cols - 1).astype(np.int64)
    width = np.maximum(c1 - c0 + 1, 0)
    count = np.maximum(r1 - r0 + 1, 0) * width
    t = np.repeat(np.arange(tri.shape[0]), count)
    k = np.arange(int(count.sum())) - np.repeat(np.cumsum(count) - count, count)
    r, col = r0[t] + k // width[t], c0[t] + k % width[t]
    qn, qe = north_axis[r], east_axis[col]
    an, bn, cn = tn[t, 0], tn[t, 1], tn[t, 2]
    ae, be, ce = te[t, 0], te[t, 1], te[t, 2]
    det = (bn - an) * (ce - ae) - (cn - an) * (be - ae)
    ok = det != 0.0
    det = np.where(ok, det, 1.0)
    wb = ((qn - an) * (ce - ae) - (cn - an) * (qe - ae)) / det
    wc = ((bn - an) * (qe - ae) - (qn - an) * (be - ae)) / det
    wa = 1.0 - wb - wc
    tol = 1e-9
    inside = ok & (wa >= -tol) & (wb >= -tol) & (wc >= -tol)
    node = (r * cols + col)[inside]
    node, first = np.unique(node, return_index=True)     # a node on a shared edge: either triangle (equal values)
    corners = np.full((rows * cols, 3), -1, dtype=np.int64)
    weights = np.zeros((rows * cols, 3))
    corners[node] = tri[t[inside][first]]
    weights[node] = np.clip(np.stack([wa, wb, wc], axis=1)[inside][first], 0.0, 1.0)
    weights[node] /= weights[node].sum(axis=1, keepdims=True)
    return corners, weights


def parse_time(text: str, what: str = "current.start_time") -> float:
    """ISO 8601 (UTC unless it says otherwise) -> seconds since the Unix epoch; CurrentSourceError."""
    from datetime import UTC, datetime

    try:
        d = datetime.fromisoformat(text.replace("Z", "+00:00"))
    except ValueError:
        raise CurrentSourceError(f"{what}: {text!r} is not an ISO 8601 time (e.g. 2024-05-01T12:00:00Z)") from None
    if d.tzinfo is None:
        d = d.replace(tzinfo=UTC)
    return d.timestamp()


class GriddedCurrent:
    """A gridded current in NED: ``vn``, ``ve`` (m/s) [slice, row (north), col (east)] on a regular grid
    (``n0 + row * dn``, ``e0 + col * de``, m); ``times`` (s of run time) of the slices. One station's
    series (``station``) is held as [slice, 1, 1], the same everywhere."""

    def __init__(self, raw: RawCurrentGrid, frame: LocalFrame, start_time: float | None = None,
                 source: str = "current file") -> None:
        self.source = source
        self.station = raw.lat.size == 1 and raw.lon.size == 1
        # A curvilinear file's: True at the NED nodes inside its grid (elsewhere the nearest such node's
        # values, as queries beyond a rectilinear file clamp to its edge); None for the others.
        self.covered: np.ndarray | None = None
        if self.station:
            # One station (a moored ADCP's series): its current everywhere, in time only; ``vn``, ``ve`` hold
            # its series [slice, 1, 1] and the queries answer from them directly, with no grid to interpolate
            # on and no extent to check a map against.
            lat, lon = float(raw.lat[0]), float(raw.lon[0])
            lon += 360.0 * round((frame.lon0 - lon) / 360.0)   # 0..360 against -180..180
            away = math.hypot(*frame.geodetic_to_sea_level(lat, lon))
            if not away <= STATION_MAX_DISTANCE:
                raise CurrentSourceError(
                    f"{source}: its one station ({lat:.5f}, {lon:.5f}) is {away / 1e3:.0f} km from the origin; "
                    f"a station's current is used within {STATION_MAX_DISTANCE / 1e3:.0f} km of it")
            self.north_axis = self.east_axis = np.zeros(1)   # the station's one node (not used by queries)
            self.ve, self.vn = raw.u, raw.v
        elif raw.lat.ndim == 2:
            self._resample_curvilinear(raw, frame, source)
        else:
            self._resample(raw, frame, source)
        self.steady = raw.times is None
        if raw.times is None:
            self.times = np.zeros(1)
        else:
            t0 = float(raw.times[0]) if start_time is None else float(start_time)
            self.times = np.asarray(raw.times, dtype=float) - t0
        self._times = [float(t) for t in self.times]
        self.n0, self.e0 = float(self.north_axis[0]), float(self.east_axis[0])
        self.rows, self.cols = self.north_axis.size, self.east_axis.size
        self.dn = self.de = 0.0     # a station's: no grid
        if not self.station:
            self.dn = float(self.north_axis[1] - self.north_axis[0])
            self.de = float(self.east_axis[1] - self.east_axis[0])

    def _resample(self, raw: RawCurrentGrid, frame: LocalFrame, source: str) -> None:
        """The file's grid bilinearly interpolated at the nodes of a regular NED grid inside it."""
        lat, lon = raw.lat, raw.lon
        lon = lon + 360.0 * np.round((frame.lon0 - lon.mean()) / 360.0)  # 0..360 files against a -180..180 origin
        # The NED box inside the file's latitude/longitude box (its edges bow slightly in NED).
        edge = np.linspace(0.0, 1.0, 9)
        la = lat[0] + edge * (lat[-1] - lat[0])
        lo = lon[0] + edge * (lon[-1] - lon[0])
        south = [frame.geodetic_to_sea_level(lat[0], x)[0] for x in lo]
        north = [frame.geodetic_to_sea_level(lat[-1], x)[0] for x in lo]
        west = [frame.geodetic_to_sea_level(y, lon[0])[1] for y in la]
        east = [frame.geodetic_to_sea_level(y, lon[-1])[1] for y in la]
        n0, n1, e0, e1 = max(south), min(north), max(west), min(east)
        if not (n1 > n0 and e1 > e0):
            raise CurrentSourceError(f"{source}: the file's area is empty around the origin")
        # Node spacing: the file's own (in metres), at most MAX_NODES per axis.
        dlat = float(np.min(np.diff(lat))) * 111_000.0
        dlon = float(np.min(np.diff(lon))) * 111_000.0 * max(math.cos(math.radians(frame.lat0)), 0.01)
        self.north_axis, self.east_axis = _ned_axes((n0, n1), (e0, e1), (dlat, dlon), raw.u.shape[0], source)
        nn, ne = self.north_axis.size, self.east_axis.size
        node_lat = np.empty((nn, ne))
        node_lon = np.empty((nn, ne))
        for i, n in enumerate(self.north_axis):
            for j, e in enumerate(self.east_axis):
                node_lat[i, j], node_lon[i, j] = frame.sea_level_to_geodetic(float(n), float(e))
        self.ve = np.ascontiguousarray(_bilinear(lat, lon, raw.u, node_lat, node_lon))
        self.vn = np.ascontiguousarray(_bilinear(lat, lon, raw.v, node_lat, node_lon))

    def _resample_curvilinear(self, raw: RawCurrentGrid, frame: LocalFrame, source: str) -> None:
        """A curvilinear file's grid, linearly interpolated on its cells' triangles, at the nodes of a
        regular NED grid over its nodes' bounding box (``covered``: the NED nodes inside its cells)."""
        lon = raw.lon + 360.0 * np.round((frame.lon0 - np.nanmean(raw.lon)) / 360.0)   # 0..360 against -180..180
        placed = np.isfinite(raw.lat) & np.isfinite(lon)
        la, lo, la0 = np.radians(raw.lat), np.radians(lon - frame.lon0), math.radians(frame.lat0)
        with np.errstate(invalid="ignore"):
            cos_arc = np.sin(la) * math.sin(la0) + np.cos(la) * math.cos(la0) * np.cos(lo)
            placed &= np.arccos(np.clip(np.nan_to_num(cos_arc, nan=-1.0), -1.0, 1.0)) * 6_371_000.0 <= CURVILINEAR_REACH
        if not placed.any():
            raise CurrentSourceError(f"{source}: its curvilinear grid has no node within "
                                     f"{CURVILINEAR_REACH / 1e3:.0f} km of the origin")
        pn = np.full(raw.lat.shape, np.nan)
        pe = np.full(raw.lat.shape, np.nan)
        for (i, j) in zip(*np.nonzero(placed), strict=True):
            pn[i, j], pe[i, j] = frame.geodetic_to_sea_level(float(raw.lat[i, j]), float(lon[i, j]))
        # Node spacing: half the file's typical cell side (m; the median along each grid direction, the smaller),
        # so that a grid turned against north keeps its detail; at most MAX_NODES per axis.
        sides = [np.hypot(np.diff(pn, axis=a), np.diff(pe, axis=a)) for a in (0, 1)]
        side = min(float(np.nanmedian(x)) if np.isfinite(x).any() else math.inf for x in sides)
        if not math.isfinite(side) or side <= 0.0:
            raise CurrentSourceError(f"{source}: its curvilinear grid has no cell with a position at each corner")
        n0, n1 = float(np.nanmin(pn)), float(np.nanmax(pn))
        e0, e1 = float(np.nanmin(pe)), float(np.nanmax(pe))
        slices = raw.u.shape[0]
        self.north_axis, self.east_axis = _ned_axes((n0, n1), (e0, e1), (0.5 * side, 0.5 * side), slices, source)
        nn, ne = self.north_axis.size, self.east_axis.size
        corners, weights = _cell_triangles(pn, pe, placed, self.north_axis, self.east_axis)
        covered = corners[:, 0] >= 0
        if not covered.any():
            raise CurrentSourceError(f"{source}: its curvilinear grid covers no area")
        # Each uncovered node takes the nearest covered node's values (clamping, as at a rectilinear file's edge).
        from scipy import ndimage

        self.covered = covered.reshape(nn, ne)
        nearest = ndimage.distance_transform_edt(~self.covered, return_distances=False, return_indices=True)
        source_node = (nearest[0] * ne + nearest[1]).ravel()
        c, w = corners[source_node], weights[source_node]
        self.ve = np.empty((slices, nn, ne))
        self.vn = np.empty((slices, nn, ne))
        for k in range(slices):   # one slice at a time: [node, 3] gathers, not [slice, node, 3]
            self.ve[k] = np.einsum("nc,nc->n", raw.u[k].ravel()[c], w).reshape(nn, ne)
            self.vn[k] = np.einsum("nc,nc->n", raw.v[k].ravel()[c], w).reshape(nn, ne)

    # -- coverage ------------------------------------------------------------------------------
    @property
    def extent(self) -> tuple[float, float, float, float]:
        """(north_min, north_max, east_min, east_max) in metres: where the file has data (a station: everywhere;
        a curvilinear grid: the box around the NED nodes inside it, which it need not fill)."""
        if self.station:
            return -math.inf, math.inf, -math.inf, math.inf
        if self.covered is not None:
            rows, cols = np.nonzero(self.covered)
            return (float(self.north_axis[rows.min()]), float(self.north_axis[rows.max()]),
                    float(self.east_axis[cols.min()]), float(self.east_axis[cols.max()]))
        return self.n0, float(self.north_axis[-1]), self.e0, float(self.east_axis[-1])

    def _covers_box(self, north: tuple[float, float], east: tuple[float, float]) -> bool:
        """A curvilinear file: whether every NED node of the cells the box (m) touches is inside its grid,
        so that the current anywhere in the box is interpolated from the file's values only."""
        if self.covered is None:
            return True
        lo_r = int(math.floor((north[0] - self.n0) / self.dn + 1e-9))
        hi_r = int(math.ceil((north[1] - self.n0) / self.dn - 1e-9))
        lo_c = int(math.floor((east[0] - self.e0) / self.de + 1e-9))
        hi_c = int(math.ceil((east[1] - self.e0) / self.de - 1e-9))
        if lo_r < 0 or lo_c < 0 or hi_r >= self.rows or hi_c >= self.cols:
            return False
        return bool(self.covered[lo_r:hi_r + 1, lo_c:hi_c + 1].all())

    def time_span(self) -> tuple[float, float]:
        """(first, last) run time (s) the file covers; (-inf, inf) for a steady file."""
        if self.steady:
            return -math.inf, math.inf
        return self._times[0], self._times[-1]

    def check_covers(self, north: tuple[float, float] | None = None, east: tuple[float, float] | None = None,
                     t: tuple[float, float] | None = None, what: str = "the map") -> None:
        """CurrentSourceError (one line) unless the file covers north x east (m) and times t (s)."""
        n0, n1, e0, e1 = self.extent
        tol = 1e-6
        if north is not None and east is not None and (
                north[0] < n0 - tol or north[1] > n1 + tol or east[0] < e0 - tol or east[1] > e1 + tol
                or not self._covers_box(north, east)):
            within = " (not all of it: a curvilinear grid)" if self.covered is not None else ""
            raise CurrentSourceError(
                f"{self.source}: does not cover {what} (it covers north {n0:.0f}..{n1:.0f} m, east {e0:.0f}.."
                f"{e1:.0f} m of the origin{within}; {what} spans north {north[0]:.0f}..{north[1]:.0f} m, "
                f"east {east[0]:.0f}..{east[1]:.0f} m)")
        first, last = self.time_span()
        if t is not None and (t[0] < first - tol or t[1] > last + tol):
            raise CurrentSourceError(
                f"{self.source}: does not cover the run's time (it covers t = {first:g}..{last:g} s of run "
                f"time; the run needs {t[0]:g}..{t[1]:g} s; see current.start_time)")

    # -- queries -------------------------------------------------------------------------------
    def _slices(self, t: float) -> tuple[int, int, float]:
        ts = self._times
        if len(ts) == 1 or t <= ts[0]:
            return 0, 0, 0.0
        if t >= ts[-1]:
            return len(ts) - 1, len(ts) - 1, 0.0
        k = bisect.bisect_right(ts, t) - 1
        return k, k + 1, (t - ts[k]) / (ts[k + 1] - ts[k])

    def velocity_at(self, north: float, east: float, t: float) -> tuple[float, float]:
        """(v_north, v_east) m/s at one point (plain floats)."""
        if self.station:   # the same everywhere: in time only, exactly
            k0, k1, ft = self._slices(t)
            return (self.vn.item(k0, 0, 0) * (1 - ft) + self.vn.item(k1, 0, 0) * ft,
                    self.ve.item(k0, 0, 0) * (1 - ft) + self.ve.item(k1, 0, 0) * ft)
        gy = (north - self.n0) / self.dn
        gx = (east - self.e0) / self.de
        if gy != gy or gx != gx:
            return 0.0, 0.0
        gy = min(max(gy, 0.0), self.rows - 1.0)
        gx = min(max(gx, 0.0), self.cols - 1.0)
        r = min(int(gy), self.rows - 2)
        c = min(int(gx), self.cols - 2)
        fy, fx = gy - r, gx - c
        k0, k1, ft = self._slices(t)
        out = []
        for a in (self.vn, self.ve):
            vals = []
            for k in (k0, k1) if k1 != k0 else (k0,):
                vals.append(a.item(k, r, c) * (1 - fy) * (1 - fx) + a.item(k, r, c + 1) * (1 - fy) * fx
                            + a.item(k, r + 1, c) * fy * (1 - fx) + a.item(k, r + 1, c + 1) * fy * fx)
            out.append(vals[0] if len(vals) == 1 else vals[0] * (1 - ft) + vals[1] * ft)
        return out[0], out[1]

    def velocity(self, north: npt.ArrayLike, east: npt.ArrayLike, t: npt.ArrayLike) -> tuple[np.ndarray, np.ndarray]:
        """Vectorised (v_north, v_east) m/s; ``t`` a scalar or an array broadcast with the points."""
        n, e, tt = np.broadcast_arrays(np.asarray(north, float), np.asarray(east, float), np.asarray(t, float))
        n, e = np.nan_to_num(n), np.nan_to_num(e)
        vn = np.empty(n.shape)
        ve = np.empty(n.shape)
        for tv in np.unique(tt):
            m = tt == tv
            k0, k1, ft = self._slices(float(tv))
            if self.station:   # the same everywhere: in time only, exactly
                vn[m] = self.vn.item(k0, 0, 0) * (1 - ft) + self.vn.item(k1, 0, 0) * ft
                ve[m] = self.ve.item(k0, 0, 0) * (1 - ft) + self.ve.item(k1, 0, 0) * ft
                continue
            vn[m] = (_bilinear(self.north_axis, self.east_axis, self.vn[k0], n[m], e[m]) * (1 - ft)
                     + _bilinear(self.north_axis, self.east_axis, self.vn[k1], n[m], e[m]) * ft)
            ve[m] = (_bilinear(self.north_axis, self.east_axis, self.ve[k0], n[m], e[m]) * (1 - ft)
                     + _bilinear(self.north_axis, self.east_axis, self.ve[k1], n[m], e[m]) * ft)
        return vn, ve


_FILE_CACHE: dict[tuple, GriddedCurrent] = {}


def load_file(path: str, frame: LocalFrame, east_variable: str = "", north_variable: str = "",
              start_time: str = "", reach: float = 0.0) -> GriddedCurrent:
    """A current file as a :class:`GriddedCurrent` in ``frame`` (cached per file version and frame);
    ``reach`` > 0: only its part within ``reach`` m of the frame's origin (:func:`read_netcdf`)."""
    try:
        mtime = os.stat(path).st_mtime_ns
    except OSError:
        raise CurrentSourceError(f"current.file: no such file {path}") from None
    key = (os.path.abspath(path), mtime, frame.lat0, frame.lon0, frame.alt0, east_variable, north_variable,
           start_time, reach)
    if key not in _FILE_CACHE:
        try:
            raw = read_netcdf(path, east_variable, north_variable,
                              near=(frame.lat0, frame.lon0, reach) if reach > 0 else None)
            t0 = parse_time(start_time) if start_time else None
            _FILE_CACHE[key] = GriddedCurrent(raw, frame, t0, source=os.path.basename(path))
        except CurrentSourceError:
            raise
        except (ValueError, TypeError, IndexError, KeyError, OverflowError, MemoryError) as exc:
            # A layout none of the checks above foresaw: one line naming the file and what numpy or
            # xarray said, not a traceback (the file is the user's input).
            first = str(exc).splitlines()[0] if str(exc) else ""
            raise CurrentSourceError(f"{path}: not read as a current file ({type(exc).__name__}: {first})") from None
    return _FILE_CACHE[key]


def make_current(params: CurrentParams, frame: LocalFrame | None = None) -> CurrentSource | None:
    """The current a ``[current]`` table describes, or None when disabled. ``frame``: the geodesy
    origin, needed for a file."""
    if not params.enabled:
        return None
    file, uniform = params.file, tuple(params.uniform)
    if file:
        if frame is None:
            raise CurrentSourceError("current.file: needs the geodesy origin")
        return load_file(file, frame, params.east_variable, params.north_variable, params.start_time, params.reach)
    if uniform:
        return UniformCurrent(float(uniform[0]), float(uniform[1]))
    from common.current_field import CurrentField

    return CurrentField(params)


class NoCurrent:
    """Still water (``enabled = false``): the simulator's stand-in for None."""

    def velocity_at(self, north: float, east: float, t: float) -> tuple[float, float]:
        return 0.0, 0.0

    def velocity(self, north: npt.ArrayLike, east: npt.ArrayLike, t: npt.ArrayLike) -> tuple[np.ndarray, np.ndarray]:
        shape = np.broadcast_shapes(np.shape(north), np.shape(east), np.shape(t))
        return np.zeros(shape), np.zeros(shape)
