"""`hil bench ardupilot`: ArduRover against the project's vessel computer, on the same boat, sea and missions.

Each mission is flown twice in one run, in lockstep with the same seed: by the vessel computer
(`hil run`) and by ArduPilot's ArduRover SITL (`hil run --autopilot ardupilot`), which follows the same
global route as an ArduPilot mission. Both are judged from the simulator's truth alike: mission time
(simulated s to the goal; ArduRover's boat is moored at its start while ArduRover boots, aligns and
takes its mission, and its time counts from AUTO, the set-up reported apart), the truth's
cross-track distance from the global route (RMS and largest, m), the minimum clearance from the chart
(m), energy (J, eq. of `hil run`), collisions. Ratios are ArduRover / vessel computer.
"""

from __future__ import annotations

import argparse
import math
import subprocess
import tempfile
from pathlib import Path
from typing import Any

import numpy as np

from hil.console import emit, load_settings, progress
from hil.errors import UsageError

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
                    "vessel computer (docs/ardupilot.md).",
    )
    p.add_argument("--scenarios", nargs="+", default=["harbour"], metavar="NAME",
                   help="fixed scenarios to fly (default: harbour)")
    p.add_argument("--duration", type=float, default=300.0, metavar="S",
                   help="simulated seconds at most per flight (default: 300)")
    p.add_argument("--seed", type=int, default=1, help="seed of both flights (default: 1)")
    p.add_argument("--ardupilot-bin", metavar="PATH", default=None,
                   help="the ArduRover SITL binary (default: $ARDUPILOT_SITL)")
    p.add_argument("--out", metavar="DIR", default=None,
                   help="keep the run folders here (default: a temporary folder, removed)")
    p.set_defaults(func=run)


def truth_track(tlog: Path, geo: Any, until_s: float) -> np.ndarray:
    """The truth (north, east) in m from a run's .tlog, up to ``until_s`` of simulated time."""
    from pymavlink import mavutil

    pts = []
    m = mavutil.mavlink_connection(str(tlog))
    try:
        while (msg := m.recv_match(type="HIL_STATE_QUATERNION")) is not None:
            if msg.time_usec * 1e-6 > until_s + 1e-9:
                break
            pts.append(geo.geodetic_to_sea_level(msg.lat * 1e-7, msg.lon * 1e-7))
    finally:
        m.close()
    return np.array(pts, dtype=float).reshape(-1, 2)


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


def flight_figures(summary: Any, route_ned: np.ndarray, geo: Any) -> dict[str, Any]:
    from hil.ardupilot import route_cross_track

    tlog = Path(summary.tlog)
    track = truth_track(tlog, geo, summary.sim_time_s)
    xte = route_cross_track(track, route_ned) or {}
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
    from common.geodesy import LocalFrame
    from hil import scenario as scenarios
    from hil.ardupilot import find_sitl, run_ardupilot
    from hil.hilrun import RunOptions, run_loop

    if not 0 < args.duration < math.inf:
        raise UsageError("--duration: must be a finite number > 0 of seconds")
    sitl = find_sitl(args.ardupilot_bin)
    cfg = load_settings(args)
    for name in args.scenarios:
        if scenarios.load_spec(name).kind != "fixed":
            raise UsageError(f"scenario {name!r} draws a new map per run; the bench needs fixed scenarios")
    geo = LocalFrame(cfg.geodesy.lat0, cfg.geodesy.lon0, cfg.geodesy.alt0)
    result: dict[str, Any] = {"commit": commit(), "seed": args.seed, "duration_s": args.duration,
                              "ardupilot": str(sitl.binary), "scenarios": {}}
    lines = [f"ArduRover against the vessel computer, seed {args.seed}, lockstep, commit {result['commit']}",
             " ".join(f"{c:<15}" if i == 0 else f"{c:>8}" for i, c in enumerate(HEAD))]
    with tempfile.TemporaryDirectory(prefix="hil-bench-ardupilot-") as tmp:
        root = Path(args.out) if args.out else Path(tmp)
        for name in args.scenarios:
            scen = scenarios.load(name, cfg.current, cfg.planner.safety_radius)
            route = np.asarray(scen.reference_path, dtype=float)[:, ::-1]

            def opts(who: str, name: str = name) -> RunOptions:
                return RunOptions(scenario=name, lockstep=True, duration=args.duration, seed=args.seed,
                                  config=args.config, overrides=list(args.overrides), out=root / name / who,
                                  plot=False, on_progress=progress, cpus="off")

            progress(f"bench ardupilot: {name}: the vessel computer")
            ours = flight_figures(run_loop(opts("vessel-computer"), cfg), route, geo)
            progress(f"bench ardupilot: {name}: ArduRover")
            ap_summary = run_ardupilot(opts("ardurover"), cfg, sitl)
            theirs = flight_figures(ap_summary, route, geo)
            ap = (ap_summary.simulator or {}).get("ardupilot", {})
            theirs["setup_to_auto_s"] = ap.get("auto_at_s")   # moored until then: the mission counts from AUTO
            if theirs["reached_goal"]:
                theirs["mission_time_s"] = ap.get("mission_time_s")
            ratios = {k: ratio(theirs[k], ours[k]) for k in METRICS if k != "collisions"}
            result["scenarios"][name] = {"ardurover": theirs, "vessel_computer": ours, "ratio": ratios}
            lines += [_row(name, "ArduRover", theirs), _row("", "ours", ours),
                      _row("", "ratio", {**ratios, "outcome": "", "collisions": None})]
    emit(args, result, lines)


HEAD = ("scenario", "who", "outcome", "time s", "way s", "xte rms", "xte max", "clear m", "energy J", "path m",
        "coll")   # time: to the goal (ArduRover's from AUTO); way: from the start of motion; xte: from the route


def _row(scenario: str, who: str, f: dict[str, Any]) -> str:
    cells = (scenario, who, str(f.get("outcome", "")), *(_fmt(f.get(k)) for k in METRICS))
    return " ".join(f"{c:<15}" if i == 0 else f"{c:>8}" for i, c in enumerate(cells))
    return 0


def _fmt(v: Any) -> str:
    if v is None:
        return "-"
    return f"{v:.3g}" if isinstance(v, float) else str(v)
