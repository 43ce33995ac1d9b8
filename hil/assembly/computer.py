"""Assembly of the vessel computer from a configuration and a scenario.

`hil autopilot` (and through it every `hil run`) calls :func:`build`; the command module only
parses arguments and runs the loop. Here the scenario, its planning world and the root of the
computer's own configuration (:func:`computer_settings`) are made from the HIL configuration; the
computer's package then opens its devices and builds it
(:func:`autopilot_bridge.assembly.build_computer`). The vessel computer's models come from the
configuration (e.g. the nominal surge model of eq. (5),
:meth:`autopilot_bridge.control.SurgeModel.from_hull`), never from the simulator's classes.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from hil.console import progress
from hil.errors import UsageError

if TYPE_CHECKING:
    from autopilot_bridge.assembly import ComputerSettings
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
    """The vessel computer's tuning, and the [vessel] figures it derives its own nominal model of eq. (5)
    from (never the simulator's classes)."""
    from autopilot_bridge.computer_setup import ComputerConfig, Hull

    v = cfg.vessel
    hull = Hull(v.m, v.rho, v.D, v.L, v.d_u, v.B_u, v.T_max, v.T_min)
    return ComputerConfig(cfg.autopilot, cfg.navigation, cfg.control, hull, cfg.battery_monitor)


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


def computer_settings(cfg: HilConfig, lockstep: bool) -> ComputerSettings:
    """The root of the vessel computer's configuration (:class:`autopilot_bridge.assembly.ComputerSettings`)
    from the HIL configuration: the one place that reads both sides of the HIL link."""
    from autopilot_bridge.assembly import ComputerSettings, SimulatorPeer

    peer = SimulatorPeer(cfg.link.system_id, cfg.link.component_id, cfg.traffic.truth_component_id,
                         cfg.sensors.compass.declination, max_time_step(cfg, lockstep))
    return ComputerSettings(computer_config(cfg), (cfg.geodesy.lat0, cfg.geodesy.lon0, cfg.geodesy.alt0), peer,
                            cfg.gcs, cfg.tracking, cfg.colregs, cfg.can, loss_seed=cfg.sim.seed + 7)


def build(cfg: HilConfig, scenario_name: str, lockstep: bool, planner_factory: str | None = None,
          sensors_from: str | None = None, route_file: str | None = None) -> tuple[Autopilot, HilLink]:
    """The autopilot and its parts from a configuration and a scenario (used by `hil run` too), with
    its UDP link to the simulator (the process reports and closes it; the autopilot sees a SensorLink).
    ``route_file``: the scenario's global route as `hil run` planned it (:func:`known_scenario`).
    The configuration goes down once, as the vessel computer's own root
    (:func:`autopilot_bridge.assembly.build_computer`)."""
    from autopilot_bridge.assembly import SetupError, build_computer
    from autopilot_bridge.local_planning import CycleInput
    from hil.warm_up import wait_for

    scen = known_scenario(cfg, scenario_name, route_file)
    settings, options = computer_settings(cfg, lockstep), run_options(cfg, lockstep)
    start = CycleInput(scen.start[0], scen.start[1], scen.start_heading, 0.0, 0)
    world = planning_world(cfg, scen)
    try:
        # wait_for: a first run compiles the planner's and the vessel computer's kernels in processes
        # of their own (hil/warm_up.py)
        return build_computer(settings, world, options, (scen.height, scen.width), start,
                              planner_factory=planner_factory, sensors_from=sensors_from, wait_for=wait_for,
                              log=progress)
    except SetupError as exc:
        raise UsageError(str(exc)) from None


def max_time_step(cfg: HilConfig, lockstep: bool) -> float:
    """Largest forward step (s) of sensor time the link accepts: lockstep advances exactly one IMU
    period per frame; real time skips lost datagrams (0.25 s: 25 in a row at 100 Hz)."""
    period = 1.0 / cfg.sensors.imu.rate_hz
    return 1.5 * period if lockstep else max(0.25, 3.0 * period)
