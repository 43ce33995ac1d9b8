"""`hil autopilot`: run the vessel computer alone, for HIL against a simulator or hardware."""

from __future__ import annotations

import argparse
import json
import os
import signal
import sys
from dataclasses import replace

from common.readiness import Ready, announce
from common.tables import to_table
from hil.commands.arg_types import receiving, sending
from hil.commands.can_options import add_can_arguments, can_overrides, check_can
from hil.console import emit, load_settings, progress
from hil.files import write_json_atomic
from hil.processes import freeze_heap
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
    p.add_argument("--route", metavar="FILE", default=None,
                   help="the scenario's global route as `hil run` planned it (route.json in its run folder), "
                        "so that it is not planned again; refused when planned for another scenario "
                        "(default: plan it here)")
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
    p.add_argument("--telemetry-from", metavar="HOST:PORT", type=receiving, default=None,
                   help="send those copies from this address, so that the recorder can take them from it alone "
                        "(default: autopilot.telemetry_from, any free port on 127.0.0.1)")
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
    if args.telemetry_from is not None:
        out.append("autopilot.telemetry_from=" + json.dumps(args.telemetry_from))
    out += gcs_overrides(args)
    if args.seed is not None:
        out.append(f"sim.seed={int(args.seed)}")
    if args.algorithm is not None:
        out.append("planner.algorithm=" + json.dumps(args.algorithm))
    return out + can_overrides(args)


def run(args: argparse.Namespace) -> int:
    from hil import numba_env

    numba_env.apply()   # before the vessel computer compiles or loads its kernels
    import numpy as np

    args.overrides = list(args.overrides) + _overrides(args)
    cfg = load_settings(args)
    check_can(cfg, "hil autopilot (a process of its own)")
    from hil.assembly import build

    autopilot, link = build(cfg, args.scenario, args.lockstep, args.planner_factory,
                            getattr(args, "sensors_from", None), args.route)
    stop = {"flag": False}
    if args.can_record and autopilot.can is not None:
        autopilot.can.sent_times.start(spill_to=args.can_record)

    def request_stop(*_: object) -> None:
        stop["flag"] = True

    previous = {sig: signal.signal(sig, request_stop) for sig in (signal.SIGINT, signal.SIGTERM)}
    host, port = link.address
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
    freeze_heap()
    try:
        autopilot.run(lambda: stop["flag"])
    finally:
        for sig, handler in previous.items():
            signal.signal(sig, handler)
        autopilot.worker.close()
        link_summary = link.summary()
        link.close()
        if autopilot.can is not None:
            autopilot.can.close()
            if args.can_record:
                autopilot.can.sent_times.save(args.can_record)
        if autopilot.telemetry is not None:
            autopilot.telemetry.close()
    summary = replace(
        autopilot.summary(),
        link=link_summary,  # refusals by reason, source address, kernel drops (docs/security.md)
        busy_poll=None if autopilot.link.busy is None else autopilot.link.busy.summary(),
        gcs=None if autopilot.telemetry is None else autopilot.telemetry.summary(),
        local_paths=tuple(autopilot.local_paths),
        estimated_track=tuple(map(tuple, np.frombuffer(autopilot.track, dtype=float).reshape(-1, 4).round(3).tolist())),
        sensed_cells=tuple(map(tuple, autopilot.keeper.sensed.cells().tolist())),
    )
    table = to_table(summary)
    written = True
    if args.summary_out:
        try:
            write_json_atomic(args.summary_out, table, private=bool(cfg.gcs.signing_key_file))
        except OSError as exc:   # a full disk: one line, the summary still goes to stdout (issue 31)
            print(f"autopilot: cannot write {args.summary_out}: {exc.strerror or exc}", file=sys.stderr)
            written = False
    if args.json:
        emit(args, table)
    else:
        emit(args, {k: v for k, v in table.items() if k not in summary.BULKY})
    return 0 if written else 1
