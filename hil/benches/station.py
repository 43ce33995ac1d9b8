"""`hil bench station`: keeping station in a current, against ArduRover's way and against drifting.

One run of this command flies the open-water scenario (configs/scenarios/open-water-current.toml) to its
goal and then keeps station there, in lockstep with one seed, in each uniform current across the route
(0.2, 0.5, 1.0 m/s by default) and with each way of keeping station:

* ``into-current`` (the vessel computer's: bow into the water velocity needed, the estimated current fed
  forward; autopilot_bridge/station_keeping.py);
* ``drift-and-return`` (ArduRover's boats and this project's LOITER before: drift within LOIT_RADIUS,
  then steer straight back bow first);
* ``hold`` (thrusters off at the goal, ArduRover's HOLD: the boat drifts with the stream).

From the simulator's truth over the last ``--hold`` seconds of each run: the distance from the goal
(p50, p95, max, m) and the thrusters' electrical energy per minute (J/min, the simulator's thruster power
model: simulator/battery.py), with the ratios against ``drift-and-return`` in the same run.
"""

from __future__ import annotations

import argparse
import math
import tempfile
from pathlib import Path
from typing import TYPE_CHECKING

from common.tables import JsonTable
from hil.console import emit, progress

if TYPE_CHECKING:
    from simulator.battery import ThrusterPower
    from simulator.config import VesselParams

METHODS = ("into-current", "drift-and-return", "hold")
SCENARIO = "open-water-current"


def add_parser(sub: argparse._SubParsersAction, parents: list[argparse.ArgumentParser]) -> None:
    p = sub.add_parser(
        "station", parents=parents,
        help="station keeping in 0.2/0.5/1.0 m/s currents: into the current, ArduRover's drift-and-return, HOLD",
        description="Flies open water to a goal and keeps station there in uniform currents across the route, "
                    "with each way of keeping station (into-current: the vessel computer's; drift-and-return: "
                    "ArduRover's boats; hold: thrusters off), and prints the distance from the point (p50, p95, "
                    "max) and the thrusters' electrical energy per minute over the last --hold seconds, with "
                    "ratios against drift-and-return from the same run (docs/simulator.md).")
    p.add_argument("--currents", default="0.2,0.5,1.0", metavar="V,...",
                   help="current speeds across the route, m/s (default: 0.2,0.5,1.0)")
    p.add_argument("--duration", type=float, default=260.0, metavar="S",
                   help="simulated seconds of each run (default: 260: ~80 s to the goal in 1 m/s, then holding)")
    p.add_argument("--hold", type=float, default=120.0, metavar="S",
                   help="judged over the last S simulated seconds of each run (default: 120)")
    p.add_argument("--seed", type=int, default=1, help="seed of every run (default: 1)")
    p.add_argument("--out", metavar="DIR", default=None, help="keep the run folders here (default: removed)")
    p.set_defaults(func=run)


def _parse_currents(text: str) -> list[float]:
    from hil.errors import UsageError

    try:
        values = [float(v) for v in text.split(",") if v.strip()]
    except ValueError:
        raise UsageError(f"--currents {text!r}: comma-separated speeds in m/s") from None
    if not values or any(not (math.isfinite(v) and 0.0 <= v <= 2.5) for v in values):
        raise UsageError(f"--currents {text!r}: each between 0 and 2.5 m/s (the hull's top speed is 3)")
    return values


def scenario_in_current(speed: float, folder: Path) -> Path:
    """configs/scenarios/open-water-current.toml with the current set to ``speed`` m/s across the route
    (a scenario's [current] wins over the configuration's, so the speed is written into a copy)."""
    from hil.scenario_names import SCENARIO_DIR

    src = SCENARIO_DIR / f"{SCENARIO}.toml"
    text = src.read_text().replace('map = "../maps/open_water.npy"',
                                   f'map = "{(SCENARIO_DIR / "../maps/open_water.npy").resolve()}"')
    text = text.replace("uniform = [0.0, 1.0]", f"uniform = [0.0, {float(speed)!r}]")
    folder.mkdir(parents=True, exist_ok=True)
    out = folder / f"{SCENARIO}-{speed:g}.toml"
    out.write_text(text)
    return out


def judge(truth: dict[int, tuple[float, float, float, float]], commands: list[tuple[int, float, float]],
          goal: tuple[float, float], t_from: float, power: ThrusterPower, vessel: VesselParams
          ) -> dict[str, float | None]:
    """Distance from ``goal`` (NED m) and electrical energy per minute after ``t_from`` (s)."""
    import numpy as np

    times = sorted(t for t in truth if t * 1e-6 >= t_from)
    if len(times) < 2:
        return {"samples": len(times)}
    d = np.array([math.hypot(truth[t][0] - goal[0], truth[t][1] - goal[1]) for t in times])
    cmds = sorted(commands)
    cmd_t = np.array([c[0] for c in cmds]) if cmds else np.zeros(0)

    def thrust(u: float) -> float:
        return u * vessel.T_max if u >= 0 else -u * vessel.T_min

    joules = 0.0
    for i in range(len(times) - 1):
        j = int(np.searchsorted(cmd_t, times[i], side="right")) - 1
        if j >= 0:
            _, port, stdb = cmds[j]
            joules += (power(thrust(port)) + power(thrust(stdb))) * (times[i + 1] - times[i]) * 1e-6
    minutes = (times[-1] - times[0]) * 1e-6 / 60.0
    return {"p50_m": round(float(np.percentile(d, 50)), 3), "p95_m": round(float(np.percentile(d, 95)), 3),
            "max_m": round(float(d.max()), 3), "energy_J_per_min": round(joules / minutes, 1), "samples": len(times)}


def one(current: float, method: str, args: argparse.Namespace, out: Path) -> dict[str, float | None]:
    from hil import settings
    from hil.hilrun import HilRun, RunOptions
    from simulator.battery import ThrusterPower

    overrides = ['autopilot.mission_done="hold"' if method == "hold" else 'autopilot.mission_done="loiter"',
                 f'autopilot.station_keeping="{"into-current" if method == "hold" else method}"']
    cfg = settings.load(None, overrides)
    scenario = scenario_in_current(current, out)
    run = HilRun(RunOptions(scenario=str(scenario), seed=args.seed, duration=args.duration, stop_at_goal=False,
                            plot=False, out=out / f"{method}-{current:g}", overrides=overrides), cfg)
    s = run.execute()
    done = [float(e.split("s ", 1)[0]) for e in s.events if "mission complete" in e]
    # Judged from 30 s after the goal for --hold seconds (a drifting HOLD may reach the map's edge first).
    t0 = done[0] + 30.0 if done else args.duration - args.hold
    truth = {t: v for t, v in run.tap.truth.items() if t * 1e-6 <= t0 + args.hold}
    result = judge(truth, list(run.tap.commands), run.judge.goal, t0, ThrusterPower(cfg.esc, cfg.vessel),
                   cfg.vessel)
    result["goal_s"] = done[0] if done else None
    result["collisions"] = s.collisions
    return result


def run(args: argparse.Namespace) -> int:
    currents = _parse_currents(args.currents)
    with tempfile.TemporaryDirectory(prefix="hil-bench-station-") as tmp:
        out = Path(args.out) if args.out else Path(tmp)
        table: JsonTable = {"scenario": SCENARIO, "seed": args.seed, "hold_s": args.hold, "currents": {}}
        for v in currents:
            rows: JsonTable = {}
            for method in METHODS:
                progress(f"bench station: current {v:g} m/s, {method} ...")
                rows[method] = one(v, method, args, out)
            base = rows["drift-and-return"]
            for method in METHODS:
                r = rows[method]
                for k in ("p95_m", "energy_J_per_min"):
                    if base.get(k) and k in r:
                        r[f"{k}_vs_drift_and_return"] = round(r[k] / base[k], 3)
            table["currents"][f"{v:g}"] = rows
    lines = [f"{'current':>8} {'method':>17} {'p50 m':>7} {'p95 m':>7} {'max m':>7} {'J/min':>8} "
             f"{'p95 ratio':>9} {'J ratio':>8}"]
    for v, rows in table["currents"].items():
        for method, r in rows.items():
            lines.append(f"{v:>8} {method:>17} {r.get('p50_m', math.nan):7.2f} {r.get('p95_m', math.nan):7.2f} "
                         f"{r.get('max_m', math.nan):7.2f} {r.get('energy_J_per_min', math.nan):8.0f} "
                         f"{r.get('p95_m_vs_drift_and_return', math.nan):9.3f} "
                         f"{r.get('energy_J_per_min_vs_drift_and_return', math.nan):8.3f}")
    emit(args, table, lines)
    return 0
