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

This class is the frame pipeline that runs those steps in order; the steps' parts are components of
their own, each owning its parameters (:mod:`autopilot_bridge.parameters`): the world keeper (the grid
with its sensed obstacles and fence, the global route, what the planner worker is told:
:mod:`autopilot_bridge.world_keeper`), the helm (step 3-4, :mod:`autopilot_bridge.helm`), plan
acceptance (:mod:`autopilot_bridge.plan_acceptance`), the planning hand-off
(:mod:`autopilot_bridge.plan_handoff`), station keeping, the vehicle's modes and mission
(:mod:`autopilot_bridge.vehicle`). Ground stations command it through
:class:`autopilot_bridge.vehicle_commands.VehicleCommands` (``commands``, the
:class:`autopilot_bridge.vehicle_api.VehicleApi`) and read the frozen
:class:`autopilot_bridge.vehicle_api.VehicleStatus` it publishes with every frame.

A frame that repeats the last one (the simulator re-sends after a lost command) is answered with
the same command again. Sensor time jumping backwards means the simulator restarted: navigation
and planning start over.
"""

from __future__ import annotations

import logging
import math
import time
import traceback
from array import array
from collections.abc import Callable
from pathlib import Path

import numpy as np

from autopilot_bridge import guidance
from autopilot_bridge.actuators import Actuators, MavlinkActuators
from autopilot_bridge.battery_monitor import FS_NONE, FS_RTL, BatteryMonitor
from autopilot_bridge.behaviour import STATION, Behaviour
from autopilot_bridge.computer_setup import AutopilotStats, ComputerConfig, Devices, Propulsion, RunOptions
from autopilot_bridge.control import HeadingPID, SpeedController, Thrust
from autopilot_bridge.course import Course
from autopilot_bridge.current_estimate import CurrentObserver
from autopilot_bridge.helm import Helm
from autopilot_bridge.hil_link import SensorFrame
from autopilot_bridge.local_planning import World, map_to_ned_path
from autopilot_bridge.modes import Mode
from autopilot_bridge.navigation import NavigationFilter, NavState
from autopilot_bridge.onboard_failsafes import OnboardFailsafes
from autopilot_bridge.onboard_status import OnboardSensors, OnboardStatus
from autopilot_bridge.parameters import ParamTable, bind
from autopilot_bridge.plan_acceptance import AcceptedPath, PlanAcceptance
from autopilot_bridge.plan_handoff import PlanHandoff
from autopilot_bridge.station_keeping import StationKeeper
from autopilot_bridge.summary import AutopilotSummary, ComputerCurrent, ControlLatency, NavigationCounts, WorkerStartup
from autopilot_bridge.vehicle import MIS_DONE_HOLD, MIS_DONE_LOITER, Vehicle, Waypoint
from autopilot_bridge.vehicle_api import VehicleStatus
from autopilot_bridge.vehicle_commands import VehicleCommands
from autopilot_bridge.world_keeper import WorldKeeper
from common.current_tally import CurrentTally
from common.dronecan_layout import RAW_COMMAND_MAX, quantize
from common.mavlink import MAV_TYPE as M
from planner.gridmap import OccupancyGrid

_logger = logging.getLogger(__name__)


class Autopilot:
    """One vessel computer's frame pipeline: sensors -> navigation -> planning -> helm -> thrusters."""

    def __init__(self, config: ComputerConfig, world: World, devices: Devices, options: RunOptions,
                 log: Callable[[str], None] | None = None, *, grid: OccupancyGrid) -> None:
        """``grid``: the chart's occupancy grid (a copy of ``world``'s), which the sensed obstacles are
        added to, built by the assembly."""
        params, propulsion = config.params, Propulsion.from_hull(config.hull)
        self.p, self.nav_params = params, config.nav
        self.world, self.link, self.worker = world, devices.link, devices.worker
        self.telemetry = devices.telemetry
        self.traffic = devices.traffic
        self.can = devices.actuators     # the DroneCAN back-end, or None
        self.actuators: Actuators = devices.actuators if devices.actuators is not None else MavlinkActuators(self.link)
        self.int14_commands = options.int14_commands
        self.lockstep, self.seed = options.lockstep, options.seed
        wait_for_arm, pace_speedup = options.wait_for_arm, options.pace_speedup
        self.log = log or _logger.info
        guidance.warm_up()   # compiled before the first frame, not in it
        safety = world.params.safety_radius
        reference_ned = map_to_ned_path(world.reference_path)
        # The chart plus the obstacles sensed on the way (kept across simulator restarts: the
        # world did not change).
        self.grid = grid
        self.stats = AutopilotStats()
        self.track = array("d")   # t, north, east, psi of the estimate at 10 Hz, flat (8 bytes a value)
        # What a ground station commands (autopilot_bridge.vehicle). Without one the scenario's
        # reference path is the mission and the boat starts armed in AUTO, as it always did.
        self.vehicle = Vehicle([Waypoint(float(n), float(e), params.goal_tolerance) for n, e in reference_ned],
                               armed=not wait_for_arm, mode=Mode.HOLD if wait_for_arm else Mode.AUTO,
                               scenario_route=reference_ned, default_radius=params.goal_tolerance,
                               wp_speed=params.cruise_speed,
                               mission_done=MIS_DONE_LOITER if params.mission_done == "loiter" else MIS_DONE_HOLD,
                               home_item=options.home_item)
        goal = (world.goal[1], world.goal[0])
        self.course = Course(goal_ned=goal, goal_radius=params.goal_tolerance, reference_ned=reference_ned,
                             target=goal)
        # Lockstep with a ground station attached: simulated time passes at most pace_speedup x wall
        # time (None: only while disarmed, at 1x), so that a person can follow the boat.
        self.pace_speedup = pace_speedup
        self._pace_anchor: tuple[float, float, float] | None = None
        self._status: VehicleStatus | None = None
        self._local_path: tuple[int, tuple[tuple[float, float], ...]] = (0, ())   # (paths accepted, newest, NED)
        self.planning = PlanHandoff(self.worker, params, self.lockstep, self.seed, self.stats, self._event,
                                    speed=self.vehicle.speed_setpoint)
        # The grid's sensed obstacles and fence, the global route over it, the planner's tuning
        # (autopilot_bridge/world_keeper.py).
        self.keeper = WorldKeeper(world, grid, params, self.vehicle, self.course, self.planning, self.stats,
                                  self._event, self.log)
        self.acceptance = PlanAcceptance(params, self.grid, self.keeper.sensed, self.planning, self.course, self.stats)
        self.station = StationKeeper(params.loiter_radius, params.loiter_speed,
                                     Thrust(0.0, 0.0, 0.0, 0.0, False), params.station_keeping)
        self._planner_current = self._field_prior(world)
        self.current = CurrentObserver(propulsion.surge, prior=self._planner_current)
        # The planner's field and this computer's estimate where the boat was (10 Hz), for the summary.
        self.current_seen = (CurrentTally(), CurrentTally())
        self.helm = Helm(params, propulsion, self.course, self.vehicle, self.grid, safety, self.planning,
                         self.acceptance, HeadingPID(config.control), SpeedController(config.control, propulsion.surge),
                         self.station, self.current, self._event, self._count_fallback)
        self.station.zero_thrust = self.helm.zero_thrust
        self.helm.fence_depth = self.keeper.geofence.depth
        self.nav: NavigationFilter   # built by _reset, as after every simulator restart
        # Telemetry's truth: sensor health and the pack (BATT_* parameters, low-battery failsafe).
        self.onboard = OnboardSensors(BatteryMonitor(config.battery, self._battery_failsafe, self._event))
        self.failsafes = OnboardFailsafes(self.vehicle, self._event)
        self._reset()
        # One table of every component's own declarations: the parameter service reads and writes them.
        self.param_table = ParamTable(bind(self.vehicle, self.planning, self.keeper.planner_tuning,
                                           self.helm.heading_pid, self.helm.speed_ctl, self.station,
                                           self.keeper.geofence,
                                           self.onboard.battery))
        self.commands = VehicleCommands(self.vehicle, self.grid, safety, self.param_table, self.actuators,
                                        lambda: self._status, self._record_event, self.keeper.geofence,
                                        self.keeper.fence_changed, onboard=self.onboard_status,
                                        current=lambda: self.current.velocity,
                                        coast_s=propulsion.surge.m11 / propulsion.surge.d_u)
        self.grid.polyline_free(np.zeros((0, 2)))   # plan acceptance's check compiled now, not in a frame

    @staticmethod
    def _field_prior(world: World) -> Callable[[float, float], tuple[float, float]] | None:
        """The planner's current field (map frame: x east, y north) as a prior, NED in and out."""
        field = world.field
        if field is None:
            return None

        def at(north: float, east: float) -> tuple[float, float]:
            vx, vy = field.at(east, north)
            return float(vy), float(vx)
        return at

    # -- state ---------------------------------------------------------------------------------
    def _reset(self) -> None:
        """Navigation and planning start over (a simulator restart); tuned parameters stay."""
        self.nav = NavigationFilter(self.nav_params)
        self.helm.heading_pid.reset()
        self.helm.speed_ctl.reset()
        self.current.reset()
        self.station.reset()
        self.course.restart()
        self.planning.reset()
        self.last_frame_usec: int | None = None
        self.last_command: Thrust | None = None
        self.last_t: float | None = None
        self.helm.last_t = None
        if self.traffic is not None:
            self.traffic.reset()
        self.onboard.reset()

    @property
    def local_paths(self) -> tuple[AcceptedPath, ...]:
        """The accepted local paths, for the run's record."""
        return tuple(self.acceptance.local_paths)

    def _event(self, t: float, text: str, warning: bool = False) -> None:
        self.stats.events.append((t, text))
        self.log(f"autopilot t={t:.2f}s: {text}")
        if self.telemetry is not None:
            self.telemetry.statustext(text, M.MAV_SEVERITY_WARNING if warning else M.MAV_SEVERITY_INFO)

    def _record_event(self, text: str) -> None:
        self.stats.events.append((self.last_t or 0.0, text))

    def _count_fallback(self) -> None:
        self.stats.fallback_activations += 1

    def onboard_status(self) -> OnboardStatus:
        """Sensor health, the GPS receiver's account of itself and the pack, as of the newest frame."""
        return self.onboard.status()

    def _battery_failsafe(self, action: int) -> None:
        """BATT_FS_LOW_ACT's action when the battery monitor's failsafe triggers: RTL, or hold station
        (LOITER, as the GCS failsafe's hold; also where RTL cannot be entered); nothing while disarmed or
        for action 0."""
        if action == FS_NONE or not self.vehicle.armed:
            return
        position = None if self._status is None else self._status.position
        if action == FS_RTL and self.vehicle.set_mode(Mode.RTL, position)[0]:
            return
        self.vehicle.set_mode(Mode.LOITER, position)

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
    def _submit_deferred_plan(self) -> None:
        """Submit the cycle the helm decided on. It waits until the frame's command has been sent: the
        request does not change the command, and handing it over (pickling, the pipe, a woken worker
        taking this core) cost ~2 ms on the frames that did it in lockstep."""
        s, self.helm.plan_due = self.helm.plan_due, None
        if s is not None:
            self.planning.submit(s, self.keeper.sensed, self.traffic, self.keeper.update())

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
        self.helm.last_t = t
        self._fuse(f)
        s = self.nav.state()
        self.onboard.on_frame(f, self.nav.stats.updates, s is not None)
        if s is not None:
            last = self.last_command
            self.current.update(s, 0.0 if last is None else last.port + last.stdb, dt)
        if s is None:
            self._send(f.time_usec, self.helm.zero_thrust, received_at)
            return
        c = self.course
        if c.behaviour.state is Behaviour.WAITING:
            c.behaviour.to(Behaviour.IDLE)      # navigation is ready
            c.next_plan_t = t
        if f.scan is not None and self.p.sensed_obstacles:
            self.keeper.sense(t, f.scan, s)
        if self.traffic is not None:
            texts, replan = self.traffic.on_frame(t, s, self.link.take_ais(), self.telemetry)
            for text in texts:
                self._event(t, text)
            if replan and c.behaviour.state not in STATION:
                c.next_plan_t = t  # a new encounter: plan now, not at the next period
                c.path_invalid = True
        if self.stats.frames % 10 == 0:  # the estimated track at 10 Hz, for the run's plot
            self.track.extend((t, s.x, s.y, s.psi))
            if self._planner_current is not None:
                self.current_seen[0].add(*self._planner_current(s.x, s.y))
            self.current_seen[1].add(*self.current.velocity)

        self.vehicle.update(s.x, s.y, t)
        self.keeper.check_fence(t, s)
        self.failsafes.check(s, c.behaviour.state)
        self.keeper.apply_route(t)
        v = self.vehicle
        # The active mode decides where the thrust comes from (autopilot_bridge.modes), after the keep-off guard
        # (autopilot_bridge.keep_off); disarmed: none.
        cmd = self.helm.keep_clear(s, dt) if v.armed else self.helm.idle()
        if cmd is None:
            cmd = v.active.output(self.helm, v, s, dt)
        if self.lockstep and (self.pace_speedup is not None or not v.armed):
            self._pace(t, self.pace_speedup if (self.pace_speedup is not None and v.armed) else 1.0)
        else:
            self._pace_anchor = None
        self._send(f.time_usec, cmd, received_at)
        self._submit_deferred_plan()
        self._publish(t, s, cmd)

    def _publish(self, t: float, s: NavState | None, cmd: Thrust | None) -> None:
        """The frame's frozen status, handed to the ground-station link."""
        v = self.vehicle
        for text, warning in v.take_notes():   # the mission executor's and the modes' messages
            self._event(t, text, warning)
        accepted = self.acceptance.local_paths
        if self._local_path[0] != len(accepted):   # a new local path: its tuple once, not every frame
            last = accepted[-1].path_ned if accepted else ()
            self._local_path = (len(accepted), tuple((float(n), float(e)) for n, e in last))
        status = VehicleStatus(
            t=t, armed=v.armed, mode=v.mode, mode_flags=v.active.flags, behaviour=self.course.behaviour.state, nav=s,
            home=v.home, mission_count=len(v.mission), mission_current=v.current, mission_complete=v.complete,
            speed_setpoint=v.speed_setpoint(),
            thrust=None if cmd is None else (float(cmd.port_cmd), float(cmd.stdb_cmd)),
            local_paths=len(accepted), local_path=self._local_path[1],
            reached=tuple(v.take_reached()), changed=v.changed)
        v.changed = False
        self._status = status
        if self.telemetry is not None:
            self.telemetry.on_frame(status)

    # -- pacing ----------------------------------------------------------------------------------
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
            self.helm.waited = True  # a paced frame measures the pacing, not the control loop

    def _send(self, time_usec: int, cmd: Thrust, received_at: float) -> None:
        port, stdb = cmd.port_cmd, cmd.stdb_cmd
        if self.int14_commands:  # the ESCs' resolution on either back-end: both paths drive the same thrust
            port, stdb = quantize(port) / RAW_COMMAND_MAX, quantize(stdb) / RAW_COMMAND_MAX
        self.actuators.send_controls(time_usec, port, stdb)
        self.last_command = cmd
        self.stats.commands += 1
        if not self.helm.waited:
            self.stats.latency_ms.add((time.perf_counter() - received_at) * 1e3)
        self.helm.waited = False

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
            self.actuators.service()
            for alarm in self.actuators.alarms():
                self._event(self.last_t or 0.0, alarm, warning=True)

    def _numeric_fault(self, f: SensorFrame, received_at: float, exc: BaseException) -> None:
        """A numeric error escaped a frame (docs/security.md): stop the thrusters for this frame,
        count it, and restart navigation, which re-initialises on the next GPS fix."""
        self._submit_deferred_plan()   # if the fault came after the helm decided to plan
        self.link.rejects["control_numeric_fault"] += 1
        frames = [fr for fr in traceback.extract_tb(exc.__traceback__) if "site-packages" not in fr.filename]
        where = frames[-1] if frames else None        # the deepest line of ours: where to look
        at = f" at {Path(where.filename).name}:{where.lineno}" if where is not None else ""
        self._event(f.t if math.isfinite(f.t) else 0.0, f"numeric fault ({type(exc).__name__}{at}: "
                    f"{str(exc)[:80]}): stopped, navigation restarts")
        self.nav = NavigationFilter(self.nav_params)
        self.last_frame_usec = f.time_usec
        self._send(f.time_usec, self.helm.zero_thrust, received_at)

    def summary(self) -> AutopilotSummary:
        lat = self.stats.latency_ms
        w = self.worker.stats
        return AutopilotSummary(
            mode=self.course.behaviour.state.value,
            vehicle_mode=self.vehicle.mode.name,
            mission_complete=self.course.complete_t is not None,
            complete_time_s=self.course.complete_t,
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
            tracking=self.helm.tracking.summary(),
            simulator_restarts=self.stats.simulator_restarts,
            navigation=NavigationCounts(updates=dict(self.nav.stats.updates), rejected=dict(self.nav.stats.rejected),
                                        position_resets=self.nav.stats.position_resets),
            sensed_obstacles={**self.keeper.sensed.summary(), "replans": self.stats.sensed_replans},
            link_rejects=dict(self.link.rejects),
            truth_messages_ignored=self.link.truth_ignored,
            control_latency_ms=ControlLatency(p50=lat.percentile(50) or 0.0, p99=lat.percentile(99) or 0.0,
                                              max=max(lat.max, 0.0), frames=lat.count),
            lockstep_planner_waits=self.stats.planner_waits,
            lockstep_planner_wait_ms_max=max(self.stats.planner_wait_ms, default=0.0),
            lockstep_planner_wait_ms_total=round(sum(self.stats.planner_wait_ms), 3),
            events=tuple(f"{t:.2f}s {e}" for t, e in self.stats.events),
            can=self.actuators.summary(),
            traffic=None if self.traffic is None else self.traffic.summary(),
            current=ComputerCurrent(planner_field=self.current_seen[0].stats(), estimate=self.current_seen[1].stats()),
        )
