"""`hil bench frame`: where one autopilot frame's time goes (cProfile), in-process.

The simulator core (:class:`simulator.core.SimulatorCore`) and the vessel computer
(:func:`hil.assembly.build`, as `hil autopilot --lockstep` builds it: HIL link, planner
worker process, ground-station link) run in this one process, closed-loop: each datagram the core
encodes is decoded by the autopilot's link, handled by ``Autopilot.on_frame``, and the
HIL_ACTUATOR_CONTROLS it sends over loopback UDP is read back and applied by the core. Only the
autopilot's part of each frame is timed and profiled; frames on which lockstep waits for the
planner (by design, once per planning cycle) are left out of the timing, and the planner wait is
subtracted from the profile, as ``hil bench loop`` leaves them out of the latency.
"""

from __future__ import annotations

import argparse
import cProfile
import json
import pstats
import socket
import statistics
import time
from typing import TYPE_CHECKING

from common.tables import JsonTable
from hil.console import emit, load_settings, progress
from hil.errors import UsageError

if TYPE_CHECKING:
    from autopilot_bridge.navigation import NavigationParams

# Profile rows: (label, [(file suffix, function name), ...]) summed by cumulative time. The rows
# are disjoint calls of one frame (none calls another), so their shares add up; "other" is the rest.
ROWS: tuple[tuple[str, tuple[tuple[str, str], ...]], ...] = (
    ("MAVLink decode + plausibility (HilLink.decode)", (("autopilot_bridge/hil_link.py", "decode"),)),
    ("navigation EKF: predicts + updates (Autopilot._fuse)", (("autopilot_bridge/autopilot.py", "_fuse"),)),
    ("navigation estimate (NavigationFilter.state)", (("autopilot_bridge/navigation.py", "state"),)),
    ("planning hand-off: submit/collect, planner waits excluded",
     (("autopilot_bridge/autopilot.py", "_submit_deferred_plan"), ("autopilot_bridge/plan_handoff.py", "collect"))),
    ("guidance (LineOfSight.update)", (("autopilot_bridge/guidance.py", "update"),)),
    ("control: set-points, PID, speed, allocation (Helm._control)",
     (("autopilot_bridge/helm.py", "_control"), ("autopilot_bridge/helm.py", "_station_keep"),
      ("autopilot_bridge/helm.py", "hold"))),
    ("sensed obstacles (WorldKeeper.sense)", (("autopilot_bridge/world_keeper.py", "sense"),)),
    ("traffic awareness (TrafficAwareness.on_frame)", (("autopilot_bridge/traffic_awareness.py", "on_frame"),)),
    ("vehicle / mission (Vehicle.update, WorldKeeper.apply_route)",
     (("autopilot_bridge/vehicle.py", "update"), ("autopilot_bridge/world_keeper.py", "apply_route"))),
    ("MAVLink encode + UDP send of the command (Autopilot._send)", (("autopilot_bridge/autopilot.py", "_send"),)),
    ("telemetry: status + GCS link (Autopilot._publish, GcsLink.service)",
     (("autopilot_bridge/autopilot.py", "_publish"), ("autopilot_bridge/gcs/link.py", "service"))),
)
# Inside the navigation row: the filter's own steps.
NAV_DETAIL: tuple[tuple[str, tuple[tuple[str, str], ...]], ...] = (
    ("  of which filter arithmetic (nav_kernel.step | predict_to+EKF.update)",
     (("autopilot_bridge/nav_kernel.py", "step"), ("autopilot_bridge/navigation.py", "predict_to"),
      ("filterpy/kalman/EKF.py", "update"))),
)
PLANNER_WAIT = ("autopilot_bridge/planning_worker.py", "wait")
# The whole of the autopilot's part of a frame, as _Loop.step runs it.
FRAME = (("autopilot_bridge/hil_link.py", "decode"), ("autopilot_bridge/autopilot.py", "on_frame"),
         ("autopilot_bridge/gcs/link.py", "service"))


def add_parser(sub: argparse._SubParsersAction, parents: list[argparse.ArgumentParser]) -> None:
    p = sub.add_parser(
        "frame", parents=parents,
        help="profile one autopilot frame in-process (cProfile): decode, EKF, planning hand-off, guidance, "
             "control, encode, telemetry",
        description="Runs the simulator core and the vessel computer closed-loop in this process (lockstep, "
                    "real planner worker, HIL_ACTUATOR_CONTROLS over loopback UDP) and reports (1) the "
                    "autopilot's time per frame without a profiler (microseconds: mean, p50, p99) and (2) a "
                    "second run under cProfile: microseconds per frame and share of each part of the frame. "
                    "Frames that wait for the planner in lockstep are left out of both.",
    )
    p.add_argument("--scenario", default="harbour", help="fixed scenario (default: harbour)")
    p.add_argument("--steps", type=int, default=3000, metavar="N",
                   help="frames per run, at the IMU rate (default: 3000, i.e. 30 s simulated at 100 Hz)")
    p.add_argument("--seed", type=int, default=1, help="seed (default: 1)")
    p.add_argument("--top", type=int, default=0, metavar="N",
                   help="also list the N functions with the most own time (default: 0)")
    p.set_defaults(func=run)


class _Loop:
    """Simulator core + autopilot in one process; ``step()`` runs one frame and returns the
    autopilot's seconds for it (None when it waited for the planner)."""

    def __init__(self, args: argparse.Namespace) -> None:
        from hil import scenario as scenarios
        from hil.assembly import build, simulator_settings
        from hil.scenario import simulator_overrides
        from simulator.core import SimulatorCore
        from simulator.rangefinder import WorldMap

        self.rx = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.rx.bind(("127.0.0.1", 0))
        self.rx.settimeout(5.0)
        port = self.rx.getsockname()[1]
        base = load_settings(args)
        spec = scenarios.load_spec(args.scenario)
        if spec.kind != "fixed":
            raise UsageError(f"--scenario {args.scenario}: draws a new map per run; pick a fixed scenario")
        scen = scenarios.instance(spec, None, base.current)
        seed = [f"sim.seed={int(args.seed)}"]
        sim_cfg = load_settings(argparse.Namespace(config=args.config, overrides=list(args.overrides) + seed
                                                   + simulator_overrides(scen, base.current)))
        self.core = SimulatorCore(simulator_settings(sim_cfg), WorldMap(scen.truth_occ(), scen.resolution),
                                  tuple(scen.traffic))
        ap_cfg = load_settings(argparse.Namespace(config=args.config, overrides=list(args.overrides) + seed + [
            'autopilot.listen="127.0.0.1:0"', f'autopilot.actuators_to=["127.0.0.1:{port}"]']))
        self.ap, self.link = build(ap_cfg, args.scenario, lockstep=True)

    def step(self, prof: cProfile.Profile | None = None) -> float | None:
        from simulator.core import Command

        data = self.core.frame()
        ap = self.ap
        waits = ap.stats.planner_waits
        t0 = time.perf_counter()
        if prof is not None:
            prof.enable()
        frame = self.link.decode(data)
        if frame is not None:
            ap.on_frame(frame, t0)
        if ap.telemetry is not None:
            ap.telemetry.service()
        if prof is not None:
            prof.disable()
        spent = time.perf_counter() - t0
        for cmd in self.core.receive(self.rx.recv(65536)):
            self.core.apply(Command(self.core.time_usec, cmd.port, cmd.stdb))
        self.core.step()
        return None if ap.stats.planner_waits != waits else spent

    def close(self) -> None:
        self.ap.worker.close()
        self.link.close()
        if self.ap.telemetry is not None:
            self.ap.telemetry.close()
        self.rx.close()


def _cum(stats: dict, keys: tuple[tuple[str, str], ...]) -> float:
    total = 0.0
    for (filename, _line, name), (_cc, _nc, _tt, ct, _callers) in stats.items():
        for suffix, fn in keys:
            if name == fn and filename.replace("\\", "/").endswith(suffix):
                total += ct
    return total


def _timed(args: argparse.Namespace, profile: bool) -> tuple[list[float], int, cProfile.Profile | None]:
    loop = _Loop(args)
    prof = cProfile.Profile() if profile else None
    times, waited = [], 0
    try:
        for _ in range(args.steps):
            s = loop.step(prof)
            if s is None:
                waited += 1
            else:
                times.append(s)
    finally:
        loop.close()
    return times, waited, prof


def bench_filters(nav: NavigationParams, frames: int, seed: int) -> dict[str, float]:
    """Microseconds per 100 Hz frame of the navigation filter alone, per implementation, on one
    synthetic seeded sequence as the HIL link delivers it: gyro and compass every frame, GPS
    position and velocity every 10th (10 Hz), called as ``Autopilot._fuse`` calls them."""
    import math
    from dataclasses import replace

    import numpy as np

    from autopilot_bridge.navigation import NavigationFilter

    rng = np.random.default_rng(seed)
    noise = rng.normal(0.0, 1.0, size=(frames, 6)).tolist()
    out = {}
    for kind in ("filterpy", "fast"):
        f = NavigationFilter(replace(nav, filter=kind))
        f.update_compass(0.0, 0.3)
        f.update_gps_position(0.0, 0.0, 0.0)
        t0 = time.perf_counter()
        for k in range(1, frames):
            t, e = k * 0.01, noise[k]
            heading = 0.3 + 0.1 * math.sin(0.05 * t) + 0.02 * e[0]
            rate = 0.005 * math.cos(0.05 * t) + 0.004 + 0.002 * e[1]
            if k % 10 == 0:   # in the order of Autopilot._fuse
                f.update_compass(t, heading)
                f.update_gps_position(t, 1.5 * t + 0.5 * e[2], 0.1 * t + 0.5 * e[3])
                f.update_gps_velocity(t, 1.5 + 0.05 * e[4], 0.1 + 0.05 * e[5])
                f.update_gyro(t, rate)
            else:
                f.update_heading_and_rate(t, heading, rate)
        out[kind] = round((time.perf_counter() - t0) / (frames - 1) * 1e6, 1)
    return out


def run(args: argparse.Namespace) -> int:
    if args.steps < 100 or args.top < 0:
        raise UsageError("--steps must be >= 100 and --top >= 0")
    progress(f"bench frame: {args.steps} frames on {args.scenario}, no profiler")
    plain, waited, _ = _timed(args, profile=False)
    us = sorted(t * 1e6 for t in plain)
    result: JsonTable = {
        "scenario": args.scenario, "steps": args.steps, "frames_waiting_for_planner": waited,
        "navigation_filter": getattr(load_settings(args).navigation, "filter", "filterpy"),
        "frame_us": {"mean": round(statistics.fmean(us), 1), "p50": round(us[len(us) // 2], 1),
                     "p99": round(us[min(len(us) - 1, int(0.99 * len(us)))], 1)},
    }
    result["navigation_alone_us_per_frame"] = bench_filters(load_settings(args).navigation, args.steps, args.seed)
    progress(f"bench frame: {args.steps} frames under cProfile")
    prof_times, _, prof = _timed(args, profile=True)
    assert prof is not None
    stats = pstats.Stats(prof).stats  # type: ignore[attr-defined]
    n = len(prof_times) + waited
    # The profile covers every frame; the planner waits (on the frames left out above) are
    # subtracted from the planning hand-off and from the total.
    wait = _cum(stats, (PLANNER_WAIT,))
    profiled_total = _cum(stats, FRAME) - wait
    rows, accounted = [], 0.0
    for label, keys in ROWS:
        t = _cum(stats, keys) - (wait if label.startswith("planning") else 0.0)
        accounted += t
        rows.append((label, t))
        if label.startswith("navigation EKF"):
            rows += [(lab, _cum(stats, k)) for lab, k in NAV_DETAIL]
    rows.append(("other (frame bookkeeping, modes, behaviour)", profiled_total - accounted))
    result["profiled_frame_us"] = round(profiled_total / n * 1e6, 1)
    result["profile"] = [{"part": label, "us_per_frame": round(t / n * 1e6, 1),
                          "share": round(t / profiled_total, 3) if profiled_total > 0 else None} for label, t in rows]
    if args.top:
        top = sorted(stats.items(), key=lambda kv: -kv[1][2])[:args.top]
        result["top_own_time"] = [{"function": f"{f.split('site-packages/')[-1]}:{line}({name})",
                                   "calls_per_frame": round(v[1] / n, 2), "own_us_per_frame": round(v[2] / n * 1e6, 1)}
                                  for (f, line, name), v in top]
    fu = result["frame_us"]
    human = [f"{args.scenario}, {result['navigation_filter']} EKF, {args.steps} frames "
             f"({waited} waited for the planner, "
             f"left out): mean {fu['mean']} us, p50 {fu['p50']} us, p99 {fu['p99']} us without profiler",
             f"under cProfile {result['profiled_frame_us']} us/frame; navigation filter alone, us/frame: " + ", ".join(
                 f"{k} {v}" for k, v in result["navigation_alone_us_per_frame"].items())]
    for r in result["profile"]:
        share = "" if r["share"] is None else f"{100 * r['share']:5.1f}%"
        human.append(f"{r['part']:70s} {r['us_per_frame']:9.1f} {share:>6s}")
    human += [json.dumps(r) for r in result.get("top_own_time", [])]
    emit(args, result, human)
    return 0
