"""`hil autopilot`: run the vessel computer alone, for HIL against a simulator or hardware."""

from __future__ import annotations

import argparse
import json
import multiprocessing
import os
import signal
import tempfile
from pathlib import Path

from common.readiness import Ready, announce
from hil.commands.can_options import add_can_arguments, can_overrides, check_can
from hil.commands.sim import receiving, sending
from hil.console import emit, load_settings, progress
from hil.errors import UsageError
from planner.params import ALGORITHM_NAMES


def _gcs_endpoint(text: str) -> str:
    from autopilot_bridge.gcs.transport import parse_endpoint

    if text == "none":
        return text
    try:
        parse_endpoint(text)
    except ValueError as exc:
        raise argparse.ArgumentTypeError(str(exc)) from None
    return text


def add_gcs_arguments(p: argparse.ArgumentParser) -> None:
    """--gcs and --wait-for-arm (shared by `hil autopilot` and `hil run`)."""
    p.add_argument("--gcs", metavar="CONNECTION", type=_gcs_endpoint, action="append", default=None,
                   help="ground-station endpoint as pymavlink's mavutil writes it, repeatable: udpout:HOST:PORT "
                        "(or plain HOST:PORT) sends to a GCS listening there (default: gcs.endpoints = "
                        "udpout:127.0.0.1:14550, as SITL); udpin:HOST:PORT (= udp:HOST:PORT) listens; "
                        "tcpin:HOST:PORT accepts TCP connections; tcp:HOST:PORT connects to a GCS's TCP server; "
                        "serial:DEVICE:BAUD is a telemetry radio (pyserial). Every GCS that talks is answered. "
                        "'none' turns the link off")
    p.add_argument("--wait-for-arm", action="store_true",
                   help="start disarmed in HOLD: a ground station uploads a mission (or keeps the scenario's), "
                        "arms and sets AUTO (custom mode 10) or sends MISSION_START. The vehicle stays up: at the "
                        "end of a mission it keeps station and takes the next one. In lockstep, simulated time "
                        "then passes at wall-clock speed (hil run: x --speedup) so a person can follow it")


def gcs_overrides(args: argparse.Namespace) -> list[str]:
    out = []
    if getattr(args, "gcs", None) is not None:
        eps = [] if args.gcs == ["none"] else [e for e in args.gcs if e != "none"]
        out.append("gcs.endpoints=" + json.dumps(eps))
    if getattr(args, "wait_for_arm", False):
        out.append("gcs.wait_for_arm=true")
    return out


def add_parser(sub: argparse._SubParsersAction, parents: list[argparse.ArgumentParser]) -> None:
    p = sub.add_parser(
        "autopilot", parents=parents,
        help="run the vessel computer alone: navigation, online DDRRT* planning, control over HIL MAVLink",
        description="Run the autopilot bridge: it receives HIL_SENSOR/HIL_GPS (and ODOMETRY for a DVL) on "
                    "--listen, fuses them in an EKF, plans local paths with the configured planner inside "
                    "the perceptual domain along the scenario's global reference path (a separate worker "
                    "process under a watchdog deadline), follows them with line-of-sight guidance, a heading "
                    "PID and pole-placement speed control, and answers every sensor frame with "
                    "HIL_ACTUATOR_CONTROLS to --actuators-to. Runs until SIGINT/SIGTERM, then prints its "
                    "summary.",
        epilog="Options given here override the [autopilot] configuration keys.",
    )
    p.add_argument("--scenario", default="harbour",
                   help="scenario whose map, reference path and current the vessel knows a priori "
                        "(configs/scenarios/NAME.toml; default: harbour)")
    p.add_argument("--listen", metavar="HOST:PORT", type=receiving, default=None,
                   help="where sensor frames arrive, HOST:PORT or udpin:HOST:PORT "
                        "(default: autopilot.listen = 127.0.0.1:14560)")
    p.add_argument("--actuators-to", metavar="HOST:PORT", type=sending, action="append", default=None,
                   help="where HIL_ACTUATOR_CONTROLS go, HOST:PORT or udpout:HOST:PORT; repeatable "
                        "(default: autopilot.actuators_to = 127.0.0.1:14561)")
    p.add_argument("--sensors-from", metavar="HOST:PORT", type=sending, default=None,
                   help="take sensor frames only from this source address, the simulator's socket (its "
                        "--commands-on; default: any address). Frames must also carry link.system_id and "
                        "link.component_id")
    p.add_argument("--telemetry-to", metavar="HOST:PORT", type=sending, action="append", default=None,
                   help="where a copy of all ground-station traffic in and out goes (a recorder); repeatable "
                        "(default: autopilot.telemetry_to, none)")
    add_gcs_arguments(p)
    p.add_argument("--lockstep", action="store_true",
                   help="the simulator runs in lockstep: plan on an iteration budget "
                        "(autopilot.lockstep_iterations) so runs are repeatable")
    p.add_argument("--seed", type=int, default=None, help="seed of the planner's sampling (default: sim.seed)")
    p.add_argument("--algorithm", choices=ALGORITHM_NAMES, default=None,
                   help="local planner (default: planner.algorithm = ddrrt-star)")
    p.add_argument("--summary-out", metavar="FILE", default=None,
                   help="also write the summary JSON to FILE (atomically) when stopping")
    p.add_argument("--ready-fd", type=int, default=None, metavar="FD",
                   help="write a one-line JSON readiness message to this inherited file descriptor once "
                        "serving, then close it (how `hil run` knows the autopilot is up)")
    p.add_argument("--planner-factory", default=None, help=argparse.SUPPRESS)  # tests: a planner double
    p.add_argument("--can-record", default=None, help=argparse.SUPPRESS)  # hil soak: RawCommand send times (.npz)
    add_can_arguments(p)
    p.set_defaults(func=run)


def _overrides(args: argparse.Namespace) -> list[str]:
    out = []
    if args.listen is not None:
        out.append("autopilot.listen=" + json.dumps(args.listen))
    if args.actuators_to is not None:
        out.append("autopilot.actuators_to=" + json.dumps(args.actuators_to))
    if args.telemetry_to is not None:
        out.append("autopilot.telemetry_to=" + json.dumps(args.telemetry_to))
    out += gcs_overrides(args)
    if args.seed is not None:
        out.append(f"sim.seed={int(args.seed)}")
    if args.algorithm is not None:
        out.append("planner.algorithm=" + json.dumps(args.algorithm))
    return out + can_overrides(args)


def _save_record(path: str, tids, times) -> None:
    import numpy as np

    np.savez(path, tid=np.frombuffer(tids, dtype=np.int8), at=np.frombuffer(times, dtype=float))


def write_json_atomic(path: str | Path, data: dict) -> None:
    """Write JSON to ``path`` via a temporary file and rename: never a half-written file."""
    from hil.console import to_json

    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=".tmp")
    try:
        with os.fdopen(fd, "w") as fh:
            fh.write(to_json(data) + "\n")
        os.replace(tmp, path)
    except BaseException:  # a full disk, an interrupt: never leave the temporary file behind
        try:
            os.unlink(tmp)
        except OSError:
            pass
        raise


def build(cfg, scenario_name: str, lockstep: bool, planner_factory: str | None = None,
          sensors_from: str | None = None):
    """The autopilot and its parts from a configuration and a scenario (used by `hil run` too)."""
    from autopilot_bridge.autopilot import Autopilot, Propulsion
    from autopilot_bridge.control import SurgeModel
    from autopilot_bridge.gcs.link import GcsLink
    from autopilot_bridge.hil_link import HilLink
    from autopilot_bridge.local_planning import World
    from autopilot_bridge.planning_worker import PlannerWorker
    from common.geodesy import LocalFrame
    from hil import scenario as scenarios
    from simulator.vessel import Vessel

    scen = scenarios.load(scenario_name, cfg.current, cfg.planner.safety_radius)
    params = scenarios.planner_params(cfg.planner, scen.planner_overrides, f"scenario {scen.name}")
    online = scenarios.online_params(scen.online_overrides, f"scenario {scen.name}")
    world = World(occ=scen.occ, resolution=scen.resolution, goal=tuple(scen.goal),
                  reference_path=scen.reference_path, field=scen.planning_field(),
                  params=params, online=online, algorithm=params.algorithm)
    vessel = Vessel(cfg.vessel)  # eq. (5): the vessel computer's nominal model of the same hull
    propulsion = Propulsion(SurgeModel(vessel.m11, vessel.m22, cfg.vessel.d_u), cfg.vessel.B_u,
                            cfg.vessel.T_max, cfg.vessel.T_min)
    ap = cfg.autopilot
    geo = LocalFrame(cfg.geodesy.lat0, cfg.geodesy.lon0, cfg.geodesy.alt0)
    try:
        link = HilLink(ap.listen, ap.actuators_to, geo, declination=cfg.sensors.compass.declination,
                       system_id=ap.system_id, component_id=ap.component_id, send_loss=ap.send_loss,
                       recv_loss=ap.recv_loss, loss_seed=cfg.sim.seed + 7,
                       truth_component_id=cfg.traffic.truth_component_id,
                       sim_ids=(cfg.link.system_id, cfg.link.component_id), sensors_from=sensors_from,
                       max_time_step=_max_time_step(cfg, lockstep))
    except ValueError as exc:
        raise UsageError(str(exc)) from None
    actuators = None
    if cfg.can.actuators == "can":
        from autopilot_bridge.can_actuators import CanActuators
        from common.can_params import open_bus

        try:
            actuators = CanActuators(open_bus(cfg.can), cfg.can, lockstep_token=link if lockstep else None)
        except ValueError as exc:
            link.close()
            raise UsageError(str(exc)) from None
    try:
        telemetry = GcsLink(cfg.gcs, ap.system_id, ap.component_id, geo, mirror_to=ap.telemetry_to,
                            chart_size=(scen.height, scen.width), log=progress)
    except ValueError as exc:
        link.close()
        if actuators is not None:
            actuators.close()
        raise UsageError(str(exc)) from None
    # Compile (first run on a machine: ~7 s) or load the planner's numba core here, once, before
    # the control loop starts: forked workers inherit it, so no planning cycle pays for it.
    # One real planning cycle from the start compiles everything a cycle uses (tree core, grid
    # kernels of pruning and smoothing).
    import time as _time

    from autopilot_bridge.local_planning import CycleInput, online_cycle_handler

    t0 = _time.monotonic()
    warm_up = CycleInput(scen.start[0], scen.start[1], scen.start_heading, 0.0, 0)
    online_cycle_handler(world, warm_up)
    spent = _time.monotonic() - t0
    if spent > 1.0:
        progress(f"autopilot: planner compiled and warmed up in {spent:.1f} s (cached for next time)")
    # fork: a restarted worker inherits the world instead of receiving it pickled; with spawn the
    # parent blocks writing ~100 KB into a 64 KB pipe until the new interpreter has started, which
    # stalls the control loop on every watchdog restart.
    start_method = "fork" if "fork" in multiprocessing.get_all_start_methods() else "spawn"
    if planner_factory:
        worker = PlannerWorker(planner_factory, (), grace_s=ap.watchdog_grace, start_method=start_method)
    else:
        # Each (re)started worker warms up too (its first cycle would pay the fork's page faults).
        worker = PlannerWorker("autopilot_bridge.local_planning:online_cycle_handler", (world, warm_up),
                               grace_s=ap.watchdog_grace, start_method=start_method)
    from autopilot_bridge.traffic_awareness import TrafficAwareness

    traffic = TrafficAwareness(cfg.tracking, cfg.colregs, geo)  # AIS targets, COLREGs encounters
    autopilot = Autopilot(ap, cfg.navigation, cfg.control, propulsion, world, link, worker, telemetry,
                          lockstep=lockstep, seed=cfg.sim.seed, traffic=traffic, actuators=actuators,
                          int14_commands=cfg.esc.int14_resolution or cfg.can.actuators == "can",
                          wait_for_arm=cfg.gcs.wait_for_arm,
                          pace_speedup=cfg.gcs.pace_speedup if cfg.gcs.wait_for_arm else None)
    telemetry.attach(autopilot)
    return autopilot


def _max_time_step(cfg, lockstep: bool) -> float:
    """Largest forward step (s) of sensor time the link accepts: lockstep advances exactly one IMU
    period per frame; real time skips lost datagrams (0.25 s: 25 in a row at 100 Hz)."""
    period = 1.0 / cfg.sensors.imu.rate_hz
    return 1.5 * period if lockstep else max(0.25, 3.0 * period)


def run(args: argparse.Namespace) -> int:
    import numpy as np

    args.overrides = list(args.overrides) + _overrides(args)
    cfg = load_settings(args)
    check_can(cfg, "hil autopilot (a process of its own)")
    autopilot = build(cfg, args.scenario, args.lockstep, args.planner_factory, getattr(args, "sensors_from", None))
    stop = {"flag": False}
    if args.can_record and autopilot.actuators is not autopilot.link:
        autopilot.actuators.record = True

    def request_stop(*_):
        stop["flag"] = True

    previous = {sig: signal.signal(sig, request_stop) for sig in (signal.SIGINT, signal.SIGTERM)}
    host, port = autopilot.link.address
    acts = (f"DroneCAN RawCommand on {cfg.can.interface}:{cfg.can.channel}" if cfg.can.actuators == "can"
            else "actuators to " + ", ".join(cfg.autopilot.actuators_to))
    gcs = autopilot.telemetry
    if gcs is not None and gcs.addresses:
        progress("autopilot: ground stations on " + ", ".join(
            f"{spec} (local {h}:{p})" for spec, (h, p) in zip(cfg.gcs.endpoints, gcs.addresses, strict=False)))
    progress(f"autopilot: listening on {host}:{port}, {acts}, "
             f"scenario {args.scenario}, {'lockstep' if args.lockstep else 'real time'}"
             f"{', waiting for a GCS to arm' if cfg.gcs.wait_for_arm else ''}")
    announce(args.ready_fd, Ready("autopilot", f"{host}:{port}", os.getpid()))
    try:
        autopilot.run(lambda: stop["flag"])
    finally:
        for sig, handler in previous.items():
            signal.signal(sig, handler)
        autopilot.worker.close()
        link_summary = autopilot.link.summary()
        autopilot.link.close()
        if autopilot.actuators is not autopilot.link:
            autopilot.actuators.close()
            if args.can_record:
                _save_record(args.can_record, autopilot.actuators.sent_tid, autopilot.actuators.sent_at)
        if autopilot.telemetry is not None:
            autopilot.telemetry.close()
    summary = autopilot.summary()
    summary["link"] = link_summary  # refusals by reason, source address, kernel drops (docs/security.md)
    if autopilot.telemetry is not None:
        summary["gcs"] = autopilot.telemetry.summary()
    summary["local_paths"] = autopilot.local_paths
    summary["estimated_track"] = np.frombuffer(autopilot.track, dtype=float).reshape(-1, 4).round(3).tolist()
    summary["sensed_cells"] = autopilot.sensed.cells().tolist()
    if args.summary_out:
        write_json_atomic(args.summary_out, summary)
    if args.json:
        emit(args, summary)
    else:
        emit(args, {k: v for k, v in summary.items() if k not in ("local_paths", "estimated_track", "sensed_cells")})
    return 0
