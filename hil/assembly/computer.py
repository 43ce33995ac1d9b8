"""Assembly of the vessel computer: its parts built from a configuration and a scenario.

`hil autopilot` (and through it every `hil run`) calls :func:`build`; the command module only
parses arguments and runs the loop. The vessel computer's models come from the configuration
(e.g. the nominal surge model of eq. (5), :meth:`autopilot_bridge.control.SurgeModel.from_hull`),
never from the simulator's classes.
"""

from __future__ import annotations

import multiprocessing
from typing import TYPE_CHECKING

from hil.console import progress
from hil.errors import UsageError

if TYPE_CHECKING:
    from autopilot_bridge.autopilot import Autopilot
    from autopilot_bridge.computer_setup import ComputerConfig, RunOptions
    from autopilot_bridge.hil_link import HilLink
    from autopilot_bridge.local_planning import World
    from hil.scenario import Scenario
    from hil.settings import HilConfig


def planning_world(cfg: HilConfig, scen: Scenario) -> World:
    """What the local planner gets once: the scenario's chart, goal and route, its current, the
    configuration's planner parameters with the scenario's own laid over them."""
    from autopilot_bridge.local_planning import World
    from hil import scenario as scenarios

    params = scenarios.planner_params(cfg.planner, scen.planner_overrides, f"scenario {scen.name}")
    online = scenarios.online_params(scen.online_overrides, f"scenario {scen.name}")
    return World(occ=scen.occ, resolution=scen.resolution, goal=(float(scen.goal[0]), float(scen.goal[1])),
                 reference_path=scen.reference_path, field=scen.planning_field(),
                 params=params, online=online, algorithm=params.algorithm)


def computer_config(cfg: HilConfig) -> ComputerConfig:
    """The vessel computer's tuning, and its nominal model of the hull: eq. (5) from the configuration,
    never the simulator's classes."""
    from autopilot_bridge.computer_setup import ComputerConfig, Propulsion
    from autopilot_bridge.control import SurgeModel

    hull = cfg.vessel
    propulsion = Propulsion(SurgeModel.from_hull(hull.m, hull.rho, hull.D, hull.L, hull.d_u), hull.B_u,
                            hull.T_max, hull.T_min)
    return ComputerConfig(cfg.autopilot, cfg.navigation, cfg.control, propulsion, cfg.battery_monitor)


def run_options(cfg: HilConfig, lockstep: bool) -> RunOptions:
    from autopilot_bridge.computer_setup import RunOptions

    return RunOptions(lockstep=lockstep, seed=cfg.sim.seed,
                      int14_commands=cfg.esc.int14_resolution or cfg.can.actuators == "can",
                      wait_for_arm=cfg.gcs.wait_for_arm,
                      pace_speedup=cfg.gcs.pace_speedup if cfg.gcs.wait_for_arm else None,
                      home_item=cfg.gcs.identity == "ardupilot")


def known_scenario(cfg: HilConfig, scenario_name: str, route_file: str | None = None) -> Scenario:
    """The scenario the vessel computer knows a priori, with its global route: planned here, or with
    ``route_file`` (`hil run`'s route.json, a :class:`hil.routing.PlannedRoute`) taken as planned there,
    so that a run plans it once. A file planned for another scenario is a one-line UsageError."""
    from hil import scenario as scenarios
    from hil.routing import RouteRequest, read_route

    scen = scenarios.load(scenario_name, cfg.current, cfg.planner.safety_radius, cfg.geodesy)
    if route_file is not None:
        scen.take_planned_route(read_route(route_file), f"--route {route_file}")
        progress(f"autopilot: global route from {route_file} ({len(scen.reference_path)} points), not planned here")
    elif isinstance(scen.route, RouteRequest):
        waypoints = len(scen.route.waypoints)
        progress(f"autopilot: planned the global route through {waypoints} waypoints "
                 f"({len(scen.reference_path)} points)")
    return scen


def build(cfg: HilConfig, scenario_name: str, lockstep: bool, planner_factory: str | None = None,
          sensors_from: str | None = None, route_file: str | None = None) -> tuple[Autopilot, HilLink]:
    """The autopilot and its parts from a configuration and a scenario (used by `hil run` too), with
    its UDP link to the simulator (the process reports and closes it; the autopilot sees a SensorLink).
    ``route_file``: the scenario's global route as `hil run` planned it (:func:`known_scenario`)."""
    from autopilot_bridge.autopilot import Autopilot
    from autopilot_bridge.computer_setup import Devices
    from autopilot_bridge.gcs.link import GcsLink
    from autopilot_bridge.hil_link import HilLink
    from autopilot_bridge.planning_worker import PlannerWorker
    from common.geodesy import LocalFrame

    scen = known_scenario(cfg, scenario_name, route_file)
    world = planning_world(cfg, scen)
    # What the parts take, derived here first: the configuration then only goes down.
    computer, options, time_step = computer_config(cfg), run_options(cfg, lockstep), max_time_step(cfg, lockstep)
    ap = cfg.autopilot
    geo = LocalFrame(cfg.geodesy.lat0, cfg.geodesy.lon0, cfg.geodesy.alt0)
    try:
        link = HilLink(ap.listen, ap.actuators_to, geo, declination=cfg.sensors.compass.declination,
                       system_id=ap.system_id, component_id=ap.component_id, send_loss=ap.send_loss,
                       recv_loss=ap.recv_loss, loss_seed=cfg.sim.seed + 7,
                       truth_component_id=cfg.traffic.truth_component_id,
                       sim_ids=(cfg.link.system_id, cfg.link.component_id), sensors_from=sensors_from,
                       max_time_step=time_step,
                       busy_poll=ap.lockstep_busy_poll if lockstep else 0.0, late_window=ap.sim_restart_gap,
                       realtime=not lockstep)
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
                            mirror_from=ap.telemetry_from,
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

    from autopilot_bridge.local_planning import CycleInput, LocalPlan, online_cycle_handler
    from hil.warm_up import wait_for

    t0 = _time.monotonic()
    wait_for("planner")   # a first run compiles the planner in a process of its own (hil/warm_up.py)
    warm_up = CycleInput(scen.start[0], scen.start[1], scen.start_heading, 0.0, 0)
    online_cycle_handler(world, warm_up)
    spent = _time.monotonic() - t0
    if spent > 1.0:
        progress(f"autopilot: planner compiled and warmed up in {spent:.1f} s (cached for next time)")
    # fork: a restarted worker inherits the world instead of receiving it pickled; with spawn the
    # parent blocks writing ~100 KB into a 64 KB pipe until the new interpreter has started, which
    # stalls the control loop on every watchdog restart.
    start_method = "fork" if "fork" in multiprocessing.get_all_start_methods() else "spawn"
    worker: PlannerWorker[CycleInput, LocalPlan]
    if planner_factory:
        worker = PlannerWorker(planner_factory, (), grace_s=ap.watchdog_grace, start_method=start_method)
    else:
        # Each (re)started worker warms up too (its first cycle would pay the fork's page faults).
        worker = PlannerWorker("autopilot_bridge.local_planning:online_cycle_handler", (world, warm_up),
                               grace_s=ap.watchdog_grace, start_method=start_method)
    from autopilot_bridge.traffic_awareness import TrafficAwareness

    traffic = TrafficAwareness(cfg.tracking, cfg.colregs, geo)  # AIS targets, COLREGs encounters
    wait_for("vessel-computer")   # the filter's, guidance's and obstacle map's kernels (hil/warm_up.py)
    autopilot = Autopilot(computer, world,
                          Devices(link, worker, telemetry, traffic=traffic, actuators=actuators),
                          options)
    telemetry.attach(autopilot.commands)
    return autopilot, link


def max_time_step(cfg: HilConfig, lockstep: bool) -> float:
    """Largest forward step (s) of sensor time the link accepts: lockstep advances exactly one IMU
    period per frame; real time skips lost datagrams (0.25 s: 25 in a row at 100 Hz)."""
    period = 1.0 / cfg.sensors.imu.rate_hz
    return 1.5 * period if lockstep else max(0.25, 3.0 * period)
