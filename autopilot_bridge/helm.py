"""The helm: where a mode's thrust comes from (:class:`autopilot_bridge.modes.Driver`).

Step 3 of :mod:`autopilot_bridge.autopilot`: thrusters at zero (disarmed, HOLD), the operator's sticks
(MANUAL), or navigation along the vehicle's route - the newest accepted local path under line-of-sight
guidance (PLANNED), the reactive avoidance behaviour when there is none (FALLBACK), station keeping at
the route's end - then heading PID and speed pole placement, allocated to the two thrusters (step 4).
Positions NED m, angles rad, speeds m/s over ground, times s of vehicle time.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable

from autopilot_bridge.angles import wrap_angle
from autopilot_bridge.behaviour import STATION, Behaviour, BehaviourMachine
from autopilot_bridge.computer_setup import Propulsion
from autopilot_bridge.config import AutopilotParams
from autopilot_bridge.control import (
    HeadingPID,
    SpeedController,
    Thrust,
    allocate,
    clearance_speed_cap,
    heading_error_speed_cap,
    stopping_speed_cap,
)
from autopilot_bridge.course import Course
from autopilot_bridge.current_estimate import CurrentObserver
from autopilot_bridge.guidance import GuidanceOutput
from autopilot_bridge.keep_off import MARGIN as CLEAR_MARGIN
from autopilot_bridge.keep_off import REACH as CLEAR_REACH
from autopilot_bridge.keep_off import KeepOff, clear_point
from autopilot_bridge.modes import Mode
from autopilot_bridge.navigation import NavState
from autopilot_bridge.plan_acceptance import PlanAcceptance
from autopilot_bridge.plan_handoff import PlanHandoff
from autopilot_bridge.reactive import ReactiveAvoidance
from autopilot_bridge.station_keeping import StationKeeper
from autopilot_bridge.tracking_stats import TrackingStats
from autopilot_bridge.vehicle import MIS_DONE_LOITER, Vehicle
from planner.gridmap import OccupancyGrid

AVOID_DECELERATION = 0.25     # m/s^2: as ARRIVAL_DECELERATION
AVOID_BRAKE_MARGIN = 0.1      # m/s over the limit: braking, the yaw moment gives way to the surge force
BRAKING_YAW_SHARE = 0.1       # of the reverse thrust as a yaw moment while braking: the hull stays along its way
AVOID_COURSE_SPEED = 0.3      # m/s over ground: above it the course over ground is checked too (below, noise)
AVOID_LOOKAHEAD = 24.0        # m: 3 m/s, the hull's top speed, stops within it (18 m + 2 s of lag)
BLOCKED_RUN = 1.0             # m of free water the set-point's way leaves: less, the way is blocked
CLEAR_RUN = 3.0               # m of free water along the set-point's way that ends the blockage
BLOCKED_SPEED = 0.2           # m/s: a set-point below it is no way to block (arrival, station keeping)
DRIFT_SPEED = 0.1             # m/s over ground: above it the course over ground counts (below, noise)
DRIFT_ANGLE = math.radians(35.0)   # rad between the course over ground and the way asked: set off it
DRIFT_LOOKAHEAD_S = 6.0       # s of the set ahead that are checked: the keeper's turn into the current takes 3-5 s
DRIFT_SURGE = 0.5             # m/s: above it the boat's own way carries it, which the surge limit governs
CELL_SLACK = 0.1              # m: a way along a wall that only crosses the chart's cell-centre steps is no blockage
BLOCKED_HOLD_S = 5.0          # s: a blockage keeps station at least this long (no flicker at its edge)
BLOCKED_TELL_S = 10.0         # s between two events of a blockage
RETREAT_RANGE = 2.0           # m: how far a blocked boat may move off to keep station clear of the obstacle
ARRIVAL_DECELERATION = 0.25   # m/s^2: half the speed reference model's limit (max_acceleration 0.5)
MANUAL_STICK_TIMEOUT_S = 1.0   # wall s: an older MANUAL_CONTROL is no stick (MANUAL then holds)


class Helm:
    def __init__(self, params: AutopilotParams, propulsion: Propulsion, course: Course, vehicle: Vehicle,
                 grid: OccupancyGrid, safety_radius: float, planning: PlanHandoff, acceptance: PlanAcceptance,
                 heading_pid: HeadingPID, speed_ctl: SpeedController, station: StationKeeper,
                 current: CurrentObserver, event: Callable[[float, str], None],
                 on_fallback: Callable[[], None]) -> None:
        self.p, self.prop, self.course, self.vehicle = params, propulsion, course, vehicle
        self.grid, self.safety_radius = grid, safety_radius
        self.planning, self.acceptance = planning, acceptance
        self.heading_pid, self.speed_ctl, self.station = heading_pid, speed_ctl, station
        self.current = current
        self.hold_clearance = 2.0 * safety_radius      # m: HOLD drifts no nearer to an obstacle or the fence
        self.avoid_clearance = 0.75 * safety_radius    # m: no speed that cannot stop before this clearance
        self.fence_depth: Callable[[float, float], float] = lambda _n, _e: math.inf
        self.last_safe: tuple[float, float] | None = None
        self._hold_point: tuple[float, float] = (0.0, 0.0)     # NED m: where HOLD keeps station (while holding)
        self.holding = False
        # The station keeper's state in HOLD (not the route's). From IDLE, since it goes to COMPLETE or RETURNING
        # at once: from WAITING that raised, every frame, and a HOLD near the quay drifted onto it (issue 31's
        # chaos GCS found it).
        self._hold_behaviour = BehaviourMachine(start=Behaviour.IDLE)
        self.blocked_at: tuple[float, float] | None = None   # NED m: where a blocked way keeps station
        self._blocked_behaviour = BehaviourMachine(start=Behaviour.IDLE)
        self._blocked_since = self._blocked_told = -math.inf   # s of vehicle time
        self.keep_off = KeepOff(grid, safety_radius, station, self._keeping_drive, lambda: self.current.velocity,
                                self.reset_controllers, event)
        self.reactive = ReactiveAvoidance(grid, params.fallback_range, params.min_clearance, params.fallback_speed)
        self.tracking = TrackingStats()
        self.zero_thrust = allocate(0.0, 0.0, propulsion.B_u, propulsion.T_max, propulsion.T_min)
        self._event, self._on_fallback = event, on_fallback
        self.waited = False                  # this frame waited for the planner (lockstep)
        self.plan_due: NavState | None = None   # a cycle to submit once this frame's command is out
        self.last_t: float | None = None

    # -- Driver ---------------------------------------------------------------------------------
    def idle(self) -> Thrust:
        """Thrusters at zero (disarmed, HOLD, a mode without a route)."""
        self.course.behaviour.pause()
        self.blocked_at = None
        self.keep_off.reset()
        return self.zero_thrust

    def keep_clear(self, s: NavState, dt: float) -> Thrust | None:
        """Armed, ahead of the mode: the keep-off guard's thrust (:mod:`autopilot_bridge.keep_off`), or None
        when the mode has the helm. A pilot at MANUAL's stick always has it."""
        v = self.vehicle
        if v.mode == Mode.MANUAL and self._stick_live(v.manual):
            self.keep_off.reset()
            return None
        return self.keep_off.command(s, dt)

    @staticmethod
    def _stick_live(stick: tuple[float, float, float] | None) -> bool:
        return stick is not None and time.monotonic() - stick[2] <= MANUAL_STICK_TIMEOUT_S

    def hold(self, s: NavState, dt: float) -> Thrust:
        """HOLD, armed: thrusters off and the boat drifts, as ArduRover's HOLD - while it is at least
        ``hold_clearance`` (twice the planner's safety radius) from every charted or sensed obstacle and
        as far inside the geofence. Nearer, it keeps station, so a current never sets it onto the rocks or
        across the fence (issue 33): near the fence at the last point that was that far inside it; near an
        obstacle where it is, or at the nearest point half a metre beyond the safety radius
        (:meth:`station_point`). Sent back to a last safe point 4 m off, the station keeper asked for more way
        than astern gives and turned bow first through 135 degrees while the current set it onto the
        breakwater (issue 31's chaos, in-process)."""
        self.course.behaviour.pause()
        self.blocked_at = None
        clearance = self.grid.clearance_at(s.y, s.x)
        safe = clearance >= self.hold_clearance and self.fence_depth(s.x, s.y) >= self.hold_clearance
        if safe:
            self.last_safe = (s.x, s.y)
            self.holding = False
            return self.zero_thrust
        if not self.holding:
            self.holding = True
            depth = self.fence_depth(s.x, s.y)
            self.station.reset()
            if depth < self.hold_clearance and self.last_safe is not None:
                self._hold_point, where = self.last_safe, "at the last safe point"
            else:
                self._hold_point, where = self.station_point((s.x, s.y)), "clear of it"
            self._event(s.t, f"{self.vehicle.mode.name}: {min(clearance, depth):.1f} m from an obstacle or the "
                        f"fence: keeping station {where}")
        return self.station.command(s, dt, self._hold_point, True, self._hold_behaviour, self._keeping_drive,
                                    self.current.velocity, lambda: self.reset_controllers(s))

    def manual(self, stick: tuple[float, float, float] | None, s: NavState, dt: float) -> Thrust:
        """MANUAL_CONTROL x (surge) and r (yaw), each -1..1, given at wall time stick[2]. Without a stick
        newer than ``MANUAL_STICK_TIMEOUT_S`` it is HOLD, as ArduRover's radio failsafe puts the boat in
        HOLD: here that drifts only while clear of obstacles and the fence, and keeps station nearer, so
        a ground station that selects MANUAL and sends nothing never leaves the boat to the current."""
        self.course.behaviour.pause()
        if stick is None or not self._stick_live(stick):
            return self.hold(s, dt)
        self.holding = False
        x, r = stick[0], stick[1]
        prop = self.prop
        tau_u = x * 2.0 * (prop.T_max if x >= 0 else -prop.T_min)
        tau_r = r * 0.5 * (prop.T_max - prop.T_min) * prop.B_u
        return allocate(tau_u, tau_r, prop.B_u, prop.T_max, prop.T_min)

    def navigate(self, s: NavState, dt: float) -> Thrust:
        """Follow the vehicle's route: plan online, follow the local path or avoid reactively, and keep
        station at its end."""
        c, p = self.course, self.p
        t = s.t if self.last_t is None else self.last_t
        b = c.behaviour
        if b.state is Behaviour.IDLE:     # back under control: the controllers start from the present state
            b.resume()
            self.reset_controllers(s)
        if b.state not in STATION and math.hypot(c.goal_ned[0] - s.x, c.goal_ned[1] - s.y) <= c.goal_radius:
            b.to(Behaviour.COMPLETE)
            v = self.vehicle
            if v.mode == Mode.AUTO:
                v.finish()
                if v.complete:
                    c.complete_t = t
                    self._event(t, "mission complete: final goal reached")
            else:
                c.complete_t = t
                self._event(t, f"{v.mode.name}: destination reached, holding")
        if b.state in STATION:
            return self._station_keep(s, dt)
        plan, waited = self.planning.collect(t)
        self.waited = self.waited or waited
        if plan is not None:
            if self.acceptance.accept(plan, s):
                if b.to(Behaviour.PLANNED):
                    self._event(t, f"following local path (cycle {plan.cycle}, {plan.status})")
            elif c.los is None:
                self.to_fallback(t, f"no valid local path ({plan.reason or plan.status})")
        if self.planning.pending_since is None and t + 1e-9 >= c.next_plan_t:
            c.next_plan_t = t + p.planning_period
            self.plan_due = s   # submitted by the pipeline once the command is out
        preview = max(p.lookahead, 3.0 * self.speed_setpoint())  # ~3 s of travel
        following = b.state is Behaviour.PLANNED and c.los is not None
        guidance = c.los.update(s.x, s.y, preview) if following and c.los is not None else None
        if guidance is not None and guidance.finished and \
                math.hypot(c.goal_ned[0] - s.x, c.goal_ned[1] - s.y) > p.goal_tolerance:
            self.to_fallback(t, "local path finished before a new one arrived")
            guidance = None
        return self._control(s, dt, guidance)

    # -- helpers --------------------------------------------------------------------------------
    def speed_setpoint(self) -> float:
        """m/s over ground along the path: the vehicle's (DO_CHANGE_SPEED, RTL_SPEED, WP_SPEED)."""
        return self.vehicle.speed_setpoint()

    def to_fallback(self, t: float, why: str) -> None:
        if self.course.behaviour.to(Behaviour.FALLBACK):
            self._on_fallback()
            self._event(t, f"reactive avoidance engaged: {why}")
        self.course.los = None

    def reset_controllers(self, s: NavState) -> None:
        self.heading_pid.reset()
        self.speed_ctl.reset(s.u)

    def _control(self, s: NavState, dt: float, g: GuidanceOutput | None) -> Thrust:
        c, p = self.course, self.p
        if g is not None and c.los is not None:
            # LOS gives the course to steer; the hull must point the drift angle beta = atan2(v, u)
            # (current, sway in turns) away from it. Uncompensated, each cycle's new path (starting
            # where the vessel is) forgave the drift, and a cross-current set the boat onto walls.
            psi_ref, u_ref = g.heading - s.drift_angle(p.min_turn_speed), self.speed_setpoint() * c.speed_factor
            self.tracking.add(g.cross_track, psi_ref, s.psi)
            r_ref = max(s.u, 0.0) * g.curvature   # the path turns at u kappa: feed it forward
            # Slow down for sharp turns ahead so the yaw rate they need (u kappa) stays within reach.
            if g.curvature_ahead > 1e-6:
                u_ref = min(u_ref, max(p.min_turn_speed, p.max_turn_rate / g.curvature_ahead))
            u_ref = min(u_ref, self._near_obstacle_speed(s))
            u_ref = min(u_ref, heading_error_speed_cap(psi_ref - s.psi, p.turn_in_place_angle,
                                                        p.min_turn_speed, math.inf))
            if g.remaining < 2.0 * p.lookahead and c.los.path[-1].tolist() == list(c.goal_ned):
                u_ref = max(0.5, self.speed_setpoint() * g.remaining / (2.0 * p.lookahead))
        else:
            a = self.reactive.command(s.x, s.y, s.psi, c.target)
            psi_ref, u_ref, r_ref = a.heading, a.speed, 0.0
        return self.drive(s, dt, psi_ref, min(u_ref, self._arrival_speed(s)), r_ref)

    def drive(self, s: NavState, dt: float, psi_ref: float, u_ref: float, r_ref: float = 0.0) -> Thrust:
        """Heading (rad, with yaw-rate feed-forward r_ref rad/s) and speed over ground (m/s) set-points to
        thrust. Under way the speed loop's integral takes up the current (feeding the estimate forward here
        too moved the COLREGs encounters' trajectories: crossing-right seed 3 turned to port); station
        keeping, where the current is the whole load, feeds it forward (:meth:`_station_keep`)."""
        if self._way_blocked(s, psi_ref, u_ref):
            return self._keep_blocked(s, dt)
        return self._drive(s, dt, psi_ref, u_ref, 0.0, r_ref)

    def _way_blocked(self, s: NavState, psi_ref: float, u_ref: float) -> bool:
        """Whether the boat must keep station (:meth:`_keep_blocked`) rather than follow the set-point:
        the set-point asks it where the avoidance limit will not let it go (less than ``BLOCKED_RUN`` of free
        water along ``psi_ref``, or astern for a negative ``u_ref``), or the current sets it there sideways
        (as little free water along its course over ground, above ``DRIFT_SPEED`` and ``DRIFT_ANGLE`` off the
        way asked; inside the avoidance clearance, any way), which no surge limit stops. It keeps station for
        at least ``BLOCKED_HOLD_S``, until ``CLEAR_RUN`` is free along the way asked. Before, a boat held
        back by the limit, or creeping at a slow set-point, was set sideways onto the quay beside it (the
        chaos hour, seed 31: unsigned at 1,051 s, signed at 1,805 s)."""
        cog = s.psi + math.atan2(s.v, s.u)
        inside = self.grid.clearance_at(s.y, s.x) < self.avoid_clearance
        if abs(u_ref) < BLOCKED_SPEED:
            wanted_free, astray = math.inf, True
        else:
            way = psi_ref if u_ref > 0.0 else psi_ref + math.pi
            wanted_free = self._free_run(s, way, CLEAR_RUN, CELL_SLACK)
            astray = inside or abs(wrap_angle(cog - way)) > DRIFT_ANGLE
        drift_run = min(max(BLOCKED_RUN, s.speed * DRIFT_LOOKAHEAD_S), CLEAR_RUN)
        drifting = astray and s.speed > DRIFT_SPEED and s.u < DRIFT_SURGE and \
            self._free_run(s, cog, drift_run, CELL_SLACK) < drift_run
        if self.blocked_at is None:
            blocked = wanted_free < BLOCKED_RUN or drifting
        else:
            blocked = wanted_free < CLEAR_RUN or drifting or s.t - self._blocked_since < BLOCKED_HOLD_S
        if blocked and self.blocked_at is None:
            self.blocked_at, self._blocked_since = self._retreat_point(s), s.t
            self.station.reset()
            self._blocked_behaviour.to(Behaviour.IDLE)
            if s.t - self._blocked_told >= BLOCKED_TELL_S:
                self._blocked_told = s.t
                self._event(s.t, f"{self.vehicle.mode.name}: {'set towards' if drifting else 'way blocked'} "
                            f"{self.grid.clearance_at(s.y, s.x):.1f} m from an obstacle: keeping station")
        elif not blocked and self.blocked_at is not None:
            self.blocked_at = None
            self.reset_controllers(s)
        return blocked

    def _retreat_point(self, s: NavState) -> tuple[float, float]:
        """Where a blocked boat keeps station (NED m): the nearest point within ``RETREAT_RANGE`` that is at
        least the planner's safety radius from every obstacle, else the clearest one there. Held where it
        stood, 1.5 m from a pier head, a boat turning into the current swept its ends within a quarter of
        a metre of it, and the current's next push touched (the chaos hour, seed 31 signed, 660.7 s)."""
        return clear_point(self.grid, (s.x, s.y), self.safety_radius, RETREAT_RANGE)

    def _keep_blocked(self, s: NavState, dt: float) -> Thrust:
        """Keep station at the retreat point (:meth:`_retreat_point`), against the current, as HOLD does near
        obstacles."""
        assert self.blocked_at is not None
        return self.station.command(s, dt, self.blocked_at, True, self._blocked_behaviour, self._keeping_drive,
                                    self.current.velocity, lambda: self.reset_controllers(s), rest=False)

    def _keeping_drive(self, s: NavState, dt: float, psi_ref: float, u_ref: float, u_current: float) -> Thrust:
        """The station keeper's drive: it may turn on the spot at any speed it asks."""
        return self._drive(s, dt, psi_ref, u_ref, u_current, yaw_limit=self.turn_on_the_spot)

    def station_point(self, point: tuple[float, float]) -> tuple[float, float]:
        """Where a mode asked to keep station at ``point`` (NED m) keeps it: there, or, inside ``keep_off.MARGIN``
        beyond the safety radius of an obstacle, the nearest point within ``keep_off.REACH`` that is that clear
        (:func:`autopilot_bridge.keep_off.clear_point`). Held 1.5 m off the breakwater, a LOITER entered there
        was set onto it (the chaos hour, seed 31, at f5d6fd1)."""
        return clear_point(self.grid, point, self.safety_radius + CLEAR_MARGIN, CLEAR_REACH)

    def _drive(self, s: NavState, dt: float, psi_ref: float, u_ref: float, u_current: float,
               r_ref: float = 0.0, yaw_limit: float = math.inf) -> Thrust:
        capped = self.avoidance_cap(s, u_ref)
        if capped != u_ref:
            # No turn may push the boat on: a full differential with the weaker reverse thrust makes surge force
            # (turn_on_the_spot), which crept a boat 1.5 m off a wall to 1.0 m at 0.1 m/s while it turned away.
            self.speed_ctl.limit_reference(abs(capped))
            brake = abs(s.u) > abs(capped) + AVOID_BRAKE_MARGIN   # surge momentum: the sway no thrust stops
            yaw_limit = min(yaw_limit, self.braking_yaw_limit if brake else self.turn_on_the_spot)
        tau_r = self.heading_pid.update(psi_ref, s.psi, s.r, dt, r_ref)
        tau_r = min(max(tau_r, -yaw_limit), yaw_limit)
        tau_u = self.speed_ctl.update(capped, s.u, s.v, s.r, dt, u_current)
        return allocate(tau_u, tau_r, self.prop.B_u, self.prop.T_max, self.prop.T_min)

    def avoidance_cap(self, s: NavState, u_ref: float) -> float:
        """The surge set-point (m/s, negative astern) limited so the boat can stop, braking at
        ``AVOID_DECELERATION``, before the clearance along its bow (or stern, astern) - and along its course
        over ground, where a turn or the current carries it - falls below ``avoid_clearance``: in every mode
        that drives, whatever the route or the target asked, as ArduPilot's simple avoidance limits the
        velocity towards a fence by its stopping distance. Chaotic mode changes beside a quay (issue 31) left
        a boat heading for it at 0.8 m/s with each new route's controllers starting afresh. Only a ray that
        goes nearer to an obstacle than the boat is now counts, so a boat already inside the clearance can
        still sail away from it."""
        if abs(u_ref) < 1e-3:
            return u_ref
        lag = self.speed_ctl.p.speed_reference_time_constant
        reach = min(u_ref * u_ref / (2.0 * AVOID_DECELERATION) + s.speed * lag + self.grid.resolution,
                    AVOID_LOOKAHEAD)               # beyond it the cap is above u_ref
        free = self._free_run(s, s.psi if u_ref > 0.0 else s.psi + math.pi, reach)
        if s.speed > AVOID_COURSE_SPEED:
            free = min(free, self._free_run(s, s.psi + math.atan2(s.v, s.u), reach))
        if free >= reach:
            return u_ref
        cap = stopping_speed_cap(free, s.speed, 0.0, AVOID_DECELERATION, lag)
        return max(min(u_ref, cap), -cap)

    def _free_run(self, s: NavState, direction: float, reach: float, slack: float = 0.0) -> float:
        """m the boat can go along ``direction`` (rad) before the clearance falls below ``avoid_clearance``
        (or more than ``slack`` m below the clearance it has now); ``reach`` when nothing is nearer."""
        c, sn = math.cos(direction), math.sin(direction)
        limit = min(self.avoid_clearance, self.grid.clearance_at(s.y, s.x) - slack)
        step = self.grid.resolution
        for k in range(1, int(reach / step) + 1):
            d = k * step
            if self.grid.clearance_at(s.y + d * sn, s.x + d * c) < limit:
                return d - step
        return reach

    @property
    def braking_yaw_limit(self) -> float:
        """The largest yaw moment (N m) that leaves half the reverse thrust for braking: ``allocate`` keeps
        the yaw moment first, and a full-rate turn left no surge force to stop with (the chaos hour, seed 31
        signed: a boat turning at 0.68 rad/s beside the quay kept its 1 m/s onto it)."""
        prop = self.prop
        return -BRAKING_YAW_SHARE * prop.T_min * prop.B_u

    @property
    def turn_on_the_spot(self) -> float:
        """The largest yaw moment (N m) that leaves zero surge force possible: a full differential with a
        reverse thrust weaker than the forward one pushes the boat ahead (``allocate`` keeps the yaw
        moment first), 53 N on this hull, enough to sail off the point while turning on it."""
        prop = self.prop
        return 0.95 * min(-prop.T_min, prop.T_max) * prop.B_u

    def _near_obstacle_speed(self, s: NavState) -> float:
        """Speed cap (m/s) near obstacles: the set-point beyond ``slow_clearance`` of the vessel's
        clearance (cell-centre distance on the chart plus sensed obstacles), ``min_turn_speed`` at the
        planner's safety radius. The cross-track error of a turn grows with speed; a path at the
        inflation's edge leaves the hull only safety radius - L/2 of it."""
        return clearance_speed_cap(self.grid.clearance_at(s.y, s.x), self.safety_radius,
                                   self.p.slow_clearance, self.p.min_turn_speed, self.speed_setpoint())

    def _arrival_speed(self, s: NavState) -> float:
        """Speed cap (m/s) that brings the boat to the route's end within its stopping distance: at the goal
        radius it is down to the station keeper's approach speed there, so station keeping starts from a
        speed it can take up, not from WP_SPEED (a GUIDED target 2 m off a quay was overrun by 1.2 m)."""
        c = self.course
        beyond = math.hypot(c.goal_ned[0] - s.x, c.goal_ned[1] - s.y) - c.goal_radius
        return stopping_speed_cap(beyond, s.u, self.station.approach_speed(c.goal_radius), ARRIVAL_DECELERATION,
                                  self.speed_ctl.p.speed_reference_time_constant)

    def _station_keep(self, s: NavState, dt: float) -> Thrust:
        """After the route's end: loiter when the route says so or MIS_DONE_BEHAVE is loiter, else hold."""
        route = self.vehicle.route
        loiter = self.vehicle.mission_done == MIS_DONE_LOITER or (route is not None and route.loiter)
        return self.station.command(s, dt, self.station_point(self.course.goal_ned), loiter, self.course.behaviour,
                                    self._keeping_drive, self.current.velocity, lambda: self.reset_controllers(s))
