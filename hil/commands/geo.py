"""`hil geo`: a scenario's positions between map metres and latitude/longitude, and its route as a
QGroundControl mission (.plan)."""

from __future__ import annotations

import argparse
import json
import math
from collections.abc import Callable
from pathlib import Path

from hil.console import emit, load_settings
from hil.errors import UsageError
from hil.files import check_output_file


def _pair(what: str) -> Callable[[str], tuple[float, float]]:
    def parse(text: str) -> tuple[float, float]:
        parts = text.split(",")
        try:
            if len(parts) != 2:
                raise ValueError
            a, b = float(parts[0]), float(parts[1])
        except ValueError:
            raise argparse.ArgumentTypeError(f"expected {what}, got {text!r}") from None
        if not (math.isfinite(a) and math.isfinite(b)):
            raise argparse.ArgumentTypeError(f"expected finite {what}, got {text!r}")
        return a, b
    return parse


def add_parser(sub: argparse._SubParsersAction, parents: list[argparse.ArgumentParser]) -> None:
    p = sub.add_parser(
        "geo", parents=parents,
        help="convert a scenario's positions between metres and latitude/longitude; write its route as a .plan",
        description="Positions of a scenario's map frame (x east, y north, metres from the map's south-west "
                    "corner) in WGS-84 latitude/longitude and back, on the origin a run of the scenario uses "
                    "(a chart's corner, else the configuration's [geodesy]). With no conversion asked, prints "
                    "the origin and the scenario's start, goal and route both ways.",
    )
    p.add_argument("--scenario", metavar="NAME", default="harbour",
                   help="NAME of configs/scenarios/NAME.toml, or a path to a scenario .toml (default: harbour)")
    p.add_argument("--to-latlon", metavar="X,Y", type=_pair("X,Y in metres (e.g. 22,40)"), action="append",
                   default=[], help="map metres to latitude,longitude; repeatable")
    p.add_argument("--to-metres", metavar="LAT,LON", type=_pair("LAT,LON in degrees (e.g. 38.9204,121.6503)"),
                   action="append", default=[], help="latitude,longitude to map metres; repeatable")
    p.add_argument("--plan", metavar="FILE.plan",
                   help="write the scenario's route (the global reference path, start to goal) as a "
                        "QGroundControl mission file")
    p.set_defaults(func=run)


def plan_document(points: list[tuple[float, float]], home: tuple[float, float], speed: float) -> dict[str, object]:
    """A QGroundControl .plan (JSON, mission version 2) of NAV_WAYPOINT items at ``points`` (lat, lon deg),
    at sea level (altitude 0 m relative to home), for a surface boat."""
    items = [{"type": "SimpleItem", "autoContinue": True, "command": 16, "doJumpId": i + 1, "frame": 3,
              "params": [0, 0, 0, None, lat, lon, 0], "Altitude": 0, "AltitudeMode": 1,
              "AMSLAltAboveTerrain": None}
             for i, (lat, lon) in enumerate(points)]
    return {"fileType": "Plan", "version": 1, "groundStation": "QGroundControl",
            "mission": {"version": 2, "firmwareType": 0, "vehicleType": 11, "cruiseSpeed": speed,
                        "hoverSpeed": speed, "globalPlanAltitudeMode": 1,
                        "plannedHomePosition": [home[0], home[1], 0], "items": items},
            "geoFence": {"version": 2, "circles": [], "polygons": []},
            "rallyPoints": {"version": 2, "points": []}}


def run(args: argparse.Namespace) -> int:
    from hil import scenario as scenarios

    cfg = load_settings(args)
    spec = scenarios.load_spec(args.scenario)
    if spec.kind != "fixed":
        raise UsageError(f"--scenario {args.scenario}: draws a new map per run; hil geo needs a fixed scenario")
    out = None
    if args.plan:
        out = check_output_file(args.plan, "--plan", (".plan",))
    scen = scenarios.load(args.scenario, cfg.current, cfg.planner.safety_radius, cfg.geodesy)
    frame = scenarios.geodesy_frame(scen.geodesy)

    def latlon(x: float, y: float) -> tuple[float, float]:
        return frame.sea_level_to_geodetic(y, x)

    def metres(lat: float, lon: float) -> tuple[float, float]:
        if not (-89 <= lat <= 89 and -180 <= lon <= 360):
            raise UsageError(f"--to-metres {lat:g},{lon:g}: not a latitude,longitude in degrees")
        n, e = frame.geodetic_to_sea_level(lat, lon)
        return e, n

    result: dict[str, object] = {"origin": [frame.lat0, frame.lon0]}
    lines = [f"origin (map x = 0, y = 0): {frame.lat0:.7f}, {frame.lon0:.7f}"]
    given = getattr(scen.geodesy, "positions_origin", ())
    if given and tuple(given) != (frame.lat0, frame.lon0):
        # a chart's grid starts elsewhere than the origin its positions in metres count from
        e, n = frame.geodetic_to_sea_level(given[0], given[1])[::-1]
        result["positions_origin"] = [given[0], given[1], e, n]
        lines.append(f"the scenario's positions in metres count from {given[0]:.7f}, {given[1]:.7f} "
                     f"(map {e:.2f}, {n:.2f} m); the map metres here are the run's")
    if args.to_latlon or args.to_metres:
        to_latlon = [[x, y, *latlon(x, y)] for x, y in args.to_latlon]
        to_metres = [[lat, lon, *metres(lat, lon)] for lat, lon in args.to_metres]
        result["to_latlon"], result["to_metres"] = to_latlon, to_metres
        lines += [f"{x:g}, {y:g} m -> {la:.7f}, {lo:.7f}" for x, y, la, lo in to_latlon]
        lines += [f"{la:.7f}, {lo:.7f} -> {x:.2f}, {y:.2f} m" for la, lo, x, y in to_metres]
    else:
        for name, p in (("start", scen.start), ("goal", scen.goal)):
            row = [p[0], p[1], *latlon(p[0], p[1])]
            result[name] = row
            lines.append(f"{name}: {p[0]:g}, {p[1]:g} m = {row[2]:.7f}, {row[3]:.7f}")
        given = scen.waypoints if scen.waypoints is not None else scen.reference_path
        waypoints = [[float(x), float(y), *latlon(float(x), float(y))] for x, y in given]
        result["waypoints"] = waypoints
        lines.append("waypoints (as given): " + "; ".join(f"{la:.7f}, {lo:.7f}" for _x, _y, la, lo in waypoints))
    if out is not None:
        route = [latlon(float(x), float(y)) for x, y in scen.reference_path]
        doc = plan_document(route, latlon(*scen.start), float(cfg.planner.speed))
        try:
            Path(out).write_text(json.dumps(doc, indent=2) + "\n")
        except OSError as exc:
            raise UsageError(f"--plan {out}: cannot write ({exc.strerror})") from None
        result["plan"] = str(out)
        lines.append(f"wrote {out}: {len(route)} waypoints (the global route, start to goal)")
    emit(args, result, lines)
    return 0
