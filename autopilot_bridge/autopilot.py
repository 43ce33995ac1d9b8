"""The vessel computer's main loop (Figure 2 of the paper): sense, plan online, follow, control.

Event-driven by the simulator's sensor frames (one per IMU period). For each new frame:

1. navigation fusion (:mod:`autopilot_bridge.navigation`) of gyro, compass, GPS and DVL; range
   scans add the obstacles the chart lacks (:mod:`autopilot_bridge.obstacle_map`), and a local
   path that a newly sensed obstacle blocks is replanned at once;
2. every ``planning_period`` of simulated time, a local planning cycle is handed to the planner
   worker process (:mod:`autopilot_bridge.planning_worker`) from the position predicted at the
   end of the cycle's deadline; its answer is collected without blocking (real time), or at
   exactly ``planning_deadline`` later in simulated time (lockstep, where the simulator waits
   for us, so waiting costs no simulated time and runs are repeatable);
3. the active Rover mode (:mod:`autopilot_bridge.modes`) says where the thrust comes from; a mode
   that navigates follows the vehicle's route through the behaviour state machine
   (:mod:`autopilot_bridge.behaviour`): the newest valid local path (PLANNED); when there is none
   (planner failure, overrun with nothing usable, vessel inside an inflated obstacle), the reactive
   avoidance behaviour (:mod:`autopilot_bridge.reactive`) steers until planning succeeds again
   (FALLBACK); station keeping at the route's end (COMPLETE/RETURNING);
4. line-of-sight guidance, heading PID and speed pole placement, allocation to the two thrusters
   (:mod:`autopilot_bridge.control`), sent back as HIL_ACTUATOR_CONTROLS answering that frame,
   or as DroneCAN RawCommand (int14) when the actuator back-end is
   :class:`autopilot_bridge.can_actuators.CanActuators`.

Ground stations command it through :class:`autopilot_bridge.vehicle_api.VehicleApi` (arm, set_mode,
set_param, goto, ...), which this class implements, and read the frozen
:class:`autopilot_bridge.vehicle_api.VehicleStatus` it publishes with every frame.

A frame that repeats the last one (the simulator re-sends after a lost command) is answered with
the same command again. Sensor time jumping backwards means the simulator restarted: navigation
and planning start over.
"""

from __future__ import annotations

import logging
import math
import time
from array import array
from collections.abc import Callable
from dataclasses import replace
from typing import Any

import numpy as np

from autopilot_bridge import guidance
from autopilot_bridge.battery_monitor import FS_NONE, FS_RTL, BatteryMonitor
from autopilot_bridge.behaviour import STATION, Behaviour, BehaviourMachine
from autopilot_bridge.computer_setup import AutopilotStats, ComputerConfig, Devices, RunOptions
from autopilot_bridge.control import (
    HeadingPID,
    SpeedController,
    Thrust,
    allocate,
    clearance_speed_cap,
    heading_error_speed_cap,
)
from autopilot_bridge.guidance import GuidanceOutput, LineOfSight
from autopilot_bridge.hil_link import RangeScan, SensorFrame
from autopilot_bridge.local_planning import LocalPlan, World, map_to_ned_path
from autopilot_bridge.mission_commands import MissionCommand
from autopilot_bridge.modes import Mode
from autopilot_bridge.navigation import NavigationFilter, NavState
from autopilot_bridge.obstacle_map import SensedObstacles, path_blocked
from autopilot_bridge.onboard_status import OnboardSensors, OnboardStatus
from autopilot_bridge.parameters import Param, ParamTable
from autopilot_bridge.plan_commitment import CommitmentParams, keep_current
from autopilot_bridge.plan_handoff import PlanHandoff
from autopilot_bridge.reactive import ReactiveAvoidance
from autopilot_bridge.route_planning import RouteKeeper, check_mission_items
from autopilot_bridge.summary import AutopilotSummary, ControlLatency, NavigationCounts, WorkerStartup
from autopilot_bridge.tracking_stats import TrackingStats
from autopilot_bridge.vehicle import Vehicle, Waypoint
from autopilot_bridge.vehicle_api import Result, VehicleStatus
from common.dronecan_layout import RAW_COMMAND_MAX, quantize
from common.mavlink import MAV_TYPE as M

_logger = logging.getLogger(__name__)

SPEED_RANGE = (0.2, 3.0)   # m/s: speed set-points a GCS may give (3 m/s: the hull's top speed)


class Autopilot:
    """One vessel computer: owns its link, navigation filter, planner worker and controllers."""

    def __init__(self, config: ComputerConfig, world: World, devices: Devices, options: RunOptions,
                 log: Callable[[str], None] | None = None) -> None:
        params, propulsion = config.params, config.propulsion
        self.p, self.nav_params, self.control_params = params, config.nav, config.control
        self.prop, self.world, self.link, self.worker = propulsion, world, devices.link, devices.worker
        self.zero_thrust = allocate(0.0, 0.0, propulsion.B_u, propulsion.T_max, propulsion.T_min)
        self.telemetry = devices.telemetry
        self.traffic = devices.traffic  # autopilot_bridge.traffic_awareness.TrafficAwareness, or None
        # send_controls(time_usec, port, stdb): the HIL link itself, or CanActuators (service(), summary())
        self.actuators: Any = devices.actuators if devices.actuators is not None else devices.link
        self.int14_commands = options.int14_commands
        self.lockstep, self.seed = options.lockstep, options.seed
        wait_for_arm, pace_speedup = options.wait_for_arm, options.pace_speedup
        self.log = log or _logger.info
        guidance.warm_up()   # compiled before the first frame, not in it
        self.goal_ned = (world.goal[1], world.goal[0])
        self.reference_ned = map_to_ned_path(world.reference_path)
        from planner.gridmap import OccupancyGrid

        # The chart plus the obstacles sensed on the way (kept across simulator restarts: the
        # world did not change).
        self.grid = OccupancyGrid(world.occ.copy(), world.resolution)
        self.grid.polyline_free(np.zeros((0, 2)))   # plan acceptance's check compiled now, not in a frame
        self.sensed = SensedObstacles(world.occ, world.resolution, params.sensed_confirm_hits,
                                      params.sensed_explain_radius)
        # The global route (autopilot_bridge/route_planning.py): planned on this grid for every new
        # route, re-planned when sensed obstacles block it.
        self.routes = RouteKeeper(self.grid, world.params.safety_radius, log=self.log)
        self.routes.adopt(self.reference_ned)
        self.reactive = ReactiveAvoidance(self.grid, params.fallback_range, params.min_clearance, params.fallback_speed)
        self.stats = AutopilotStats()
        self.tracking = TrackingStats()
        self._waited = False
        self._plan_after_send: NavState | None = None   # a cycle to submit once this frame's command is out
        self.local_paths: list[dict[str, Any]] = []
        self._local_path: tuple[int, tuple[tuple[float, float], ...]] = (0, ())   # (len(local_paths), newest, NED)
        self.track = array("d")   # t, north, east, psi of the estimate at 10 Hz, flat (8 bytes a value)
        # What a ground station commands (autopilot_bridge.vehicle). Without one the scenario's
        # reference path is the mission and the boat starts armed in AUTO, as it always did.
        self.vehicle = Vehicle([Waypoint(float(n), float(e), params.goal_tolerance) for n, e in self.reference_ned],
                               armed=not wait_for_arm, mode=Mode.HOLD if wait_for_arm else Mode.AUTO,
                               scenario_route=self.reference_ned, default_radius=params.goal_tolerance)
        self.goal_radius = params.goal_tolerance
        self.planner_overrides: dict[str, float] = {}   # PlannerParams changed by a GCS (parameters)
        self._route_version = 0
        self._world_version = 0
        # Lockstep with a ground station attached: simulated time passes at most pace_speedup x wall
        # time (None: only while disarmed, at 1x), so that a person can follow the boat.
        self.pace_speedup = pace_speedup
        self._pace_anchor: tuple[float, float, float] | None = None
        self._status: VehicleStatus | None = None
        self.planning = PlanHandoff(self.worker, params, self.lockstep, self.seed, self.stats, self._event)
        # Telemetry's truth: sensor health and the pack (BATT_* parameters, low-battery failsafe).
        self.onboard = OnboardSensors(BatteryMonitor(config.battery, self._battery_failsafe, self._event))
        self._reset()
        self.param_table = ParamTable(self.parameters())

    # -- state ---------------------------------------------------------------------------------
    def _reset(self) -> None:
        self.nav = NavigationFilter(self.nav_params)
        self.heading_pid = HeadingPID(self.control_params)
        self.speed_ctl = SpeedController(self.control_params, self.prop.surge)
        self.behaviour = BehaviourMachine()
        self.los: LineOfSight | None = None
        self.next_plan_t = 0.0
        self.planning.reset()
        self.last_frame_usec: int | None = None
        self.last_command: Thrust | None = None
        self.last_t: float | None = None
        self.complete_t: float | None = None
        self.target = self.goal_ned
        self.speed_factor = 1.0
        self._path_invalid = False   # the followed path is blocked (sensed) or traffic asks for a new one
        if self.traffic is not None:
            self.traffic.reset()
        self.onboard.reset()

    def _event(self, t: float, text: str, warning: bool = False) -> None:
        self.stats.events.append((t, text))
        self.log(f"autopilot t={t:.2f}s: {text}")
        if self.telemetry is not None:
            self.telemetry.statustext(text, M.MAV_SEVERITY_WARNING if warning else M.MAV_SEVERITY_INFO)

    # -- navigation ----------------------------------------------------------------------------
    def _fuse(self, f: SensorFrame) -> None:
        t = f.t
        if f.gps is None and f.heading is not None and f.yaw_rate is not None:
            self.nav.update_heading_and_rate(t, f.heading, f.yaw_rate)   # nine frames of ten
        else:
            if f.heading is not None:
                self.nav.update_compass(t, f.heading)
            if f.gps is not None:
                g = f.gps
                lat = self.p.gps_latency
                # The fix is ``gps_latency`` old: carry it forward with its own velocity.
                self.nav.update_gps_position(t, g.north + g.vn * lat, g.east + g.ve * lat)
                self.nav.update_gps_velocity(t, g.vn, g.ve)
            if f.yaw_rate is not None:
                self.nav.update_gyro(t, f.yaw_rate)
        if f.dvl is not None:
            self.nav.update_dvl(t, *f.dvl)

    # -- planning ------------------------------------------------------------------------------
    def _submit_plan(self, s: NavState) -> None:
        self.planning.submit(s, self.sensed, self.traffic, self.world_update())

    def _submit_deferred_plan(self) -> None:
        """Submit the cycle :meth:`navigate` decided on. It waits until the frame's command has
        been sent: the request does not change the command, and handing it over (pickling, the pipe,
        a woken worker taking this core) cost ~2 ms on the frames that did it in lockstep."""
        s, self._plan_after_send = self._plan_after_send, None
        if s is not None:
            self._submit_plan(s)

    def _collect_plan(self, t: float) -> LocalPlan | None:
        plan, waited = self.planning.collect(t)
        self._waited = self._waited or waited
        return plan

    def _accept(self, plan: LocalPlan, s: NavState) -> bool:
        if plan.status == "none" or len(plan.path) < 2:
            self.stats.plans_rejected[f"status_{plan.status}"] += 1
            return False
        ned = map_to_ned_path(plan.path)
        # The path must start where the vessel now is (it was planned from a predicted position).
        if math.hypot(ned[0, 0] - s.x, ned[0, 1] - s.y) > 3.0 * self.p.lookahead:
            self.stats.plans_rejected["starts_too_far"] += 1
            return False
        if not self.grid.polyline_free(plan.path):
            self.stats.plans_rejected["collides"] += 1
            return False
        since = self.sensed.cells()[self.planning.sensed_at_submit:]
        if path_blocked(ned, since, self.grid.resolution, self.p.sensed_path_clearance):
            # Planned before these obstacles were seen: plan again at once.
            self.stats.plans_rejected["sensed_since_planning"] += 1
            self.next_plan_t = s.t
            return False
        if self._keeps_current_path(ned, s):
            self.stats.plans_rejected["other_way_round"] += 1
            return False
        self._path_invalid = False
        self.los = LineOfSight(ned, self.p.lookahead, acceptance_radius=self.p.goal_tolerance)
        self.target = (plan.subgoal[1], plan.subgoal[0])
        self.speed_factor = plan.speed_factor
        self.stats.plans_accepted += 1
        self.local_paths.append({"t": s.t, "cycle": plan.cycle, "status": plan.status,
                                 "path_ned": ned[:: max(1, len(ned) // 200)].round(3).tolist()})
        return True

    def _keeps_current_path(self, ned: np.ndarray, s: NavState) -> bool:
        """Plan commitment: stay on the followed path rather than swing round the other side of an
        obstacle (autopilot_bridge/plan_commitment.py) - unless it is blocked, traffic is being
        planned for, the followed path is not an exact one, or the vessel is off it by more than the
        look-ahead."""
        if (self.behaviour.state is not Behaviour.PLANNED or self.los is None or self._path_invalid
                or self.planning.traffic_planned):
            return False
        if self.local_paths and self.local_paths[-1]["status"] != "exact":
            # The followed path stopped short of its subgoal (the tree found no way there): it may
            # lead into a dead end, such as along a mole the reference path crosses. No commitment.
            return False
        ahead = self.los.path[self.los.index:]
        if float(np.min(np.hypot(ahead[:, 0] - s.x, ahead[:, 1] - s.y))) > self.p.lookahead:
            return False
        p = self.p
        return keep_current(ahead, ned, self.grid.occ, self.grid.resolution,
                            CommitmentParams(p.commit_compare_length, p.commit_min_remaining, p.commit_shortcut_ratio))

    # -- one frame -----------------------------------------------------------------------------
    def on_frame(self, f: SensorFrame, received_at: float) -> None:
        """Handle one new sensor frame and answer it with a thruster command."""
        t = f.t
        if self.last_frame_usec is not None and f.time_usec <= self.last_frame_usec:
            if (self.last_frame_usec - f.time_usec) * 1e-6 > self.p.sim_restart_gap:
                self.stats.simulator_restarts += 1
                self._event(t, "simulator restarted: navigation and planning start over")
                self.worker.cancel("simulator restarted")  # its answer would be for the old world
                self._reset()
            else:
                self.stats.duplicate_frames += 1
                if f.time_usec == self.last_frame_usec and self.last_command is not None:
                    self._send(f.time_usec, self.last_command, received_at)
                return
        self.stats.frames += 1
        dt = 0.0 if self.last_t is None else t - self.last_t
        self.last_t, self.last_frame_usec = t, f.time_usec
        self._fuse(f)
        s = self.nav.state()
        self.onboard.on_frame(f, self.nav.stats.updates, s is not None)
        if s is None:
            self._send(f.time_usec, self.zero_thrust, received_at)
            return
        if self.behaviour.state is Behaviour.WAITING:
            self.behaviour.to(Behaviour.IDLE)      # navigation is ready
            self.next_plan_t = t
        if f.scan is not None and self.p.sensed_obstacles:
            self._sense(t, f.scan, s)
        if self.traffic is not None:
            texts, replan = self.traffic.on_frame(t, s, self.link.take_ais(), self.telemetry)
            for text in texts:
                self._event(t, text)
            if replan and self.behaviour.state not in STATION:
                self.next_plan_t = t  # a new encounter: plan now, not at the next period
                self._path_invalid = True
        if self.stats.frames % 10 == 0:  # the estimated track at 10 Hz, for the run's plot
            self.track.extend((t, s.x, s.y, s.psi))

        self.vehicle.update(s.x, s.y, t)
        self._apply_route(t)
        v = self.vehicle
        # The active mode decides where the thrust comes from (autopilot_bridge.modes); disarmed: none.
        cmd = v.active.output(self, v, s, dt) if v.armed else self.idle()
        if self.lockstep and (self.pace_speedup is not None or not v.armed):
            self._pace(t, self.pace_speedup if (self.pace_speedup is not None and v.armed) else 1.0)
        else:
            self._pace_anchor = None
        self._send(f.time_usec, cmd, received_at)
        self._submit_deferred_plan()
        self._publish(t, s, cmd)

    # -- Driver (autopilot_bridge.modes): where a mode's thrust comes from -------------------------
    def idle(self) -> Thrust:
        """Thrusters at zero (disarmed, HOLD, a mode without a route)."""
        self.behaviour.pause()
        return self.zero_thrust

    def manual(self, stick: tuple[float, float, float] | None) -> Thrust:
        """MANUAL_CONTROL x (surge) and r (yaw), each -1..1, given at wall time stick[2]; zero when older than 1 s."""
        self.behaviour.pause()
        if stick is None or time.monotonic() - stick[2] > 1.0:
            return self.zero_thrust
        x, r = stick[0], stick[1]
        tau_u = x * 2.0 * (self.prop.T_max if x >= 0 else -self.prop.T_min)
        tau_r = r * 0.5 * (self.prop.T_max - self.prop.T_min) * self.prop.B_u
        return allocate(tau_u, tau_r, self.prop.B_u, self.prop.T_max, self.prop.T_min)

    def navigate(self, s: NavState, dt: float) -> Thrust:
        """Follow the vehicle's route: plan online, follow the local path or avoid reactively, and keep
        station at its end."""
        t = s.t if self.last_t is None else self.last_t
        b = self.behaviour
        if b.state is Behaviour.IDLE:     # back under control: the controllers start from the present state
            b.resume()
            self._reset_controllers(s)
        if b.state not in STATION and math.hypot(self.goal_ned[0] - s.x, self.goal_ned[1] - s.y) <= self.goal_radius:
            b.to(Behaviour.COMPLETE)
            v = self.vehicle
            if v.mode == Mode.AUTO:
                v.finish()
                if v.complete:
                    self.complete_t = t
                    self._event(t, "mission complete: final goal reached")
            else:
                self.complete_t = t
                self._event(t, f"{v.mode.name}: destination reached, holding")
        if b.state in STATION:
            return self._station_keep(s, dt)
        plan = self._collect_plan(t)
        if plan is not None:
            if self._accept(plan, s):
                if b.to(Behaviour.PLANNED):
                    self._event(t, f"following local path (cycle {plan.cycle}, {plan.status})")
            elif self.los is None:
                self._to_fallback(t, f"no valid local path ({plan.reason or plan.status})")
        if self.planning.pending_since is None and t + 1e-9 >= self.next_plan_t:
            self.next_plan_t = t + self.p.planning_period
            self._plan_after_send = s   # submitted by on_frame once the command is out
        preview = max(self.p.lookahead, 3.0 * self.speed_setpoint())  # ~3 s of travel
        following = b.state is Behaviour.PLANNED and self.los is not None
        guidance = self.los.update(s.x, s.y, preview) if following and self.los is not None else None
        if guidance is not None and guidance.finished and \
                math.hypot(self.goal_ned[0] - s.x, self.goal_ned[1] - s.y) > self.p.goal_tolerance:
            self._to_fallback(t, "local path finished before a new one arrived")
            guidance = None
        return self._control(s, dt, guidance)

    def speed_setpoint(self) -> float:
        """m/s along the path: DO_CHANGE_SPEED's until the mode changes, else ``cruise_speed``."""
        if self.vehicle.speed is None:
            return self.p.cruise_speed
        return min(max(self.vehicle.speed, SPEED_RANGE[0]), SPEED_RANGE[1])  # a mission item's, unchecked

    def _publish(self, t: float, s: NavState | None, cmd: Thrust | None) -> None:
        """The frame's frozen status, handed to the ground-station link."""
        v = self.vehicle
        for text, warning in v.take_notes():   # the mission executor's and the modes' messages
            self._event(t, text, warning)
        n_paths = len(self.local_paths)
        if self._local_path[0] != n_paths:   # a new local path: its tuple once, not every frame
            last = self.local_paths[-1]["path_ned"] if self.local_paths else ()
            self._local_path = (n_paths, tuple((float(n), float(e)) for n, e in last))
        status = VehicleStatus(
            t=t, armed=v.armed, mode=v.mode, mode_flags=v.active.flags, behaviour=self.behaviour.state, nav=s,
            home=v.home, mission_count=len(v.mission), mission_current=v.current, mission_complete=v.complete,
            speed_setpoint=self.speed_setpoint(),
            thrust=None if cmd is None else (float(cmd.port_cmd), float(cmd.stdb_cmd)),
            local_paths=n_paths, local_path=self._local_path[1],
            reached=tuple(v.take_reached()), changed=v.changed)
        v.changed = False
        self._status = status
        if self.telemetry is not None:
            self.telemetry.on_frame(status)

    # -- ground-station hooks ---------------------------------------------------------------------
    def _apply_route(self, t: float) -> None:
        """Follow a new global reference path (mission upload, AUTO/RTL/GUIDED entered), atomically."""
        r = self.vehicle.route
        if r is None or r.version == self._route_version:
            return
        self._route_version = r.version
        self.reference_ned = self.routes.set_route(r.path)   # legs of any length: routed on the chart
        self.goal_ned = (float(r.path[-1][0]), float(r.path[-1][1]))
        self.goal_radius = r.goal_radius
        self.target = self.goal_ned
        self.los = None
        self.behaviour.new_route()
        self.complete_t = None
        self.planning.route_changed()   # whatever the worker is planning now is for the old route
        self.next_plan_t = t
        self._world_version += 1

    def world_update(self) -> Any:
        """What the planner worker must use instead of the World it started with (None: nothing changed)."""
        if self._world_version == 0:   # no route, re-planned route or parameter since the start
            return None
        from autopilot_bridge.local_planning import WorldUpdate

        ref = self.reference_ned[:, ::-1].copy()          # NED -> map (x east, y north)
        return WorldUpdate(self._world_version, (float(ref[-1][0]), float(ref[-1][1])), ref,
                           dict(self.planner_overrides))

    def set_planner_override(self, name: str, value: float) -> None:
        self.planner_overrides[name] = value
        self._world_version += 1

    # -- command API (autopilot_bridge.vehicle_api.VehicleApi) ------------------------------------
    def _position(self) -> tuple[float, float] | None:
        st = self._status
        return None if st is None else st.position

    def status(self) -> VehicleStatus | None:
        """The newest frame's status (None before the first navigation fix)."""
        return self._status

    def arm(self, on: bool) -> Result:
        if on and self._position() is None:
            return Result(False, "arm: no navigation fix yet", temporary=True)
        return Result(*self.vehicle.arm(on))

    def set_mode(self, mode: Mode) -> Result:
        return Result(*self.vehicle.set_mode(mode, self._position()))

    def set_param(self, name: str, value: float) -> Result:
        return Result(*self.param_table.set(name, value))

    def goto(self, north: float, east: float) -> Result:
        return Result(*self.vehicle.reposition((float(north), float(east)), self._position()))

    def set_speed(self, speed: float) -> Result:
        p = self.param_table.get("CRUISE_SPEED")
        assert p is not None  # declared by parameters()
        if not math.isfinite(speed) or not p.lo <= speed <= p.hi:
            return Result(False, f"speed {speed:g} m/s outside {p.lo:g}..{p.hi:g}")
        self.vehicle.speed = float(speed)
        return Result(True, f"speed {speed:g} m/s")

    def start_mission(self, first: int) -> Result:
        if not self.vehicle.armed:
            return Result(False, "mission start: not armed")
        return Result(*self.vehicle.mission_start(first, self._position()))

    def set_mission_current(self, seq: int) -> Result:
        ok = self.vehicle.set_current(seq, self._position())
        return Result(ok, "" if ok else f"no mission item {seq}")

    def replace_mission(self, commands: tuple[MissionCommand, ...]) -> None:
        self.vehicle.replace_mission(commands, self._position())

    def mission(self) -> tuple[MissionCommand, ...]:
        return self.vehicle.mission

    def check_mission(self, items: tuple[Any, ...],
                      to_ned: Callable[[float, float], tuple[float, float]]) -> tuple[int, int, str] | None:
        return check_mission_items(items, to_ned, self.grid, self.world.params.safety_radius, self._position())

    def manual_input(self, x: float, r: float, wall_time: float) -> None:
        self.vehicle.manual = (x, r, wall_time)

    def record_event(self, text: str) -> None:
        self.stats.events.append((self.last_t or 0.0, text))

    def esc_telemetry(self) -> list[dict[str, Any]]:
        esc = getattr(self.actuators, "esc_telemetry", None)
        return esc() if callable(esc) else []

    def onboard_status(self) -> OnboardStatus:
        """Sensor health, the GPS receiver's account of itself and the pack, as of the newest frame."""
        return self.onboard.status()

    def _battery_failsafe(self, action: int) -> None:
        """BATT_FS_LOW_ACT's action when the battery monitor's failsafe triggers: RTL (Hold where RTL
        cannot be entered, e.g. without home) or Hold; nothing while disarmed or for action 0."""
        if action == FS_NONE or not self.vehicle.armed:
            return
        position = self._position()
        if action == FS_RTL and self.vehicle.set_mode(Mode.RTL, position)[0]:
            return
        self.vehicle.set_mode(Mode.HOLD, position)

    def parameters(self) -> list[Param]:
        """The tunables this vessel computer owns (the GCS parameter service lists them)."""

        def set_ap(key: str) -> Callable[[float], None]:
            def f(v: float) -> None:
                changes: dict[str, Any] = {key: v}  # a float field of AutopilotParams named by the parameter
                self.p = replace(self.p, **changes)  # AutopilotParams.__post_init__ checks deadline < period
            return f

        def set_ctl(key: str) -> Callable[[float], None]:
            def f(v: float) -> None:
                self.control_params = replace(self.control_params, **{key: v})
                self.heading_pid.p = self.control_params
                self.speed_ctl.p = self.control_params
            return f

        def planner(key: str) -> Callable[[], float]:
            return lambda: float(self.planner_overrides.get(key, getattr(self.world.params, key)))

        def set_radius(v: float) -> None:
            self.vehicle.default_radius = v
            self.vehicle.executor.default_radius = v

        period = self.p.planning_period
        return [
            Param("PLN_DEADLINE", lambda: self.p.planning_deadline, set_ap("planning_deadline"), 0.05, 0.95 * period,
                  "hard deadline of one local planning cycle", "s"),
            Param("PLN_PERCEPT_RAD", planner("perceptual_radius"),
                  lambda v: self.set_planner_override("perceptual_radius", v), 5.0, 200.0,
                  "radius of the perceptual domain (33 m in section 4.2)", "m"),
            Param("PLN_PNG_PROB", planner("png_probability"),
                  lambda v: self.set_planner_override("png_probability", v), 0.0, 1.0,
                  "probability of sampling the PNG node (section 3.2)"),
            Param("CRUISE_SPEED", lambda: self.p.cruise_speed, set_ap("cruise_speed"), *SPEED_RANGE,
                  "speed set-point along the local path (3 m/s: the hull's top speed)", "m/s"),
            Param("HDG_KP", lambda: self.control_params.heading_kp, set_ctl("heading_kp"), 0.0, 1000.0,
                  "heading PID proportional gain", "N m/rad"),
            Param("HDG_KI", lambda: self.control_params.heading_ki, set_ctl("heading_ki"), 0.0, 200.0,
                  "heading PID integral gain", "N m/(rad s)"),
            Param("HDG_KD", lambda: self.control_params.heading_kd, set_ctl("heading_kd"), 0.0, 500.0,
                  "heading PID derivative gain", "N m s/rad"),
            Param("SPD_BANDWIDTH", lambda: self.control_params.speed_bandwidth, set_ctl("speed_bandwidth"), 0.05, 5.0,
                  "speed loop natural frequency", "rad/s"),
            Param("WP_RADIUS", lambda: self.vehicle.default_radius, set_radius, 0.5, 50.0,
                  "acceptance radius of items that give none (and of RTL/GUIDED)", "m"),
            *self.onboard.battery.parameters(),
        ]

    def _pace(self, t: float, speedup: float) -> None:
        """Lockstep with a person watching: let simulated time pass no faster than ``speedup`` x wall time.

        A boat waiting for its operator (``--wait-for-arm``) drifts with the current; at lockstep
        speed (~15x) a minute at the ground station would be a quarter of an hour adrift. Armed, a
        GCS session runs at ``pace_speedup`` (``hil run --speedup``, default 1)."""
        now = time.monotonic()
        if self._pace_anchor is None or self._pace_anchor[2] != speedup:
            self._pace_anchor = (t, now, speedup)
            return
        ahead = (t - self._pace_anchor[0]) / speedup - (now - self._pace_anchor[1])
        if ahead > 0.0:
            time.sleep(min(ahead, 0.1))
            self._waited = True  # a paced frame measures the pacing, not the control loop

    def _sense(self, t: float, scan: RangeScan, s: NavState) -> None:
        """Add a range scan's new obstacles to the map; replan at once if they are near the path ahead."""
        new = self.sensed.add_scan(scan.bearings, scan.ranges, s.x, s.y, s.psi, scan.sector_width)
        if len(new) == 0:
            return
        self.grid.mark(new)
        replanned = self.routes.on_sensed(new, (s.x, s.y))
        if replanned is not None:
            self.reference_ned = replanned
            self._world_version += 1
            self._event(t, "sensed obstacle on the global route: route re-planned")
        if self.behaviour.state is Behaviour.PLANNED and self.los is not None:
            ahead = self.los.path[self.los.index:]
            if path_blocked(ahead, new, self.grid.resolution, self.p.sensed_path_clearance):
                self.stats.sensed_replans += 1
                self._event(t, "sensed obstacle near the local path: replanning")
                self.next_plan_t = t
                self._path_invalid = True

    def _to_fallback(self, t: float, why: str) -> None:
        if self.behaviour.to(Behaviour.FALLBACK):
            self.stats.fallback_activations += 1
            self._event(t, f"reactive avoidance engaged: {why}")
        self.los = None

    def _control(self, s: NavState, dt: float, g: GuidanceOutput | None) -> Thrust:
        if g is not None and self.los is not None:
            # LOS gives the course to steer; the hull must point the drift angle beta = atan2(v, u)
            # (current, sway in turns) away from it. Uncompensated, each cycle's new path (starting
            # where the vessel is) forgave the drift, and a cross-current set the boat onto walls.
            psi_ref, u_ref = g.heading - s.drift_angle(self.p.min_turn_speed), self.speed_setpoint() * self.speed_factor
            self.tracking.add(g.cross_track, psi_ref, s.psi)
            r_ref = max(s.u, 0.0) * g.curvature   # the path turns at u kappa: feed it forward
            # Slow down for sharp turns ahead so the yaw rate they need (u kappa) stays within reach.
            if g.curvature_ahead > 1e-6:
                u_ref = min(u_ref, max(self.p.min_turn_speed, self.p.max_turn_rate / g.curvature_ahead))
            u_ref = min(u_ref, self._near_obstacle_speed(s))
            u_ref = min(u_ref, heading_error_speed_cap(psi_ref - s.psi, self.p.turn_in_place_angle,
                                                        self.p.min_turn_speed, math.inf))
            if g.remaining < 2.0 * self.p.lookahead and self.los.path[-1].tolist() == list(self.goal_ned):
                u_ref = max(0.5, self.speed_setpoint() * g.remaining / (2.0 * self.p.lookahead))
        else:
            a = self.reactive.command(s.x, s.y, s.psi, self.target)
            psi_ref, u_ref, r_ref = a.heading, a.speed, 0.0
        return self._drive(s, dt, psi_ref, u_ref, r_ref)

    def _drive(self, s: NavState, dt: float, psi_ref: float, u_ref: float, r_ref: float = 0.0) -> Thrust:
        """Heading (rad, with yaw-rate feed-forward r_ref rad/s) and speed (m/s) set-points to thrust."""
        tau_r = self.heading_pid.update(psi_ref, s.psi, s.r, dt, r_ref)
        tau_u = self.speed_ctl.update(u_ref, s.u, s.v, s.r, dt)
        return allocate(tau_u, tau_r, self.prop.B_u, self.prop.T_max, self.prop.T_min)

    def _reset_controllers(self, s: NavState) -> None:
        self.heading_pid.reset()
        self.speed_ctl.reset(s.u)

    def _near_obstacle_speed(self, s: NavState) -> float:
        """Speed cap (m/s) near obstacles: cruise beyond ``slow_clearance`` of the vessel's clearance
        (cell-centre distance on the chart plus sensed obstacles), ``min_turn_speed`` at the
        planner's safety radius. The cross-track error of a turn grows with speed; a path at the
        inflation's edge leaves the hull only safety radius - L/2 of it."""
        return clearance_speed_cap(self.grid.clearance_at(s.y, s.x), self.world.params.safety_radius,
                                   self.p.slow_clearance, self.p.min_turn_speed, self.p.cruise_speed)

    def _station_keep(self, s: NavState, dt: float) -> Thrust:
        """After the final goal. ``mission_done = "hold"``: thrusters off, the boat drifts.
        ``"loiter"`` (ArduPilot's LOITER for boats): drift while within ``loiter_radius`` of the goal;
        beyond it, steer straight back at ``loiter_speed`` until within half the radius. The way back
        is the water the boat has just drifted across, so it needs no planning."""
        d = math.hypot(self.goal_ned[0] - s.x, self.goal_ned[1] - s.y)
        route = self.vehicle.route
        loiter = self.p.mission_done == "loiter" or (route is not None and route.loiter)
        b = self.behaviour
        if not loiter or d <= 0.5 * self.p.loiter_radius or \
                (b.state is Behaviour.COMPLETE and d <= self.p.loiter_radius):
            b.to(Behaviour.COMPLETE)
            return self.zero_thrust
        if b.to(Behaviour.RETURNING):
            self._reset_controllers(s)
        psi_ref = math.atan2(self.goal_ned[1] - s.y, self.goal_ned[0] - s.x)
        return self._drive(s, dt, psi_ref, min(self.p.loiter_speed, max(0.3, 0.5 * d)))

    def _send(self, time_usec: int, cmd: Thrust, received_at: float) -> None:
        port, stdb = cmd.port_cmd, cmd.stdb_cmd
        if self.int14_commands:  # the ESCs' resolution on either back-end: both paths drive the same thrust
            port, stdb = quantize(port) / RAW_COMMAND_MAX, quantize(stdb) / RAW_COMMAND_MAX
        self.actuators.send_controls(time_usec, port, stdb)
        self.last_command = cmd
        self.stats.commands += 1
        if not self._waited:
            self.stats.latency_ms.add((time.perf_counter() - received_at) * 1e3)
        self._waited = False

    # -- loop ----------------------------------------------------------------------------------
    def run(self, should_stop: Callable[[], bool], poll_s: float = 0.05) -> None:
        """Serve sensor frames until ``should_stop()``; the planner is watched between frames too."""
        busy = self.link.busy
        while not should_stop():
            if busy is not None:
                # While the worker plans, wait without polling: in lockstep the worker shares this CPU and
                # gets it only while the vessel computer sleeps (hil/placement.py, docs/performance.md).
                busy.hold(self.planning.pending_since is not None)
            frames = self.link.receive(timeout=poll_s)
            received_at = time.perf_counter()
            for f in frames:
                try:
                    self.on_frame(f, received_at)
                except (ArithmeticError, ValueError, np.linalg.LinAlgError) as exc:
                    self._numeric_fault(f, received_at, exc)
            if not frames and not self.lockstep and self.worker.watchdog():
                self._event(self.last_t or 0.0, "planner overran its deadline: worker killed and restarted")
                self.planning.pending_since = None
            if self.telemetry is not None:
                self.telemetry.service()
            if self.actuators is not self.link:
                self.actuators.service()

    def _numeric_fault(self, f: SensorFrame, received_at: float, exc: BaseException) -> None:
        """A numeric error escaped a frame (docs/security.md): stop the thrusters for this frame,
        count it, and restart navigation, which re-initialises on the next GPS fix."""
        self._submit_deferred_plan()   # if the fault came after navigate() decided to plan
        self.link.rejects["control_numeric_fault"] += 1
        self._event(f.t if math.isfinite(f.t) else 0.0, f"numeric fault ({type(exc).__name__}): stopped, "
                    "navigation restarts")
        self.nav = NavigationFilter(self.nav_params)
        self.last_frame_usec = f.time_usec
        self._send(f.time_usec, self.zero_thrust, received_at)

    def summary(self) -> AutopilotSummary:
        lat = self.stats.latency_ms
        w = self.worker.stats
        return AutopilotSummary(
            mode=self.behaviour.state.value,
            vehicle_mode=self.vehicle.mode.name,
            mission_complete=self.complete_t is not None,
            complete_time_s=self.complete_t,
            frames=self.stats.frames,
            duplicate_frames=self.stats.duplicate_frames,
            commands_sent=self.stats.commands,
            planning_cycles=self.stats.planning_cycles,
            plans_accepted=self.stats.plans_accepted,
            plans_rejected=dict(self.stats.plans_rejected),
            deadline_overruns=w.overruns + w.killed,
            worker_kills=w.killed,
            worker_restarts=w.restarts,
            worker_startup_s=WorkerStartup(count=len(w.startup_s),
                                           max=round(max(w.startup_s), 3) if w.startup_s else None),
            plans_skipped_worker_starting=w.not_ready_rejections,
            fallback_activations=self.stats.fallback_activations,
            tracking=self.tracking.summary(),
            simulator_restarts=self.stats.simulator_restarts,
            navigation=NavigationCounts(updates=dict(self.nav.stats.updates), rejected=dict(self.nav.stats.rejected),
                                        position_resets=self.nav.stats.position_resets),
            sensed_obstacles={**self.sensed.summary(), "replans": self.stats.sensed_replans},
            link_rejects=dict(self.link.rejects),
            truth_messages_ignored=self.link.truth_ignored,
            control_latency_ms=ControlLatency(p50=lat.percentile(50) or 0.0, p99=lat.percentile(99) or 0.0,
                                              max=max(lat.max, 0.0), frames=lat.count),
            lockstep_planner_waits=self.stats.planner_waits,
            lockstep_planner_wait_ms_max=max(self.stats.planner_wait_ms, default=0.0),
            lockstep_planner_wait_ms_total=round(sum(self.stats.planner_wait_ms), 3),
            events=tuple(f"{t:.2f}s {e}" for t, e in self.stats.events),
            can=self.actuators.summary() if self.actuators is not self.link else None,
            traffic=None if self.traffic is None else self.traffic.summary(),
        )
