"""`hil bench ardupilot`: ArduRover against the project's vessel computer, on the same boat, sea and missions.

Each mission is flown twice in one run, in lockstep with the same seed: by the vessel computer
(`hil run`) and by ArduPilot's ArduRover SITL (`hil run --autopilot ardupilot`), which follows the same
global route as an ArduPilot mission. Both are judged from the simulator's truth alike: mission time
(simulated s to the goal; ArduRover's boat is moored at its start while ArduRover boots, aligns and
takes its mission, and its time counts from AUTO, the set-up reported apart), the truth's
cross-track distance from the global route (RMS and largest, m), the minimum clearance from the chart
(m), energy (J, eq. of `hil run`), collisions. Ratios are ArduRover / vessel computer.

A fence row ("NAME (fence)") flies the scenario's route as given, which crosses the chart (the
harbour's crosses pier 1, the breakwater and the outer mole), with the chart uploaded as ArduRover's
exclusion fence and its Dijkstra planner on (`hil run --autopilot ardupilot --ardupilot-fence`),
against the vessel computer with its global route (the same flight as the scenario's own row).
"""

from __future__ import annotations

import argparse
import math
import subprocess
import tempfile
from pathlib import Path
from typing import TYPE_CHECKING

from common.tables import JsonTable
from hil.console import emit, load_settings, progress
from hil.errors import UsageError

if TYPE_CHECKING:
    import numpy as np

    from common.geodesy import LocalFrame
    from hil.ardupilot import SitlFiles
    from hil.run_summary import RunSummary
    from hil.settings import HilConfig

ENCOUNTERS = ("colregs-head-on", "colregs-crossing-right", "colregs-crossing-left", "colregs-overtaking")
METRICS = ("mission_time_s", "time_under_way_s", "cross_track_rms_m", "cross_track_max_m", "min_clearance_m",
           "energy_J", "path_length_m", "collisions")


def add_parser(sub: argparse._SubParsersAction, parents: list[argparse.ArgumentParser]) -> None:
    p = sub.add_parser(
        "ardupilot", parents=parents,
        help="ArduRover SITL against the vessel computer on the same missions (ratios from one run)",
        description="Flies each scenario twice in lockstep with the same seed: with the project's vessel "
                    "computer and with ArduPilot's ArduRover SITL (the simulator as its JSON physics, the "
                    "scenario's global route as its mission), and prints, per scenario, mission time, time under "
                    "way (from the start of motion), cross-track distance from the global route (RMS, max), "
                    "minimum clearance, energy, path length and collisions for both, with the ratio ArduRover / "
                    "vessel computer (docs/ardupilot.md). A fence row flies the scenario's route as given, "
                    "which crosses the chart, with the chart as ArduRover's exclusion fence and its Dijkstra "
                    "path planner on, against the vessel computer's global route.",
    )
    p.add_argument("--scenarios", nargs="*", default=["harbour", *ENCOUNTERS], metavar="NAME",
                   help="fixed scenarios to fly (default: harbour and the four COLREGs encounters, "
                        f"{', '.join(ENCOUNTERS)})")
    p.add_argument("--fence-scenarios", nargs="*", default=["harbour"], metavar="NAME",
                   help="fixed scenarios whose route as given crosses the chart: ArduRover flies that route with "
                        "the chart as its exclusion fence (Dijkstra, OA_TYPE 2), the vessel computer its global "
                        "route (default: harbour; none: no fence row)")
    p.add_argument("--duration", type=float, default=300.0, metavar="S",
                   help="simulated seconds at most per flight (default: 300)")
    p.add_argument("--seed", type=int, default=1, help="seed of both flights (default: 1)")
    p.add_argument("--station-duration", type=float, default=200.0, metavar="S",
                   help="station keeping: simulated seconds of each flight to --station-goal and holding there "
                        "(ArduRover: LOITER after its mission, MIS_DONE_BEHAVE 1; ours: mission_done = loiter), "
                        "the harbour's route cut at that point; ArduRover's from AUTO (default: 200; 0 skips it)")
    p.add_argument("--station-goal", default="106,92", metavar="X,Y",
                   help="station keeping: the point held, map x east, y north in m, near the harbour's reference "
                        "path (default: 106,92: open water, 15 m from the chart, in the current's 0.5 m/s peak)")
    p.add_argument("--station-hold", type=float, default=60.0, metavar="S",
                   help="station keeping: judged over the last S simulated seconds of each flight (default: 60)")
    p.add_argument("--ardupilot-bin", metavar="PATH", default=None,
                   help="the ArduRover SITL binary (default: $ARDUPILOT_SITL)")
    p.add_argument("--out", metavar="DIR", default=None,
                   help="keep the run folders here (default: a temporary folder, removed)")
    p.set_defaults(func=run)


def truth_track(tlog: Path, geo: LocalFrame, until_s: float) -> np.ndarray:
    """The truth (north, east) in m from a run's .tlog, up to ``until_s`` of simulated time."""
    return timed_track(tlog, geo, until_s)[1]


def timed_track(tlog: Path, geo: LocalFrame, until_s: float) -> tuple[np.ndarray, np.ndarray]:
    """(times s, (north, east) m) of the truth in a run's .tlog, up to ``until_s`` of simulated time."""
    import numpy as np
    from pymavlink import mavutil

    times, pts = [], []
    m = mavutil.mavlink_connection(str(tlog))
    try:
        while (msg := m.recv_match(type="HIL_STATE_QUATERNION")) is not None:
            t = msg.time_usec * 1e-6
            if t > until_s + 1e-9:
                break
            times.append(t)
            pts.append(geo.geodetic_to_sea_level(msg.lat * 1e-7, msg.lon * 1e-7))
    finally:
        m.close()
    return np.array(times, dtype=float), np.array(pts, dtype=float).reshape(-1, 2)


def station_figures(summary: RunSummary, goal_ned: tuple[float, float], tolerance: float, geo: LocalFrame,
                    hold_s: float = 60.0) -> JsonTable:
    """Station keeping over the last ``hold_s`` simulated seconds of a run: RMS and largest distance
    (m) from ``goal_ned``, the share of that time within ``tolerance`` (m); and when the boat first came
    within ``tolerance`` (s, None: never)."""
    import numpy as np

    t, track = timed_track(Path(summary.tlog), geo, summary.sim_time_s)
    d = np.hypot(track[:, 0] - goal_ned[0], track[:, 1] - goal_ned[1]) if len(t) else np.zeros(0)
    inside = np.flatnonzero(d <= tolerance)
    out: JsonTable = {"outcome": summary.outcome, "collisions": summary.collisions,
                           "min_clearance_m": summary.min_clearance_m,
                           "arrived_s": round(float(t[inside[0]]), 2) if len(inside) else None}
    held = d[t >= t[-1] - hold_s] if len(t) else d
    if len(held) == 0:
        return {**out, "held_s": 0.0, "station_rms_m": None, "station_max_m": None, "within_tolerance": None}
    return {**out, "held_s": round(min(hold_s, float(t[-1] - t[0])), 2),
            "station_rms_m": round(float(np.sqrt(np.mean(held ** 2))), 3), "station_max_m": round(float(held.max()), 3),
            "within_tolerance": round(float(np.mean(held <= tolerance)), 3)}


def station_scenario(folder: Path, goal_xy: tuple[float, float]) -> Path:
    """The harbour scenario with its route cut at ``goal_xy`` (map x east, y north, m), written to ``folder``."""
    import tomllib

    from hil import scenario as scenarios

    src = scenarios.scenario_path("harbour")
    spec = tomllib.loads(src.read_text())
    path = [p for p in spec["reference_path"]]
    cut = min(range(len(path)), key=lambda i: math.dist(path[i], goal_xy))
    spec.update(name="harbour-station", goal=list(goal_xy), reference_path=path[:cut] + [list(goal_xy)],
                map=str((src.parent / spec["map"]).resolve()),
                description="the harbour's route cut at a point on the current's jet axis, held there")
    folder.mkdir(parents=True, exist_ok=True)
    out = folder / "harbour-station.toml"
    out.write_text(_toml(spec))
    return out


def _toml(table: JsonTable, prefix: str = "") -> str:
    import json

    flat = [f"{k} = {json.dumps(v)}" for k, v in table.items() if not isinstance(v, dict)]
    subs = [f"\n[{prefix}{k}]\n" + _toml(v, f"{prefix}{k}.") for k, v in table.items() if isinstance(v, dict)]
    return "\n".join(flat) + "\n" + "".join(subs)


def moving_from(tlog: Path, until_s: float, speed: float = 0.3) -> float | None:
    """Simulated time (s) the boat first went faster than ``speed`` (m/s) over ground."""
    from pymavlink import mavutil

    m = mavutil.mavlink_connection(str(tlog))
    try:
        while (msg := m.recv_match(type="HIL_STATE_QUATERNION")) is not None:
            t = msg.time_usec * 1e-6
            if t > until_s:
                return None
            if math.hypot(msg.vx, msg.vy) * 0.01 > speed:
                return t
    finally:
        m.close()
    return None


def flight_figures(summary: RunSummary, route_ned: np.ndarray, geo: LocalFrame) -> JsonTable:
    from autopilot_bridge.tracking_stats import TrackingSummary
    from hil.ardupilot import route_cross_track

    tlog = Path(summary.tlog)
    track = truth_track(tlog, geo, summary.sim_time_s)
    xte = route_cross_track(track, route_ned) or TrackingSummary(frames=0)
    start = moving_from(tlog, summary.sim_time_s)
    done = summary.reached_goal
    return {"outcome": summary.outcome, "reached_goal": done,
            "mission_time_s": summary.sim_time_s if done else None,
            "time_under_way_s": round(summary.sim_time_s - start, 2) if done and start is not None else None,
            "cross_track_rms_m": xte.get("cross_track_rms_m"), "cross_track_max_m": xte.get("cross_track_max_m"),
            "min_clearance_m": summary.min_clearance_m, "energy_J": summary.energy_J,
            "path_length_m": summary.path_length_m, "collisions": summary.collisions,
            "wall_time_s": summary.wall_time_s}


def ratio(a: float | None, b: float | None) -> float | None:
    if a is None or b is None or b == 0:
        return None
    return round(a / b, 3)


def commit() -> str | None:
    try:
        r = subprocess.run(["git", "rev-parse", "--short", "HEAD"], capture_output=True, text=True, timeout=10,
                           cwd=Path(__file__).resolve().parent)
    except (OSError, subprocess.TimeoutExpired):
        return None
    return r.stdout.strip() or None


def run(args: argparse.Namespace) -> int:
    import numpy as np

    from common.geodesy import LocalFrame
    from hil import scenario as scenarios
    from hil.ardupilot import find_sitl, run_ardupilot
    from hil.hilrun import RunOptions, run_loop

    if not 0 < args.duration < math.inf:
        raise UsageError("--duration: must be a finite number > 0 of seconds")
    sitl = find_sitl(args.ardupilot_bin)
    cfg = load_settings(args)
    for name in (*args.scenarios, *args.fence_scenarios):
        if scenarios.load_spec(name).kind != "fixed":
            raise UsageError(f"scenario {name!r} draws a new map per run; the bench needs fixed scenarios")
    geo = LocalFrame(cfg.geodesy.lat0, cfg.geodesy.lon0, cfg.geodesy.alt0)
    result: JsonTable = {"commit": commit(), "seed": args.seed, "duration_s": args.duration,
                              "ardupilot": str(sitl.binary), "scenarios": {}}
    lines = [f"ArduRover against the vessel computer, seed {args.seed}, lockstep, commit {result['commit']}",
             " ".join(f"{c:<15}" if i == 0 else f"{c:>8}" for i, c in enumerate(HEAD))]
    with tempfile.TemporaryDirectory(prefix="hil-bench-ardupilot-") as tmp:
        root = Path(args.out) if args.out else Path(tmp)
        flown: dict[str, JsonTable] = {}     # the vessel computer's figures per scenario, flown once
        rows = [(name, False) for name in args.scenarios] + [(name, True) for name in args.fence_scenarios]
        for name, fence in rows:
            scen = scenarios.load(name, cfg.current, cfg.planner.safety_radius)
            route = np.asarray(scen.reference_path, dtype=float)[:, ::-1]
            row = f"{name} (fence)" if fence else name

            def opts(who: str, name: str = name, folder: str = row.replace(" (fence)", "-fence")) -> RunOptions:
                return RunOptions(scenario=name, lockstep=True, duration=args.duration, seed=args.seed,
                                  config=args.config, overrides=list(args.overrides), out=root / folder / who,
                                  plot=False, on_progress=progress, cpus="off")

            if name not in flown:
                progress(f"bench ardupilot: {name}: the vessel computer")
                flown[name] = flight_figures(run_loop(opts("vessel-computer"), cfg), route, geo)
            ours = flown[name]
            progress(f"bench ardupilot: {row}: ArduRover")
            ap_summary = run_ardupilot(opts("ardurover"), cfg, sitl, fence=fence)
            if ap_summary.outcome == "interrupted":   # Ctrl-C ends the bench, not just this flight
                raise KeyboardInterrupt
            theirs = flight_figures(ap_summary, route, geo)
            ap = ap_summary.ardurover()
            # moored until AUTO: the mission counts from there
            theirs["setup_to_auto_s"] = None if ap is None else ap["auto_at_s"]
            theirs["collision_time_s"] = ap_summary.collision_time_s
            if fence:
                theirs["fence"] = None if ap is None else ap["fence"]
                theirs["mission_waypoints"] = None if ap is None else ap["mission_items"]
            if theirs["reached_goal"]:
                theirs["mission_time_s"] = None if ap is None else ap["mission_time_s"]
            ratios = {k: ratio(theirs[k], ours[k]) for k in METRICS if k != "collisions"}
            result["scenarios"][row] = {"ardurover": theirs, "vessel_computer": ours, "ratio": ratios}
            lines += [_row(row, "ArduRover", theirs), _row("", "ours", ours),
                      _row("", "ratio", {**ratios, "outcome": "", "collisions": None})]
        if args.station_duration > 0:
            result["station_keeping"] = _station(args, cfg, sitl, geo, root, lines)
    emit(args, result, lines)
    return 0


def _station(args: argparse.Namespace, cfg: HilConfig, sitl: SitlFiles, geo: LocalFrame, root: Path,
             lines: list[str]) -> dict:
    from hil.ardupilot import run_ardupilot
    from hil.hilrun import RunOptions, run_loop

    try:
        gx, gy = (float(v) for v in args.station_goal.split(","))
    except ValueError:
        raise UsageError("--station-goal: X,Y in metres") from None
    scen_file = station_scenario(root / "station", (gx, gy))

    def opts(who: str) -> RunOptions:
        return RunOptions(scenario=str(scen_file), lockstep=True, duration=args.station_duration, seed=args.seed,
                          config=args.config, overrides=list(args.overrides), out=root / "station" / who,
                          plot=False, on_progress=progress, cpus="off", stop_at_goal=False)

    tol = float(cfg.autopilot.loiter_radius)
    progress(f"bench ardupilot: station keeping at ({gx:g}, {gy:g}): the vessel computer")
    if not 0 < args.station_hold <= args.station_duration:
        raise UsageError("--station-hold: must be > 0 and at most --station-duration")
    ours = station_figures(run_loop(opts("vessel-computer"), cfg), (gy, gx), tol, geo, args.station_hold)
    progress("bench ardupilot: station keeping: ArduRover (LOITER)")
    ap = run_ardupilot(opts("ardurover"), cfg, sitl)
    theirs = station_figures(ap, (gy, gx), tol, geo, args.station_hold)
    setup = ap.ardurover()
    auto = None if setup is None else setup["auto_at_s"]
    if theirs["arrived_s"] is not None and auto is not None:
        theirs["arrived_s"] = round(theirs["arrived_s"] - auto, 2)   # from AUTO, as ours from the start
    keys = ("station_rms_m", "station_max_m", "within_tolerance", "arrived_s")
    ratios = {k: ratio(theirs[k], ours[k]) for k in keys}
    lines.append(f"station keeping at ({gx:g}, {gy:g}), {tol:g} m: RMS {_fmt(theirs['station_rms_m'])} / "
                 f"{_fmt(ours['station_rms_m'])} m (ratio {_fmt(ratios['station_rms_m'])}), max "
                 f"{_fmt(theirs['station_max_m'])} / {_fmt(ours['station_max_m'])} m, within "
                 f"{_fmt(theirs['within_tolerance'])} / {_fmt(ours['within_tolerance'])}, over "
                 f"{_fmt(theirs['held_s'])} s, arrived {_fmt(theirs['arrived_s'])} / {_fmt(ours['arrived_s'])} s "
                 f"(ArduRover / ours)")
    return {"goal_xy": [gx, gy], "tolerance_m": tol, "hold_s": args.station_hold, "ardurover": theirs,
            "vessel_computer": ours, "ratio": ratios}


HEAD = ("scenario", "who", "outcome", "time s", "way s", "xte rms", "xte max", "clear m", "energy J", "path m",
        "coll")   # time: to the goal (ArduRover's from AUTO); way: from the start of motion; xte: from the route


def _row(scenario: str, who: str, f: JsonTable) -> str:
    cells = (scenario, who, str(f.get("outcome", "")), *(_fmt(f.get(k)) for k in METRICS))
    return " ".join(f"{c:<15}" if i == 0 else f"{c:>8}" for i, c in enumerate(cells))


def _fmt(v: object) -> str:
    if v is None:
        return "-"
    return f"{v:.3g}" if isinstance(v, float) else str(v)
