"""`hil sim`: run the simulator process alone (truth, sensors, MAVLink over UDP)."""

from __future__ import annotations

import argparse
import json
import os
import signal
from typing import TYPE_CHECKING

from common import connection
from common.readiness import wait_for_start
from hil.commands.arg_types import receiving, sending
from hil.commands.can_options import add_can_arguments, can_overrides, check_can
from hil.console import emit, load_settings, progress
from hil.errors import ConfigError, UsageError
from hil.processes import freeze_heap

if TYPE_CHECKING:
    from simulator.traffic import ShipSpec


def add_parser(sub: argparse._SubParsersAction, parents: list[argparse.ArgumentParser]) -> None:
    p = sub.add_parser(
        "sim", parents=parents,
        help="run the USV simulator alone (HIL_SENSOR/HIL_GPS/HIL_STATE_QUATERNION out, "
             "HIL_ACTUATOR_CONTROLS in)",
        description="Run the 3-DOF USV simulator of Wen et al. (2019) eqs. (2)-(6) with the current of "
                    "eq. (13). It sends one datagram per IMU period (HIL_SENSOR, plus HIL_GPS and "
                    "HIL_STATE_QUATERNION when due; MAVLink 2) to every --state-to destination, from the "
                    "--commands-on socket, and applies the newest HIL_ACTUATOR_CONTROLS received there "
                    "(controls[0] port, controls[1] starboard, in [-1, 1]). Ends after --duration "
                    "simulated seconds or on SIGINT/SIGTERM, printing its summary.",
        epilog="Options given here override the [sim] and [link] configuration keys.",
    )
    p.add_argument("--state-to", metavar="HOST:PORT", action="append", type=sending, default=None,
                   help="destination of the sensor/truth datagrams, HOST:PORT or udpout:HOST:PORT; repeatable "
                        "(default: link.state_to = 127.0.0.1:14560)")
    p.add_argument("--commands-on", metavar="HOST:PORT", type=receiving, default=None,
                   help="UDP address to receive HIL_ACTUATOR_CONTROLS on, HOST:PORT or udpin:HOST:PORT (udp: "
                        "alike); port 0 picks a free port (default: link.commands_on = 127.0.0.1:14561)")
    p.add_argument("--commands-from", metavar="HOST:PORT|learn", default=None,
                   help="take HIL_ACTUATOR_CONTROLS only from this source address ('learn': from the address "
                        "of the first valid command); commands must also carry autopilot.system_id and "
                        "autopilot.component_id (default: any address)")
    p.add_argument("--lockstep", action="store_true", default=None,
                   help="advance exactly one IMU period per HIL_ACTUATOR_CONTROLS whose time_usec equals "
                        "the current frame's, instead of following the wall clock (default: sim.lockstep = false)")
    p.add_argument("--duration", metavar="SECONDS", type=float, default=None,
                   help="simulated seconds to run; 0 runs until SIGINT/SIGTERM (default: sim.duration = 60 s)")
    p.add_argument("--seed", type=int, default=None,
                   help="seed of every random process: sensor noise, GPS events, waves (default: sim.seed = 1)")
    p.add_argument("--speedup", metavar="N", type=float, default=None,
                   help="real-time mode: simulated seconds per wall-clock second (default: sim.speedup = 1)")
    p.add_argument("--scenario", metavar="NAME", default=None,
                   help="start where `hil run` would on this scenario (configs/scenarios/NAME.toml or a .toml "
                        "path): its start position and heading, its current, its true obstacle map (chart plus "
                        "uncharted obstacles) for the range sensor, and its ship traffic. Pair it with `hil autopilot "
                        "--scenario NAME` (same --lockstep or not, same --seed) for the loop by hand; --set and the "
                        "options below still override it (default: none: sim.initial, no obstacles, no traffic)")
    p.add_argument("--world", metavar="FILE.npz", default=None,
                   help="the true obstacle map the range sensor scans: an .npz with 'occ' (bool rows x cols, "
                        "row = north / resolution, column = east / resolution) and 'resolution' (m), as "
                        "`hil run` writes it to the run folder as world.npz; without it no OBSTACLE_DISTANCE is sent")
    p.add_argument("--traffic", metavar="SOURCE", default=None,
                   help="ship traffic to sail and report by AIS_VESSEL (settings in [traffic]): a scenario "
                        "name or .toml file with [[traffic]] tables, or a .json list of such tables "
                        "(default: no traffic)")
    p.add_argument("--start-fd", type=int, default=None, metavar="FD",
                   help="set up, then wait until the parent writes one byte 'g' to this inherited file "
                        "descriptor before the first frame (end of file: exit without running); how `hil run` "
                        "starts the simulator beside the autopilot")
    p.add_argument("--can-record", default=None, help=argparse.SUPPRESS)  # hil soak: RawCommand apply times (.npz)
    add_can_arguments(p)
    p.set_defaults(func=run)


def config_overrides(args: argparse.Namespace) -> list[str]:
    """The command-line options as ``--set`` overrides (validated by the configuration loader)."""
    out = []
    if args.state_to is not None:
        out.append("link.state_to=" + json.dumps(args.state_to))
    if args.commands_on is not None:
        out.append("link.commands_on=" + json.dumps(args.commands_on))
    if args.lockstep:
        out.append("sim.lockstep=true")
    if args.duration is not None:
        out.append(f"sim.duration={float(args.duration)!r}")
    if args.seed is not None:
        out.append(f"sim.seed={int(args.seed)}")
    if args.speedup is not None:
        out.append(f"sim.speedup={float(args.speedup)!r}")
    return out + can_overrides(args)


def run(args: argparse.Namespace) -> int:
    from common.udp import UdpEndpoint
    from simulator.core import SimulatorCore
    from simulator.rangefinder import WorldMap
    from simulator.server import SimulatorServer

    source = getattr(args, "commands_from", None)
    if source not in (None, "learn"):
        try:
            connection.parse(source, connection.SEND_UDP)
        except ValueError as exc:
            raise UsageError(f"--commands-from: {exc}") from None
    world = None
    traffic: tuple[ShipSpec, ...] = ()
    if getattr(args, "scenario", None):
        from hil import scenario as scenarios

        base = load_settings(args)  # the user's configuration, validated before the scenario is read
        spec = scenarios.load_spec(args.scenario)
        if spec.kind != "fixed":
            raise UsageError(f"--scenario {args.scenario}: draws a new map per run; hil sim needs a fixed scenario")
        scen = scenarios.instance(spec, None, base.current, geodesy=base.geodesy)
        args.overrides = scenarios.simulator_overrides(scen, base.current) + list(args.overrides)
        world = WorldMap(scen.truth_occ(), scen.resolution)
        traffic = tuple(scen.traffic)
    start_fd = getattr(args, "start_fd", None)
    if start_fd is not None:
        try:
            os.fstat(start_fd)
        except (OSError, OverflowError, ValueError):
            raise UsageError(f"--start-fd {start_fd}: not an open file descriptor") from None
    args.overrides = list(args.overrides) + config_overrides(args)
    cfg = load_settings(args)
    check_can(cfg, "hil sim (a process of its own)")
    if args.world is not None:
        try:
            world = WorldMap.load(args.world)
        except (OSError, KeyError, ValueError) as exc:
            raise UsageError(f"--world {args.world}: not a world map ({exc})") from None
    if getattr(args, "traffic", None):
        from hil.scenario import load_traffic

        traffic = load_traffic(args.traffic)
    try:
        core = SimulatorCore(cfg, world, traffic)
        check_covers = getattr(core.current, "check_covers", None)   # a current file: its time span
        if check_covers is not None and cfg.sim.duration > 0:
            check_covers(t=(0.0, cfg.sim.duration))
    except ValueError as exc:
        raise ConfigError(str(exc)) from None
    try:
        endpoint = UdpEndpoint(cfg.link.commands_on, cfg.link.state_to)
    except ValueError as exc:
        raise UsageError(str(exc)) from None
    esc = None
    if cfg.can.actuators == "can":
        from common.can_params import open_bus
        from simulator.esc import EscBank, kernel_filters

        try:
            esc = EscBank(open_bus(cfg.can, can_filters=kernel_filters(cfg.can)), cfg.can, cfg.esc, core.vessel)
            if args.can_record:
                esc.applied_times.start(spill_to=args.can_record)
        except ValueError as exc:
            endpoint.close()
            raise UsageError(str(exc)) from None
    try:
        server = SimulatorServer(core, endpoint, lockstep=cfg.sim.lockstep, duration=cfg.sim.duration,
                                 speedup=cfg.sim.speedup, lockstep_resend=cfg.sim.lockstep_resend,
                                 progress=progress, esc=esc, can_lockstep_wait=cfg.can.lockstep_wait,
                                 command_source=source, busy_poll=cfg.sim.lockstep_busy_poll,
                                 pipeline=cfg.sim.lockstep_pipeline)
    except ValueError as exc:
        endpoint.close()
        if esc is not None:
            esc.bus.shutdown()
        raise UsageError(str(exc)) from None
    previous = {sig: signal.signal(sig, lambda *_: server.stop()) for sig in (signal.SIGINT, signal.SIGTERM)}
    host, port = endpoint.address
    mode = ("lockstep, pipelined" if server.pipeline else "lockstep") if cfg.sim.lockstep else \
        f"real time x{cfg.sim.speedup:g}"
    progress(f"sim: commands on {host}:{port}, state to {', '.join(cfg.link.state_to)}, {mode}, "
             f"duration {cfg.sim.duration:g} s, seed {cfg.sim.seed}")
    try:
        if not wait_for_start(start_fd, lambda: server.stopped):
            progress("sim: not started (the parent closed --start-fd or a signal came first)")
            return 0
        freeze_heap()
        summary = server.run()
    finally:
        for sig, handler in previous.items():
            signal.signal(sig, handler)
        endpoint.close()
        if esc is not None:
            esc.bus.shutdown()
            if args.can_record:
                esc.applied_times.save(args.can_record)
    summary["commands_on"] = f"{host}:{port}"
    try:
        emit(args, summary)
    except BrokenPipeError:  # the reader (e.g. a killed `hil run`) is gone: nothing left to tell
        pass
    return 0
