"""`hil run`: the whole HIL loop, or (``--demo``) the simulator under a constant-thrust controller.

The loop (:mod:`hil.hilrun`): the simulator and the autopilot bridge as two OS processes linked
only by UDP/MAVLink, on a scenario, until the goal is reached or the time is up; it writes a run
folder (``run.tlog``, ``summary.json``, ``plot.png``).

The demo: the simulator in its own OS process, driven over loopback UDP by a built-in
constant-thrust controller (a steady turn) in this process, which answers every sensor frame with
one HIL_ACTUATOR_CONTROLS carrying the frame's ``time_usec``.
"""

from __future__ import annotations

import argparse
import json
import math
import re
import signal
import subprocess
import time
from pathlib import Path
from typing import TYPE_CHECKING

from common.tables import to_table
from hil import processes
from hil.commands.can_options import add_can_arguments, can_overrides, check_can
from hil.console import emit, load_settings, progress
from hil.errors import ConfigError, RunFailed, UsageError
from hil.sim_client import HilClient, sim_command, start_simulator
from planner.params import ALGORITHM_NAMES

if TYPE_CHECKING:
    from types import FrameType

    from common.current_tally import CurrentStats
    from hil.placement import Placement
    from hil.run_summary import RunCurrent, RunSummary
    from hil.settings import HilConfig

FRAME_TIMEOUT_S = 15.0  # wall seconds to wait for the simulator's next frame before giving up
DEMO_CONTROLS = (0.6, 0.5)  # port, starboard: a gentle starboard turn


class Terminated(KeyboardInterrupt):
    """SIGTERM received: unwind like Ctrl-C so that `finally` blocks stop the simulator."""


def _raise_terminated(signum: int, frame: FrameType | None) -> None:
    raise Terminated()


stop_process = processes.stop


def add_parser(sub: argparse._SubParsersAction, parents: list[argparse.ArgumentParser]) -> None:
    p = sub.add_parser(
        "run", parents=parents,
        help="run the HIL loop: simulator and autopilot as two processes over UDP/MAVLink",
        description="Start the simulator (hil sim) and the vessel computer (hil autopilot) as two separate "
                    "OS processes linked only by loopback UDP/MAVLink, on a scenario, until the vessel "
                    "reaches the final goal (judged from the simulator's truth) or --duration simulated "
                    "seconds pass. Writes a run folder with the MAVLink traffic (run.tlog, readable by "
                    "pymavlink's mavlogdump), summary.json, the processes' logs and plot.png, and prints "
                    "the summary: goal reached, collisions, minimum clearance, simulated and wall time, "
                    "path length, energy, planning cycles, deadline overruns, worker restarts, fallback "
                    "activations, navigation RMSE, control-loop latency, the ground-station link's "
                    "counters. Exit 0 only when the goal was reached without collision; Ctrl-C ends the "
                    "run with outcome 'interrupted', its folder written, exit 130. With --demo, a "
                    "constant-thrust controller replaces the autopilot (a steady starboard turn).",
    )
    p.add_argument("--scenario", default="harbour",
                   help="NAME of configs/scenarios/NAME.toml, or a path to a scenario .toml: map, start, goal, "
                        "reference path, current (default: harbour)")
    p.add_argument("--duration", metavar="SECONDS", type=float, default=None,
                   help="simulated seconds at most (default: 300; --demo: 60)")
    p.add_argument("--seed", type=int, default=None, help="seed of every random process (default: sim.seed)")
    mode = p.add_mutually_exclusive_group()
    mode.add_argument("--lockstep", dest="speedup", action="store_const", const=None,
                      help="advance the simulator one IMU period per command: repeatable runs (the default)")
    mode.add_argument("--speedup", metavar="N", type=float, default=None,
                      help="real-time mode instead: N simulated seconds per wall second. With --wait-for-arm "
                           "(a ground station attached) the run stays lockstep and is paced to N x wall time "
                           "(default 1: a person can follow it; lockstep alone runs ~10x faster)")
    p.add_argument("--pipeline", action="store_true",
                   help="lockstep one frame ahead (sim.lockstep_pipeline): the simulator computes the next frame "
                        "while the vessel computer answers the last, so the two work at once; each command then "
                        "acts one frame (10 ms) later than in plain lockstep. Repeatable like plain lockstep, but "
                        "not the same runs (docs/simulator.md)")
    p.add_argument("--cpus", default="auto", metavar="auto|off|A,B",
                   help="where a lockstep run's processes run: A,B puts the simulator and the tap on CPU A, the "
                        "vessel computer and its planner worker on CPU B; auto (the default) takes the first "
                        "pair of CPUs no other run on this host holds, or none; off leaves it to the scheduler. "
                        "Only the speed depends on it, not the run (docs/performance.md)")
    p.add_argument("--algorithm", choices=ALGORITHM_NAMES, default=None,
                   help="local planner (default: planner.algorithm = ddrrt-star)")
    p.add_argument("--out", metavar="DIR", default=None,
                   help="run folder (default: runs/NAME-seedN-YYYYmmdd-HHMMSS, NAME the scenario's name key)")
    p.add_argument("--no-plot", action="store_true", help="do not draw plot.png")
    p.add_argument("--wall-timeout", metavar="SECONDS", type=float, default=None,
                   help="end the run after this much wall time whatever happens (default: real time "
                        "--duration / speedup + 300 s; lockstep the larger of 900 s and 3 x --duration)")
    p.add_argument("--autopilot", choices=("vessel-computer", "ardupilot"), default="vessel-computer",
                   help="who flies the boat: the project's vessel computer (default) or ArduPilot's ArduRover SITL "
                        "with the simulator as its JSON physics, in lockstep (docs/ardupilot.md)")
    p.add_argument("--ardupilot-bin", metavar="PATH", default=None,
                   help="--autopilot ardupilot: the ArduRover SITL binary, ArduPilot's rover.parm, motorboat.parm "
                        "and rover-skid.parm beside it (default: $ARDUPILOT_SITL)")
    p.add_argument("--ardupilot-params", metavar="FILE", default=None,
                   help="--autopilot ardupilot: your own ArduPilot parameter file, laid over ArduPilot's and "
                        "the project's")
    p.add_argument("--ardupilot-fence", action="store_true",
                   help="--autopilot ardupilot: upload the chart as ArduRover's exclusion fence (polygons), plan "
                        "round it with its Dijkstra (OA_TYPE 2, OA_MARGIN_MAX = planner.safety_radius, FENCE_MARGIN = "
                        "half the hull's length) and give it "
                        "the scenario's route as given, which may cross the chart, instead of the global route")
    add_can_arguments(p)
    from hil.commands.autopilot import add_gcs_arguments

    add_gcs_arguments(p)
    p.add_argument("--instance", metavar="N", type=int, default=None,
                   help="run instance 0-99, as SITL's -I: ground-station ports + 10 N, autopilot.system_id + N, so "
                        "concurrent runs never share a ground station (default: the lowest instance no other "
                        "hil run on this machine holds, 0 when alone; it moves the configured ground-station ports, "
                        "not the ones given with --gcs, which stay as given unless --instance is given too)")
    p.add_argument("--demo", action="store_true",
                   help=f"constant-thrust demo controller (port {DEMO_CONTROLS[0]}, starboard {DEMO_CONTROLS[1]}) "
                        "instead of the autopilot; prints distance, final state, messages, wall time")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    if args.duration is None:
        args.duration = 60.0 if args.demo else 300.0
    if not 0 < args.duration < math.inf:
        raise ConfigError("--duration: must be a finite number > 0 of seconds")
    if args.speedup is not None and not 0 < args.speedup < math.inf:
        raise ConfigError("--speedup: must be a finite number > 0")
    if args.wall_timeout is not None and not 0 < args.wall_timeout < math.inf:
        raise ConfigError("--wall-timeout: must be a finite number > 0 of seconds")
    args.overrides = list(args.overrides) + can_overrides(args)
    if args.pipeline:
        if args.demo:
            raise UsageError("--pipeline is for the vessel computer's loop, not --demo")
        if args.speedup is not None and not args.wait_for_arm:
            raise ConfigError("--pipeline is a lockstep mode; drop --speedup (or add --wait-for-arm)")
        args.overrides.append("sim.lockstep_pipeline=true")
    if args.ardupilot_fence and args.autopilot != "ardupilot":
        raise UsageError("--ardupilot-fence is for --autopilot ardupilot (the vessel computer plans its global route)")
    if args.autopilot == "ardupilot":
        _check_ardupilot_options(args)
    from hil import instances, placement

    cpus = placement.parse(args.cpus)
    # Ground-station ports the user names (--gcs) are theirs: an instance found free shifts only the default
    # ones (as SITL's -I moves its default ports); --instance N shifts whatever the endpoints are.
    explicit_gcs = getattr(args, "gcs", None) is not None
    if explicit_gcs:
        from hil.commands.autopilot import gcs_overrides

        args.overrides += gcs_overrides(argparse.Namespace(gcs=args.gcs))
        args.gcs = None
    cfg = load_settings(args)  # fail here, with one line, on a bad configuration
    check_can(cfg, "hil run")
    if args.demo and cfg.can.actuators == "can":
        raise UsageError("--demo drives the simulator over MAVLink; --actuators can needs the autopilot (drop --demo)")
    if not args.demo:   # an unknown or bad scenario fails in one line before an instance is claimed or announced
        from hil import scenario as scenarios

        scenarios.load_spec(args.scenario)
    instance = None
    if cfg.gcs.endpoints and not args.demo:   # each concurrent run its own GCS ports and system id (hil.instances)
        instance = instances.claim(args.instance)
        try:
            if args.instance is not None or not explicit_gcs:
                args.overrides += instances.overrides(cfg.gcs.endpoints, cfg.autopilot.system_id, instance.n)
                cfg = load_settings(args)
        except BaseException:
            instance.close()
            raise
        if instance.n or args.instance is not None:
            progress(f"run: instance {instance.n}: ground stations at {', '.join(cfg.gcs.endpoints)}, "
                     f"system id {cfg.autopilot.system_id}")
    previous_term = signal.signal(signal.SIGTERM, _raise_terminated)
    try:
        if args.demo:
            if args.out:
                from hil.files import check_output_folder

                check_output_folder(Path(args.out), "--out")
            client = HilClient(system_id=cfg.autopilot.system_id, component_id=cfg.autopilot.component_id)
            return _run_loop(args, client, args.speedup is None)
        return _run_hil(args, cfg, cpus)
    finally:
        signal.signal(signal.SIGTERM, previous_term)
        if instance is not None:
            instance.close()


def _check_ardupilot_options(args: argparse.Namespace) -> None:
    from pathlib import Path

    """--autopilot ardupilot runs in plain lockstep over MAVLink actuators, without --demo, with a
    binary that runs."""
    for given, name in ((args.demo, "--demo"), (args.speedup is not None, "--speedup"), (args.pipeline, "--pipeline"),
                        (args.wait_for_arm, "--wait-for-arm"), (bool(args.gcs), "--gcs"),
                        (getattr(args, "actuators", None) == "can", "--actuators can")):
        if given:
            raise UsageError(f"--autopilot ardupilot runs ArduRover in lockstep; drop {name} (a ground station "
                             f"connects to ArduRover's TCP port, printed at the start)")
    from hil.ardupilot import find_sitl

    args.sitl = find_sitl(args.ardupilot_bin)   # before anything runs: a missing binary is one line
    if args.ardupilot_params is not None and not Path(args.ardupilot_params).is_file():
        raise UsageError(f"--ardupilot-params: no such file {args.ardupilot_params}")


def _default_wall_timeout(args: argparse.Namespace, paced: bool = False) -> float:
    if paced:  # a GCS session: lockstep paced to --speedup x wall time
        return args.duration / (args.speedup or 1.0) + 300.0
    if args.speedup is None:  # lockstep: usually faster than real time, slower on a busy machine
        return max(900.0, 3.0 * args.duration)
    return args.duration / args.speedup + 300.0


def _run_hil(args: argparse.Namespace, cfg: HilConfig, cpus: str | Placement = "auto") -> int:
    from pathlib import Path

    from hil import scenario as scenarios
    from hil.files import check_output_folder
    from hil.hilrun import REPO, RunOptions, run_loop

    spec = scenarios.load_spec(args.scenario)  # one-line error on an unknown or bad scenario
    if spec.kind != "fixed":
        raise UsageError(f"scenario {args.scenario!r} draws a new map per run; hil run needs a fixed "
                         f"scenario (random ones are for hil montecarlo)")
    seed = cfg.sim.seed if args.seed is None else args.seed
    stamp = time.strftime('%Y%m%d-%H%M%S')
    out = Path(args.out) if args.out else REPO / "runs" / f"{scenarios.folder_name(spec)}-seed{seed}-{stamp}"
    check_output_folder(out, "--out")
    overrides = list(args.overrides)
    if args.algorithm:
        overrides.append(f"planner.algorithm={json.dumps(args.algorithm)}")
    gcs_session = bool(args.wait_for_arm)
    if gcs_session:
        # A ground station attached: lockstep (repeatable) paced to --speedup x wall time, and the vehicle
        # stays up after the scenario's goal (a mission ends when the GCS says, or Ctrl-C / --duration).
        overrides.append(f"gcs.pace_speedup={float(args.speedup or 1.0)!r}")
    opts = RunOptions(scenario=args.scenario, lockstep=gcs_session or args.speedup is None,
                      speedup=args.speedup or 1.0, stop_at_goal=not gcs_session,
                      duration=args.duration, seed=seed, config=args.config, overrides=overrides, out=out,
                      on_progress=progress, plot=not args.no_plot,
                      extra_autopilot_args=_gcs_args(args), summary_on_interrupt=True, cpus=cpus,
                      wall_timeout=args.wall_timeout or _default_wall_timeout(args, gcs_session))
    opts.actuators = cfg.can.actuators
    pacing = f"lockstep paced to x{opts.speedup:g} wall time" if gcs_session else \
        ("lockstep" if opts.lockstep else f"real time x{opts.speedup:g}")
    who = "ArduRover SITL" if args.autopilot == "ardupilot" else f"actuators {cfg.can.actuators}"
    progress(f"run: scenario {args.scenario}, {pacing}, "
             f"{who}, seed {seed}, up to {args.duration:g} s simulated, run folder {out}")
    from hil.first_run import compile_notice

    ours = args.autopilot != "ardupilot"
    algorithm = str(args.algorithm or spec.planner.get("algorithm") or cfg.planner.algorithm) if ours else None
    notice = compile_notice("run", processes=3 if ours else 1, algorithm=algorithm)
    compiling: list[subprocess.Popen] = []
    if notice:
        progress(notice)
        if ours:
            from hil.warm_up import start as start_compiling

            # The vessel computer's kernels in parallel processes (hil/warm_up.py); its process waits
            # for them and loads the machine code from the cache.
            compiling = start_compiling(algorithm=algorithm)
    from hil.errors import RunFailed
    from hil.files import tidy_failed_start

    fresh = not out.exists()
    try:
        if args.autopilot == "ardupilot":
            from hil.ardupilot import run_ardupilot

            summary = run_ardupilot(opts, cfg, args.sitl, args.ardupilot_params, args.ardupilot_fence)
        else:
            summary = run_loop(opts, cfg)
    except RunFailed:
        tidy_failed_start(out, fresh)
        raise
    finally:
        for proc in compiling:   # done by now (the vessel computer waited for them), or stopped by Ctrl-C
            if proc.poll() is None:
                proc.terminate()
            proc.wait()
    emit(args, to_table(summary), human_summary(summary))
    if summary.outcome == "interrupted":
        progress(f"run: interrupted; summary in {out}")
        return 130
    return 0 if summary.reached_goal else 1


# Counters worth a human's attention: something was refused, lost, late, restarted or failed.
PROBLEM_COUNTER = re.compile(r"reject|refus|drop|overrun|restart|error|lost|loss|fail|stale|resend|timeout|reset|"
                             r"collision|fallback|malformed|invalid|overflow|kill", re.I)


def current_line(c: RunCurrent) -> str:
    """The current felt, planned with and estimated along the way: mean speed (m/s) and set (the direction
    it flows toward, degrees from north)."""
    def part(name: str, st: CurrentStats | None) -> str:
        if st is None:
            return f"{name} -"
        if math.hypot(st["mean_east_m_s"], st["mean_north_m_s"]) < 0.005:   # no mean direction to give
            return f"{name} {st['mean_speed_m_s']:.2f} m/s"
        set_deg = math.degrees(math.atan2(st["mean_east_m_s"], st["mean_north_m_s"])) % 360.0
        return f"{name} {st['mean_speed_m_s']:.2f} m/s set {set_deg:03.0f}"
    source = c["source"]
    if source.startswith("file "):
        source = "file " + Path(source[5:]).name
    return (f"current ({source}): " + ", ".join(
        (part("felt", c["felt"]), part("planner", c["planner_field"]), part("estimated", c["estimate"]))))


def human_summary(s: RunSummary) -> list[str]:
    """The run in at most 15 lines: outcome, time, clearance, errors, non-zero problem counters
    (everything else: --json and summary.json)."""
    from hil.console import MAX_LINES, clip, fmt, nonzero_counters, wrap_items

    def num(v: float | None, unit: str = "", digits: str = ".3g") -> str:
        return "-" if v is None else f"{v:{digits}}{unit}"

    outcome = "goal reached" if s.reached_goal else s.outcome.upper()
    if s.collision_time_s is not None:
        outcome += f" at {s.collision_time_s:.1f} s"
    lines = [f"outcome: {outcome} (scenario {s.scenario}, seed {s.seed}, {s.mode}, actuators {s.actuators})"]
    sim_t, wall = s.sim_time_s, s.wall_time_s
    speed_up = f" (x{sim_t / wall:.1f})" if wall > 0 else ""
    lines.append(f"time: {sim_t:.1f} s simulated in {wall:.1f} s wall" + speed_up)
    energy = s.energy_J
    lines.append(f"clearance: min {num(s.min_clearance_m, ' m')}; "
                 f"path {num(s.path_length_m, ' m', '.1f')}"
                 f"; energy {'-' if energy is None else f'{energy / 1000:.1f} kJ'}")
    from autopilot_bridge.tracking_stats import TrackingSummary

    tr, lat = s.tracking or TrackingSummary(frames=0), s.control_latency_ms
    lines.append(f"errors: navigation RMSE {num(s.navigation_rmse_m, ' m')}; cross-track RMS "
                 f"{num(tr.get('cross_track_rms_m'), ' m')} (max {num(tr.get('cross_track_max_m'), ' m')}); "
                 f"control latency p99 {num(None if lat is None else lat.p99, ' ms')}")
    lines.append(f"planning: {fmt(s.planning_cycles)} cycles, {fmt(s.plans_accepted)} plans accepted")
    if s.current is not None and s.current["source"] != "none":
        lines.append(current_line(s.current))
    if s.traffic is not None:
        shown = {k: v for k, v in s.traffic.items() if not isinstance(v, (dict, list)) and v is not None}
        lines.append("traffic: " + ", ".join(f"{k} {fmt(v)}" for k, v in list(shown.items())[:6]))
    problems = [c for c in nonzero_counters({k: v for k, v in to_table(s).items() if k not in ("collisions",)})
                if PROBLEM_COUNTER.search(c.partition("=")[0])]
    lines += wrap_items("counters (non-zero)", problems or ["none"], 3)
    if s.events:
        lines.append(f"events: {len(s.events)}, last: {fmt(s.events[-1])}")
    if s.plot_error:
        lines.append(f"plot: failed: {s.plot_error}")
    lines.append(f"folder: {s.run_folder} (summary.json has everything; --json prints it)")
    return [clip(line) for line in lines[:MAX_LINES]]


def _gcs_args(args: argparse.Namespace) -> list[str]:
    out = [a for spec in (args.gcs or []) for a in ("--gcs", spec)]
    return out + (["--wait-for-arm"] if args.wait_for_arm else [])


def _run_loop(args: argparse.Namespace, client: HilClient, lockstep: bool) -> int:
    proc = start_simulator(sim_command(args, client.port, lockstep), stdout=subprocess.PIPE, text=True)
    start = time.monotonic()
    end_usec = int(round(args.duration * 1e6))
    last_truth = None
    try:
        progress(f"run: simulator pid {proc.pid}, {'lockstep' if lockstep else f'real time x{args.speedup:g}'}, "
                 f"{args.duration:g} s simulated, demo controller {DEMO_CONTROLS}")
        next_report = start + 5.0
        while True:
            frame = client.next_frame(timeout=0.2 if not lockstep else FRAME_TIMEOUT_S, latest=not lockstep)
            if frame is None:
                if proc.poll() is not None:
                    break
                if lockstep or time.monotonic() - start > FRAME_TIMEOUT_S + args.duration / args.speedup:
                    raise RunFailed(f"no frame from the simulator for {FRAME_TIMEOUT_S:g} s")
                continue
            if "HIL_STATE_QUATERNION" in frame.messages:
                last_truth = frame.messages["HIL_STATE_QUATERNION"]
            if frame.time_usec is None:
                continue
            if frame.time_usec >= end_usec:
                break
            client.command(frame.time_usec, *DEMO_CONTROLS)
            if time.monotonic() > next_report:
                next_report += 5.0
                progress(f"run: t={frame.time_usec / 1e6:.1f} s")
        try:
            out, _ = proc.communicate(timeout=FRAME_TIMEOUT_S)
        except subprocess.TimeoutExpired:
            raise RunFailed("the simulator did not end after its last frame") from None
    finally:
        stop_process(proc)
        client.close()
    wall = time.monotonic() - start
    if proc.returncode != 0:
        raise RunFailed(f"the simulator exited with code {proc.returncode}")
    try:
        sim = json.loads(out.strip().splitlines()[-1])
    except (ValueError, IndexError):
        raise RunFailed("the simulator printed no summary") from None
    fs = sim["final_state"]
    summary = {
        "mode": "lockstep" if lockstep else "realtime",
        "seed": sim["seed"],
        "sim_time_s": sim["sim_time_s"],
        "wall_time_s": wall,
        "distance_travelled_m": sim["distance_m"],
        "final_position": {"x_north_m": fs["x"], "y_east_m": fs["y"], "lat_deg": fs["lat"], "lon_deg": fs["lon"]},
        "final_heading_deg": math.degrees(fs["psi"]) % 360.0,
        "final_speed_m_s": math.hypot(fs["u"], fs["v"]),
        "messages": {"frames_received": client.frames, "commands_sent": client.commands,
                     "frame_rejects": client.rejects, "simulator": sim["messages_sent"],
                     "simulator_commands_received": sim["commands_received"]},
        "last_truth_time_s": (last_truth.time_usec / 1e6) if last_truth is not None else None,
        "simulator": sim,
    }
    if args.out:   # the demo's run folder holds its summary (the loop's has its tlog, logs and plot too)
        from hil.files import write_json_atomic

        write_json_atomic(Path(args.out) / "summary.json", summary)
    emit(args, summary)
    return 0
