"""`hil bench loop`: the control loop's latency and the full loop's lockstep speed."""

from __future__ import annotations

import argparse
import tempfile
from pathlib import Path

from hil.console import emit, load_settings, progress


def add_parser(sub: argparse._SubParsersAction, parents: list[argparse.ArgumentParser]) -> None:
    p = sub.add_parser(
        "loop", parents=parents,
        help="HIL loop: control latency (sensor datagram in -> actuator datagram out) and lockstep speed",
        description="Runs the whole HIL loop (simulator and autopilot processes, planner worker) twice on a "
                    "scenario: in lockstep, for the loop's steps per second and the control latency "
                    "(sensor datagram received -> actuator datagram sent, p50/p99/max, excluding the frames "
                    "on which lockstep waits for the planner by design, which are counted apart); and in real "
                    "time, where the planner runs beside the control loop, for the latency under planning and "
                    "the simulator's view (stale-command events, commands per step). Goal: p99 <= 2 ms and "
                    "planning never stalls control.",
    )
    p.add_argument("--scenario", default="harbour", help="scenario (default: harbour)")
    p.add_argument("--duration", type=float, default=60.0, metavar="S",
                   help="simulated seconds of the lockstep run (default: 60)")
    p.add_argument("--realtime-duration", type=float, default=20.0, metavar="S",
                   help="seconds of the real-time run (x1, so also wall seconds; default: 20; 0 skips it)")
    p.add_argument("--seed", type=int, default=1, help="seed (default: 1)")
    p.set_defaults(func=run)


def _leg(summary: dict) -> dict:
    sim = summary.get("simulator") or {}
    steps = sim.get("steps") or 0
    return {
        "sim_time_s": summary["sim_time_s"],
        "wall_time_s": summary["wall_time_s"],
        "steps_per_wall_s": round(steps / summary["wall_time_s"], 1) if summary["wall_time_s"] else None,
        "control_latency_ms": summary["control_latency_ms"],
        "simulator_steps": steps,
        "commands_received": sim.get("commands_received"),
        "stale_command_events": sim.get("stale_command_events"),
        "step_jitter_ms": sim.get("jitter_ms"),
        "planning_cycles": summary["planning_cycles"],
        "deadline_overruns": summary["deadline_overruns"],
        "outcome": summary["outcome"],
    }


def run(args: argparse.Namespace) -> int:
    from hil.hilrun import RunOptions, run_loop

    cfg = load_settings(args)
    result: dict = {"scenario": args.scenario, "goal_p99_ms": 2.0}
    with tempfile.TemporaryDirectory(prefix="hil-bench-loop-") as tmp:
        progress(f"bench loop: lockstep, {args.duration:g} s simulated on {args.scenario}")
        lock = run_loop(RunOptions(scenario=args.scenario, lockstep=True, duration=args.duration, seed=args.seed,
                                   config=args.config, overrides=list(args.overrides), out=Path(tmp) / "lockstep",
                                   plot=False, on_progress=progress), cfg)
        result["lockstep"] = _leg(lock)
        if args.realtime_duration > 0:
            progress(f"bench loop: real time x1, {args.realtime_duration:g} s")
            rt = run_loop(RunOptions(scenario=args.scenario, lockstep=False, speedup=1.0,
                                     duration=args.realtime_duration, seed=args.seed, config=args.config,
                                     overrides=list(args.overrides), out=Path(tmp) / "realtime", plot=False,
                                     on_progress=progress), cfg)
            result["realtime"] = _leg(rt)
    p99 = [leg["control_latency_ms"]["p99"] for k, leg in result.items() if k in ("lockstep", "realtime")]
    result["goal_met"] = bool(p99) and max(p99) <= 2.0
    rt = result.get("realtime")
    result["planning_stalled_control"] = None if rt is None else bool(rt["stale_command_events"])
    emit(args, result)
    return 0
