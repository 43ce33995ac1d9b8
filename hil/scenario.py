"""Scenarios: a map, start and goal, a global reference path and the current, from ``configs/scenarios/NAME.toml``
(or any .toml path; files it names, such as the map, are relative to it).

Map frame (planner/API): x east, y north in metres, headings counter-clockwise from +x (rad).
The map's origin (x = 0, y = 0, its south-west corner) is the NED origin of the simulator, so
a map point (x, y) is NED (north = y, east = x); the HIL loop starts the simulated vessel at
``start``.

The map may be a grid (.npy, .png) or a vector chart in longitude/latitude (``hil.charts``: the
grid's south-west corner becomes the run's NED origin; positions in metres count from the
configuration's origin and are moved onto the grid). With ``positions = "latlon"`` every position
is [latitude, longitude]. The current may be eq. (13), uniform or a CF netCDF file
(``common.current_sources``; a file that does not cover the map is refused). docs/worlds.md.

A scenario file is loaded strictly (unknown or missing keys, wrong types and out-of-range values
are one-line errors). Its optional tables override keys of other sections:

* ``[current]``  keys of the configuration's ``[current]`` section (eq. 13 field, NED metres):
  ``enabled``, ``origin_x`` (north), ``origin_y`` (east, i.e. the map x of the jet axis) ...;
  ``field_time`` (s) is the instant at which the quasi-static field is frozen for planning.
* ``[planner]``  keys of ``planner.params.PlannerParams``.
* ``[online]``   keys of ``planner.online.OnlineParams`` (cycle time, local budget ...).
* ``uncharted``  obstacles that exist in the simulated world but not on the vessel's chart
  (discs ``[[x, y, radius], ...]``, metres, map frame): the simulator's range sensor sees them,
  the autopilot learns them only from it, and collisions are judged against them.
* ``[[traffic]]`` ship traffic (``simulator.traffic.ShipSpec``: MMSI, start, speed, course or
  waypoints with per-leg speeds, AIS dimensions), sailed by the simulator and reported by AIS.
* ``[random]``   for ``kind = "random"`` (Figure 11): each Monte Carlo run draws its own map,
  start and goal from the run's seed; the reference path is then the straight line between
  them, which may cross obstacles. With ``waypoints = [lo, hi]`` it also draws that many
  intermediate waypoints, and the route through them is planned as for a fixed scenario.

The global route. ``reference_path`` holds the route's waypoints as a user gives them (start
first, goal last; only start and goal is fine). With ``global_route = true`` (the default) it is
turned into the global reference path by ``planner.global_route`` on the chart inflated by the
planner's safety radius, when something first needs it (:mod:`hil.routing`; loading plans
nothing): legs whose straight line is free stay straight, the others are routed
round the obstacles (Lazy Theta*), and the result is densified to points at most
``route_spacing`` apart. A waypoint off the chart, inside an obstacle or its safety margin, or
not reachable by water is a one-line error naming it. ``global_route = false`` keeps the
reference path exactly as given (the paper's Figures 9-11: a path that may cross obstacles).
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Literal, TypeVar

import numpy as np
import numpy.typing as npt

from common.params import param
from hil import charts, config
from hil.config import CONFIG_DIR
from hil.errors import ConfigError, UsageError
from hil.routing import PlannedRoute, RouteRequest, plan_route, route_waypoints, take_route
from hil.scenario_names import SCENARIO_DIR, available
from simulator.config import CurrentParams, GeodesyParams
from simulator.traffic import ShipSpec

if TYPE_CHECKING:
    from _typeshed import DataclassInstance

    from common.current_sources import CurrentSource
    from common.geodesy import LocalFrame
    from hil.maps import Canvas
    from hil.settings import HilConfig
    from planner.field import GridField
    from planner.online import OnlineParams
    from planner.params import PlannerParams

D = TypeVar("D", bound="DataclassInstance")


@dataclass(frozen=True)
class RandomSpec:
    """How a random (Figure 11) scenario draws one run's map and end points."""

    width: float = param("map width (x, east)", "m", gt=0, le=2000)
    height: float = param("map height (y, north)", "m", gt=0, le=2000)
    resolution: float = param("cell size", "m", gt=0)
    discs: tuple[int, int] = param("range of the number of discs [min, max]", "", ge=0)
    rects: tuple[int, int] = param("range of the number of rotated rectangles [min, max]", "", ge=0)
    radius: tuple[float, float] = param("range of disc radii [min, max]", "m", gt=0)
    margin: float = param("start and goal keep this far from the map edges", "m", ge=0)
    min_distance: float = param("minimum start-goal distance", "m", gt=0)
    clearance: float = param("start and goal are cleared of obstacles within this radius", "m", ge=0)
    reference_spacing: float = param("spacing of the straight reference path's waypoints", "m", gt=0)
    waypoints: tuple[int, int] = param(
        "range of the number of intermediate route waypoints [min, max]; 0 = the straight start-goal line "
        "(Figure 11), else the global route through them", "", ge=0, default=(0, 0))
    min_leg: float = param("minimum distance between consecutive route waypoints", "m", gt=0, default=35.0)
    global_route: bool = param(
        "without intermediate waypoints: the reference path is the global route from start to goal on the chart "
        "inflated by the safety radius (planner.global_route) instead of the straight line (Figure 11 with the "
        "global route on); the map, start and goal drawn are the same either way", default=False)

    def __post_init__(self) -> None:
        for key in ("discs", "rects", "radius", "waypoints"):
            lo, hi = getattr(self, key)
            if lo > hi:
                raise ValueError(f"{key}: min must not exceed max")
        if self.min_distance >= math.hypot(self.width - 2 * self.margin, self.height - 2 * self.margin):
            raise ValueError("min_distance: larger than the map's usable diagonal")


@dataclass(frozen=True)
class ScenarioSpec:
    """The contents of a scenario TOML file."""

    name: str = param("scenario name (the file's stem)")
    description: str = param("one-line description")
    kind: Literal["fixed", "random"] = param("'fixed' map and end points, or 'random' per Monte Carlo run")
    map: str = param("map file relative to the scenario file (fixed scenarios): a grid (.npy, .png) or a vector "
                     "chart in longitude/latitude (.geojson, .shp, .gpkg, .kml, S-57 .000; docs/worlds.md)",
                     default="")
    resolution: float = param("map cell size", "m", gt=0, default=0.5)
    origin: tuple[float, ...] = param(
        "charts: [latitude, longitude] from which the scenario's positions in metres count (default: the "
        "configuration's [geodesy] origin)", "deg", ge=-180, le=360, default=())
    extent: tuple[float, ...] = param("charts: the map's [west, south, east, north] in metres from the origin "
                                      "(default: the chart's bounds)", "m", ge=-50_000, le=50_000, default=())
    positions: Literal["metres", "latlon"] = param(
        "how start, goal, reference_path, the uncharted discs' centres and the traffic's start and waypoints are "
        "given: 'metres' [x east, y north] of the map, or 'latlon' [latitude, longitude] in degrees",
        default="metres")
    chart_buffer: float = param("charts: radius given to points and half-width to lines without a 'buffer' "
                                "property", "m", ge=0, le=1000, default=2.0)
    start: tuple[float, float] = param("start position [x east, y north]", "m", default=(0.0, 0.0))
    start_heading: float = param("start heading, counter-clockwise from east", "rad", ge=-4 * math.pi,
                                 le=4 * math.pi, default=0.0)
    goal: tuple[float, float] = param("final goal [x east, y north]", "m", default=(0.0, 0.0))
    reference_path: tuple[tuple[float, float], ...] = param(
        "route waypoints [[x, y], ...], start to goal (legs of any length; may cross obstacles, Figure 9); "
        "empty: start and goal", "m", default=())
    global_route: bool = param(
        "plan the global route through the waypoints on the inflated chart (false: use reference_path as given)",
        default=True)
    route_spacing: float = param("largest gap between the global route's points", "m", gt=0, default=10.0)
    uncharted: tuple[tuple[float, float, float], ...] = param(
        "obstacles missing from the chart: discs [[x, y, radius], ...]; only the range sensor reveals them",
        "m", default=())
    current: dict[str, object] = field(default_factory=dict, metadata={"help": "overrides of [current]"})
    planner: dict[str, object] = field(default_factory=dict, metadata={"help": "overrides of [planner]"})
    online: dict[str, object] = field(default_factory=dict, metadata={"help": "overrides of the online process"})
    random: RandomSpec | None = field(default=None, metadata={"help": "random map generator (kind = 'random')"})
    traffic: tuple[ShipSpec, ...] = field(default=(), metadata={"help": "ship traffic ([[traffic]] tables)"})
    # The file it was read from (set by load_spec, not a TOML key): relative paths start there.
    path: str = field(default="", init=False, compare=False)

    def __post_init__(self) -> None:
        if self.kind == "fixed":
            if not self.map:
                raise ValueError("map: a fixed scenario needs a map file")
            if len(self.reference_path) == 1:
                raise ValueError("reference_path: needs at least two points (start ... goal), or none")
        elif self.random is None:
            raise ValueError("random: a random scenario needs a [random] table")
        if len(self.origin) not in (0, 2) or (self.origin and not -89 <= self.origin[0] <= 89):
            raise ValueError("origin: expected [latitude, longitude] in degrees (latitude within +-89)")
        if len(self.extent) not in (0, 4) or (self.extent and not (self.extent[0] < self.extent[2]
                                                                  and self.extent[1] < self.extent[3])):
            raise ValueError("extent: expected [west, south, east, north] in m, west < east and south < north")
        if (self.origin or self.extent) and not charts.is_chart(self.map):
            raise ValueError("origin, extent: only for a chart map (.geojson, .shp, ...)")
        for x, y, r in self.uncharted:
            if r <= 0:
                raise ValueError(f"uncharted: disc at ({x:g}, {y:g}) needs a positive radius, got {r:g}")


@dataclass
class Scenario:
    """A concrete scenario instance: what the planners and the online process consume."""

    name: str
    description: str
    occ: np.ndarray                 # bool [rows, cols], True = obstacle (map frame)
    resolution: float               # m / cell
    start: tuple[float, float]      # m, map frame
    start_heading: float            # rad, map frame
    goal: tuple[float, float]
    route: np.ndarray | RouteRequest  # the reference path (M, 2) m, or what to plan it from (hil.routing)
    current: CurrentParams          # NED
    field_time: float               # s, instant of the frozen planning field
    planner_overrides: dict[str, object]
    online_overrides: dict[str, object]
    uncharted: tuple[tuple[float, float, float], ...] = ()   # discs (x, y, radius), m, map frame
    traffic: tuple[ShipSpec, ...] = ()                        # ships sailed by the simulator ([[traffic]])
    waypoints: np.ndarray | None = None                       # (K, 2) the route as given, m (None: = reference_path)
    geodesy: GeodesyParams | None = None                      # the NED origin
    _current_source: CurrentSource | None = field(default=None, init=False, repr=False, compare=False)

    @property
    def reference_path(self) -> np.ndarray:
        """The global reference path (M, 2), m, map frame. A fixed scenario's route is planned here,
        once, the first time it is asked for (:func:`hil.routing.plan_route`; ConfigError naming a
        waypoint it cannot reach), never while the scenario is loaded."""
        if isinstance(self.route, RouteRequest):
            self.route = plan_route(self.route)
        return self.route

    def take_planned_route(self, route: PlannedRoute, source: str) -> None:
        """Follow ``route``, planned by another process from this scenario's own request (`hil run`'s
        route.json): nothing plans it again. UsageError (one line) where it was planned from another."""
        if not isinstance(self.route, RouteRequest):
            raise UsageError(f"{source}: scenario {self.name} gives its route as is (global_route = false): "
                             f"there is no route to take")
        self.route = take_route(self.route, route, source)

    def truth_occ(self) -> np.ndarray:
        """The simulated world's obstacles: the chart (``occ``) plus the uncharted discs."""
        if not self.uncharted:
            return self.occ
        rows, cols = self.occ.shape
        y, x = (np.mgrid[0:rows, 0:cols] + 0.5) * self.resolution
        occ = self.occ.copy()
        for cx, cy, r in self.uncharted:
            occ |= (x - cx) ** 2 + (y - cy) ** 2 <= r * r
        return occ

    @property
    def width(self) -> float:
        return self.occ.shape[1] * self.resolution

    @property
    def height(self) -> float:
        return self.occ.shape[0] * self.resolution

    def current_field(self) -> CurrentSource | None:
        """The current the simulator applies (``common.current_sources``: eq. (13), uniform or a
        file's; NED), or None when disabled. Built once per scenario (a file is read once)."""
        if not self.current.enabled:
            return None
        if self._current_source is None:
            from common.current_sources import make_current
            self._current_source = make_current(self.current, geodesy_frame(self.geodesy))
        return self._current_source

    def check_current_time(self, duration: float, source: str = "") -> None:
        """ConfigError (one line) when a current file does not cover run times 0..``duration`` s."""
        from common.current_sources import CurrentSourceError, GriddedCurrent

        f = self.current_field()
        if isinstance(f, GriddedCurrent):
            try:
                f.check_covers(t=(0.0, max(float(duration), self.field_time)))
            except CurrentSourceError as exc:
                raise ConfigError(f"{source or 'scenario ' + self.name}: current.file: {exc}") from None

    def map_field(self) -> MapFrameCurrent | None:
        """The current frozen at ``field_time`` as a map-frame DisturbanceField, or None."""
        f = self.current_field()
        return None if f is None else MapFrameCurrent(f, self.field_time)

    def planning_field(self, resolution: float = 1.0) -> GridField | None:
        """The frozen map-frame current sampled on a grid (``planner.field.GridField``), or None."""
        f = self.map_field()
        if f is None:
            return None
        from planner.field import GridField
        return GridField.sample(f, self.width, self.height, resolution)


class MapFrameCurrent:
    """A NED current seen in the map frame at a fixed time: (x east, y north) -> (v_east, v_north)."""

    def __init__(self, ned_field: CurrentSource, t: float) -> None:
        self.ned_field, self.t = ned_field, float(t)

    def __call__(self, x: npt.ArrayLike, y: npt.ArrayLike) -> tuple[np.ndarray | float, np.ndarray | float]:
        v_north, v_east = self.ned_field.velocity(y, x, self.t)   # NED x = north = map y
        if np.ndim(x) == 0 and np.ndim(y) == 0:
            return float(v_east), float(v_north)
        return v_east, v_north


def scenario_path(name: str) -> Path:
    """``configs/scenarios/NAME.toml`` (a path to a .toml file is accepted too)."""
    p = Path(name)
    if p.suffix == ".toml":
        return p
    return SCENARIO_DIR / f"{name}.toml"


def load_spec(name: str) -> ScenarioSpec:
    """Parse and validate a scenario file (ConfigError with one line on any problem)."""
    path = scenario_path(name)
    if not path.exists():
        raise UsageError(f"unknown scenario {name!r} (no {path}; available: {', '.join(available())})")
    table = config.read_toml(path)
    if table.get("kind") == "fixed":
        for key in ("start", "goal"):   # defaults only for random scenarios, which draw them
            if key not in table:
                raise ConfigError(f"{path}: {key}: missing key (a fixed scenario gives [x, y] in m, or "
                                  f"[latitude, longitude] with positions = \"latlon\")")
    spec = config.from_table(ScenarioSpec, table, str(path))
    object.__setattr__(spec, "path", str(path))
    return spec


def folder_name(spec: ScenarioSpec) -> str:
    """The scenario's ``name`` made safe as a file name (run folders are named after it)."""
    import re

    return re.sub(r"[^A-Za-z0-9_.-]+", "-", spec.name).strip("-.") or "scenario"


def resolve_file(spec: ScenarioSpec, name: str) -> Path:
    """A file named in a scenario: relative to the scenario file; for scenarios written before
    that rule (paths relative to ``configs/``), ``configs/`` when the first does not exist."""
    p = Path(name).expanduser()
    if p.is_absolute():
        return p
    here = (Path(spec.path).parent if spec.path else SCENARIO_DIR) / p
    legacy = CONFIG_DIR / p
    return here if here.exists() or not legacy.exists() else legacy


def geodesy_frame(geodesy: GeodesyParams | None = None) -> LocalFrame:
    """The ``common.geodesy.LocalFrame`` of a ``[geodesy]`` section (default: the default configuration's)."""
    from common.geodesy import LocalFrame

    if geodesy is None:
        from hil import settings
        geodesy = settings.load().geodesy
    return LocalFrame(geodesy.lat0, geodesy.lon0, geodesy.alt0)


def positions_frame(spec: ScenarioSpec, geodesy: GeodesyParams | None = None) -> LocalFrame:
    """The ``LocalFrame`` in which a chart scenario's positions in metres count: its ``origin``, else the
    configuration's (``geodesy.positions_origin`` or ``lat0/lon0``; default: the default configuration's)."""
    from common.geodesy import LocalFrame

    if geodesy is None:
        from hil import settings
        geodesy = settings.load().geodesy
    lat, lon = (spec.origin[0], spec.origin[1]) if spec.origin else geodesy.metres_origin()
    return LocalFrame(lat, lon, geodesy.alt0)


def map_frame(spec: ScenarioSpec, geodesy: GeodesyParams | None = None) -> LocalFrame:
    """The ``LocalFrame`` of the scenario's map (x = 0, y = 0 at its south-west corner): a chart's
    grid corner, else the configuration's origin (``geodesy``, default: the default configuration's)."""
    from common.geodesy import LocalFrame

    if spec.kind == "fixed" and charts.is_chart(spec.map):
        positions = positions_frame(spec, geodesy)
        lat0, lon0 = charts.grid_corner(resolve_file(spec, spec.map), positions, spec.extent)
        return LocalFrame(lat0, lon0, positions.alt0)
    return geodesy_frame(geodesy)


MAX_LATLON_DISTANCE = 50_000.0   # m from the map's origin: a position farther is a typing mistake
CURRENT_MARGIN = 2_000.0         # m beyond the map's far corner that a current file is read


def positions_in_metres(spec: ScenarioSpec, frame: LocalFrame, source: str,
                        given_in: LocalFrame | None = None) -> ScenarioSpec:
    """``spec`` with every position (start, goal, route, uncharted centres, traffic) in map metres of
    ``frame`` (x east, y north): from ``[latitude, longitude]`` (``positions = "latlon"``), or from metres
    of another frame ``given_in`` (a chart's grid starts elsewhere than the positions' origin)."""
    def xy(what: str, p: tuple[float, ...]) -> tuple[float, float]:
        if given_in is not None:
            lat, lon = given_in.sea_level_to_geodetic(float(p[1]), float(p[0]))
        else:
            lat, lon = float(p[0]), float(p[1])
            if not (-89.0 <= lat <= 89.0 and -180.0 <= lon <= 360.0):
                raise ConfigError(f"{source}: {what}: [{lat:g}, {lon:g}] is not [latitude, longitude] in degrees")
        n, e = frame.geodetic_to_sea_level(lat, lon)
        if math.hypot(n, e) > MAX_LATLON_DISTANCE:
            raise ConfigError(f"{source}: {what}: [{lat:g}, {lon:g}] is {math.hypot(n, e) / 1000:.0f} km from the "
                              f"map's origin ({frame.lat0:.6f}, {frame.lon0:.6f}); [latitude, longitude] swapped?")
        return e, n

    ships = tuple(dataclasses.replace(
        ship, start=xy(f"traffic[{i}].start", ship.start),
        waypoints=tuple(xy(f"traffic[{i}].waypoints[{j}]", w) for j, w in enumerate(ship.waypoints)))
        for i, ship in enumerate(spec.traffic))
    out = dataclasses.replace(
        spec, positions="metres", start=xy("start", spec.start), goal=xy("goal", spec.goal),
        reference_path=tuple(xy(f"reference_path[{i}]", p) for i, p in enumerate(spec.reference_path)),
        uncharted=tuple((*xy(f"uncharted[{i}]", d[:2]), d[2]) for i, d in enumerate(spec.uncharted)),
        traffic=ships)
    object.__setattr__(out, "path", spec.path)
    return out


def _current_file(spec: ScenarioSpec, current: CurrentParams) -> CurrentParams:
    """``current`` with its file as an absolute path: relative to the scenario file when the
    scenario names it, else to the working directory (a configuration's or --set's)."""
    if not current.file:
        return current
    path = resolve_file(spec, current.file) if "file" in spec.current else Path(current.file).expanduser()
    return dataclasses.replace(current, file=str(path.resolve()))


def _check_current(scen: Scenario, source: str) -> None:
    """Build the scenario's current once (a file is read here) and refuse one that does not cover
    the map or the planning instant: one-line ConfigError."""
    from common.current_sources import CurrentSourceError, GriddedCurrent

    try:
        f = scen.current_field()
        if isinstance(f, GriddedCurrent):
            f.check_covers((0.0, scen.height), (0.0, scen.width), (scen.field_time, scen.field_time),
                           what=f"the {scen.width:g} m x {scen.height:g} m map")
    except CurrentSourceError as exc:
        raise ConfigError(f"{source}: current: {exc}") from None


def _current_params(base_current: CurrentParams, overrides: dict[str, object],
                    source: str) -> tuple[CurrentParams, float]:
    table = config.to_table(base_current)
    ov = dict(overrides)
    field_time = ov.pop("field_time", 0.0)
    if isinstance(field_time, bool) or not isinstance(field_time, (int, float)):
        raise ConfigError(f"{source}: current.field_time: expected a number, got {field_time!r}")
    if not 0.0 <= field_time <= config.MAX_MAGNITUDE:
        raise ConfigError(f"{source}: current.field_time: must be a finite number of seconds >= 0 (got {field_time})")
    # The scenario's source replaces the configuration's: its file drops a configured uniform current
    # and the other way round (both at once is refused).
    if "file" in ov and "uniform" in table:
        table["uniform"] = []
    if "uniform" in ov and "file" in table:
        table["file"] = ""
    for k, v in ov.items():
        if k not in table:
            raise ConfigError(f"{source}: current.{k}: unknown key{config.suggest(k, list(table) + ['field_time'])}")
        table[k] = v
    return config.from_table(type(base_current), table, source, prefix="current"), float(field_time)


def load_occupancy(path: Path, resolution: float) -> np.ndarray:
    """A map file's obstacle array, bool [rows, cols], via the planner's loader (MapError -> UsageError)."""
    from planner.gridmap import MapError, OccupancyGrid
    if Path(path).suffix.lower() == ".npy" and Path(path).is_file():
        from hil.maps import check_npy_header

        try:
            check_npy_header(Path(path))
        except (ValueError, OSError) as exc:
            raise UsageError(f"{path}: {exc}") from None
    try:
        return OccupancyGrid.load(path, resolution).occ
    except MapError as exc:
        raise UsageError(str(exc)) from None


def _check_point(what: str, p: tuple[float, float], occ: np.ndarray, res: float, source: str) -> None:
    h, w = occ.shape[0] * res, occ.shape[1] * res
    if not (0 <= p[0] < w and 0 <= p[1] < h):
        raise ConfigError(f"{source}: {what}: ({p[0]:g}, {p[1]:g}) m is outside the {w:g} m x {h:g} m map")
    if occ[int(p[1] / res), int(p[0] / res)]:
        raise ConfigError(f"{source}: {what}: ({p[0]:g}, {p[1]:g}) m is inside an obstacle")


def load(name: str, base_current: CurrentParams | None = None, safety_radius: float | None = None,
         geodesy: GeodesyParams | None = None) -> Scenario:
    """Load a fixed scenario (for a random one, use :func:`instance` with a run's generator).
    ``safety_radius`` (m): the configuration's ``planner.safety_radius`` (default: the default
    configuration's); the scenario's own ``[planner]`` value wins, as for the planner.
    ``geodesy``: the configuration's ``[geodesy]`` (default: the default configuration's)."""
    spec = load_spec(name)
    return instance(spec, None, base_current, safety_radius, geodesy=geodesy)


def _safety_radius(spec: ScenarioSpec, base: float | None, source: str) -> float:
    value = spec.planner.get("safety_radius", base)
    if value is None:
        from hil import settings
        value = settings.load().planner.safety_radius
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not value >= 0:
        raise ConfigError(f"{source}: planner.safety_radius: expected a number >= 0, got {value!r}")
    return float(value)


def _default_current() -> CurrentParams:
    from hil import settings
    return settings.load().current


def instance(spec: ScenarioSpec, rng: np.random.Generator | None, base_current: CurrentParams | None = None,
             safety_radius: float | None = None, source: str | None = None,
             geodesy: GeodesyParams | None = None) -> Scenario:
    """A concrete :class:`Scenario`; random scenarios draw map and end points from ``rng``.
    ``source`` names the file in error messages (default: the file the spec was read from)."""
    source = source or spec.path or str(scenario_path(spec.name))
    positions = None
    if spec.kind == "fixed" and charts.is_chart(spec.map):
        positions = positions_frame(spec, geodesy)
        frame = map_frame(spec, geodesy)
        if spec.positions == "latlon":
            spec = positions_in_metres(spec, frame, source)
        elif (frame.lat0, frame.lon0) != (positions.lat0, positions.lon0):
            spec = positions_in_metres(spec, frame, source, given_in=positions)
    elif spec.positions == "latlon":
        spec = positions_in_metres(spec, map_frame(spec, geodesy), source)
    scen = _instance(spec, rng, base_current, safety_radius, source, positions)
    if scen.geodesy is None:        # a chart sets its own origin (its map's south-west corner)
        scen.geodesy = geodesy
    if scen.current.file and scen.current.reach == 0.0:
        # Read only the file's part around the map (its corners from the NED origin at its corner, and
        # 2 km for a file's coarse cells): a regional or global file costs what the run's area does.
        reach = math.ceil((math.hypot(scen.width, scen.height) + CURRENT_MARGIN) / 1000.0) * 1000.0
        scen.current = dataclasses.replace(scen.current, reach=reach)
    _check_current(scen, source)
    return scen


def _instance(spec: ScenarioSpec, rng: np.random.Generator | None, base_current: CurrentParams | None,
              safety_radius: float | None, source: str, positions: LocalFrame | None = None) -> Scenario:
    current, field_time = _current_params(base_current if base_current is not None else _default_current(),
                                          spec.current, source)
    current = _current_file(spec, current)
    if spec.kind == "fixed":
        map_path = resolve_file(spec, spec.map)
        if not map_path.exists():
            raise ConfigError(f"{source}: map: no such file {map_path}")
        geodesy = None
        if charts.is_chart(map_path):
            assert positions is not None      # instance() gives a chart scenario its frame
            grid = charts.rasterise(map_path, spec.resolution, positions, spec.extent, spec.chart_buffer)
            occ = grid.occ
            geodesy = GeodesyParams(grid.origin[0], grid.origin[1], positions.alt0,
                                    (positions.lat0, positions.lon0))
        else:
            occ = load_occupancy(map_path, spec.resolution)
        for what, p in (("start", spec.start), ("goal", spec.goal)):
            _check_point(what, p, occ, spec.resolution, source)
        if spec.global_route:
            wps = route_waypoints(spec.start, spec.goal, spec.reference_path)
            given = len(spec.reference_path) > 0 and math.dist(spec.reference_path[0], spec.start) < 1e-9
            names = ["start"] + [f"reference_path[{i if given else i - 1}]" for i in range(1, len(wps) - 1)] + ["goal"]
            route: np.ndarray | RouteRequest = RouteRequest(
                occ, spec.resolution, wps, _safety_radius(spec, safety_radius, source), spec.route_spacing,
                source, tuple(names))
        else:
            if len(spec.reference_path) < 2:
                raise ConfigError(f"{source}: reference_path: global_route = false needs the path itself (>= 2 points)")
            wps = route = np.asarray(spec.reference_path, dtype=float)
        scen = Scenario(spec.name, spec.description, occ, spec.resolution, spec.start, spec.start_heading,
                        spec.goal, route, current, field_time, dict(spec.planner), dict(spec.online),
                        tuple((float(x), float(y), float(r)) for x, y, r in spec.uncharted), traffic=spec.traffic,
                        waypoints=wps, geodesy=geodesy)
        truth = scen.truth_occ()
        for what, p in (("start", spec.start), ("goal", spec.goal)):
            if truth[int(p[1] / spec.resolution), int(p[0] / spec.resolution)]:
                raise ConfigError(f"{source}: uncharted: an obstacle covers the {what}")
        return scen
    if rng is None:
        raise UsageError(f"scenario {spec.name!r} is random: it needs a run seed (use hil montecarlo)")
    return _random_instance(spec, rng, current, field_time, _safety_radius(spec, safety_radius, source), source)


def _random_instance(spec: ScenarioSpec, rng: np.random.Generator, current: CurrentParams, field_time: float,
                     safety_radius: float = 2.0, source: str = "random scenario") -> Scenario:
    from hil.maps import Canvas, random_map
    r = spec.random
    assert r is not None
    occ = random_map(rng, r.width, r.height, r.discs, r.rects, r.radius, r.resolution)
    for _ in range(1000):
        start = rng.uniform([r.margin, r.margin], [r.width - r.margin, r.height - r.margin])
        goal = rng.uniform([r.margin, r.margin], [r.width - r.margin, r.height - r.margin])
        if math.hypot(*(goal - start)) >= r.min_distance:
            break
    canvas = Canvas(r.width, r.height, r.resolution)
    canvas.occ = occ
    canvas.clear_disc(start[0], start[1], r.clearance)
    canvas.clear_disc(goal[0], goal[1], r.clearance)
    if r.waypoints[1] == 0 and r.global_route:
        routed = _routed_instance(spec, canvas, start, goal, current, field_time, safety_radius)
        if routed is not None:
            return routed
    if r.waypoints[1] == 0:
        n = max(int(math.ceil(math.hypot(*(goal - start)) / r.reference_spacing)), 1)
        ref = start + (goal - start) * np.linspace(0.0, 1.0, n + 1)[:, None]
        heading = math.atan2(goal[1] - start[1], goal[0] - start[0])
        return Scenario(spec.name, spec.description, canvas.occ, r.resolution, (float(start[0]), float(start[1])),
                        heading, (float(goal[0]), float(goal[1])), ref, current, field_time,
                        dict(spec.planner), dict(spec.online), traffic=spec.traffic)
    return _random_route(spec, rng, canvas, start, goal, current, field_time, safety_radius, source)


def _routed_instance(spec: ScenarioSpec, canvas: Canvas, start: np.ndarray, goal: np.ndarray, current: CurrentParams,
                     field_time: float, safety_radius: float) -> Scenario | None:
    """A random scenario whose reference path is the global route from start to goal (no draw of
    its own: the map and end points are those of the straight-line scenario); None where no
    route exists (the goal walled in on the inflated chart): the straight line is used then."""
    from planner.global_route import plan_chart_route
    from planner.gridmap import OccupancyGrid

    r = spec.random
    assert r is not None
    wps = np.array([start, goal], dtype=float)
    route = plan_chart_route(OccupancyGrid(canvas.occ, r.resolution), wps, safety_radius, spec.route_spacing)
    if not route.ok:
        return None
    first = route.path[1] - route.path[0]
    return Scenario(spec.name, spec.description, canvas.occ, r.resolution, (float(start[0]), float(start[1])),
                    math.atan2(first[1], first[0]), (float(goal[0]), float(goal[1])), route.path, current,
                    field_time, dict(spec.planner), dict(spec.online), traffic=spec.traffic, waypoints=wps)


def _random_route(spec: ScenarioSpec, rng: np.random.Generator, canvas: Canvas, start: np.ndarray,
                  goal: np.ndarray, current: CurrentParams, field_time: float, safety_radius: float,
                  source: str) -> Scenario:
    """A random scenario with intermediate waypoints: each drawn in the usable area at least
    ``min_leg`` from the previous one (the goal too), cleared like start and goal, and the route
    through them planned; a draw whose route fails (a waypoint walled in) is drawn again."""
    from planner.global_route import plan_chart_route
    from planner.gridmap import OccupancyGrid

    r = spec.random
    assert r is not None
    lo, hi = [r.margin, r.margin], [r.width - r.margin, r.height - r.margin]
    k = int(rng.integers(r.waypoints[0], r.waypoints[1] + 1))
    base = canvas.occ.copy()
    for _ in range(200):
        pts = [start]
        for _j in range(k):
            for _t in range(1000):
                p = rng.uniform(lo, hi)
                if math.dist(p, pts[-1]) >= r.min_leg:
                    break
            pts.append(p)
        if math.dist(pts[-1], goal) < r.min_leg:
            continue
        pts.append(goal)
        canvas.occ = base.copy()
        for p in pts[1:-1]:
            canvas.clear_disc(p[0], p[1], r.clearance)
        wps = np.array(pts)
        route = plan_chart_route(OccupancyGrid(canvas.occ, r.resolution), wps, safety_radius, spec.route_spacing)
        if route.ok:
            first = route.path[1] - route.path[0]
            return Scenario(spec.name, spec.description, canvas.occ, r.resolution,
                            (float(start[0]), float(start[1])), math.atan2(first[1], first[0]),
                            (float(goal[0]), float(goal[1])), route.path, current, field_time,
                            dict(spec.planner), dict(spec.online), traffic=spec.traffic, waypoints=wps)
    raise ConfigError(f"{source}: random: no route with {k} waypoint(s) found in 200 draws")


def planner_params(base: PlannerParams, overrides: dict[str, object], source: str = "scenario") -> PlannerParams:
    """``base`` PlannerParams with ``overrides`` applied and validated (ConfigError on problems)."""
    table = config.to_table(base)
    for k, v in overrides.items():
        if k not in table:
            raise ConfigError(f"{source}: planner.{k}: unknown key")
        table[k] = v
    return config.from_table(type(base), table, source, prefix="planner")


def online_params(overrides: dict[str, object], source: str = "scenario",
                  base: OnlineParams | None = None) -> OnlineParams:
    """OnlineParams (defaults or ``base``) with ``overrides`` applied and validated."""
    from planner.online import OnlineParams
    table = config.to_table(base if base is not None else OnlineParams())
    for k, v in overrides.items():
        if k not in table:
            raise ConfigError(f"{source}: online.{k}: unknown key (expected one of: {', '.join(table)})")
        table[k] = v
    return config.from_table(OnlineParams, table, source, prefix="online")


def base_planner_params(settings_obj: HilConfig | None) -> PlannerParams:
    """The ``[planner]`` section of the loaded configuration, or the library defaults."""
    from planner.params import PlannerParams
    return getattr(settings_obj, "planner", None) or PlannerParams()


def with_overrides(obj: D, **kw: object) -> D:
    """``dataclasses.replace`` that ignores ``None`` values (CLI options not given)."""
    return dataclasses.replace(obj, **{k: v for k, v in kw.items() if v is not None})


def load_traffic(source: str) -> tuple[ShipSpec, ...]:
    """Ships from a JSON file (a list of ``[[traffic]]`` tables, as ``hil run`` writes) or from a
    scenario's ``[[traffic]]`` (a name or a .toml path); one-line errors."""
    import json

    p = Path(source)
    if p.suffix == ".json":
        try:
            rows = json.loads(p.read_text())
        except (OSError, json.JSONDecodeError) as exc:
            raise UsageError(f"--traffic {source}: cannot read ships: {exc}") from None
        if not isinstance(rows, list):
            raise UsageError(f"--traffic {source}: expected a JSON list of ship tables")
        return tuple(config.from_table(ShipSpec, r, source, prefix=f"traffic[{i}]") for i, r in enumerate(rows))
    return load_spec(source).traffic


def simulator_overrides(scen: Scenario, base_current: CurrentParams | None) -> list[str]:
    """The ``--set`` overrides that put the simulator where `hil run` starts it on ``scen``: the
    start (map x east, y north, heading counter-clockwise from east) as NED ``sim.initial`` and the
    scenario's own ``[current]`` keys."""
    import json

    from common.frames import map_to_ned

    north, east, psi = map_to_ned(scen.start[0], scen.start[1], scen.start_heading)
    out = [f"sim.initial.x={north!r}", f"sim.initial.y={east!r}", f"sim.initial.psi={psi!r}"]
    base, mine = config.to_table(base_current), config.to_table(scen.current)
    out += [f"current.{k}={json.dumps(v)}" for k, v in mine.items() if base.get(k) != v]
    return out
