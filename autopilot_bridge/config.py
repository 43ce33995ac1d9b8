"""Typed configuration of the vessel computer (TOML sections [autopilot], [navigation], [control])."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

from common.params import param


@dataclass(frozen=True)
class AutopilotParams:
    """The [autopilot] section: links, mission following, planning schedule, fallback."""

    listen: str = param("HOST:PORT where the simulator's HIL_SENSOR/HIL_GPS frames arrive")
    actuators_to: tuple[str, ...] = param("HOST:PORT destinations of HIL_ACTUATOR_CONTROLS")
    telemetry_to: tuple[str, ...] = param(
        "HOST:PORT destinations of a copy of every ground-station frame in and out (hil run's tap records them)")
    telemetry_from: str = param(
        "HOST:PORT those copies are sent from (port 0: any free port); hil run names one, and its tap takes them "
        "from there only")
    system_id: int = param("MAVLink system id of the vessel", ge=1, le=255)
    component_id: int = param("MAVLink component id of the autopilot", ge=1, le=255)
    cruise_speed: float = param("speed set-point along the local path", "m/s", gt=0)
    lookahead: float = param("line-of-sight look-ahead distance", "m", gt=0)
    max_turn_rate: float = param("speed is reduced so that sharp turns ahead need at most this yaw rate", "rad/s", gt=0)
    min_turn_speed: float = param("lowest speed of that reduction (steerage way)", "m/s", gt=0)
    turn_in_place_angle: float = param(
        "a heading error above this turns the boat at min_turn_speed, not at cruise: a new path that starts "
        "behind the boat is a tight turn, not a wide one (ArduPilot Rover likewise slows for its turns)", "rad",
        gt=0, le=3.1416)
    slow_clearance: float = param(
        "closer than this to an obstacle the speed set-point falls linearly, to min_turn_speed at the planner's "
        "safety radius: path-following error grows with speed, and the margin there is what is left", "m", gt=0)
    goal_tolerance: float = param("the mission is complete within this distance of the final goal", "m", gt=0)
    planning_period: float = param("simulated time between local planning cycles", "s", gt=0)
    planning_deadline: float = param("hard deadline of one local planning cycle (watchdog)", "s", gt=0)
    watchdog_grace: float = param("a planner this long past its deadline is killed and restarted", "s", gt=0)
    lockstep_iterations: int = param("lockstep: iteration budget per planning cycle (repeatable runs)", ge=1)
    lockstep_planner_timeout: float = param(
        "lockstep: wall time to wait for a cycle's plan before the watchdog kills the worker (simulated time "
        "stands still meanwhile, so a loaded machine must not change the run)", "s", gt=0)
    gps_latency: float = param("GPS output latency compensated by dead reckoning", "s", ge=0)
    commit_compare_length: float = param(
        "metres of a new and the followed local path compared: an obstacle between them means they pass it on "
        "different sides (autopilot_bridge/plan_commitment.py)", "m", gt=0)
    commit_min_remaining: float = param(
        "a new path that passes an obstacle the other way round replaces the followed one once that has less "
        "than this left", "m", ge=0)
    commit_shortcut_ratio: float = param(
        "... or at once when it is shorter than this fraction of the followed path's rest plus the gap between "
        "their ends",
        gt=0, le=1)
    fallback_speed: float = param("speed of the reactive obstacle-avoidance behaviour", "m/s", gt=0)
    fallback_range: float = param("look-ahead of the reactive behaviour's free-space rays", "m", gt=0)
    min_clearance: float = param("the reactive behaviour keeps rays this far from obstacles", "m", ge=0)
    sensed_obstacles: bool = param("add obstacles seen by the range sensor (OBSTACLE_DISTANCE) to the chart")
    sensed_confirm_hits: int = param("returns in one grid cell before it counts as a sensed obstacle", ge=1)
    sensed_explain_radius: float = param("returns this close to a charted obstacle are the chart's", "m", ge=0)
    sensed_path_clearance: float = param(
        "a new sensed obstacle this close to the local path ahead triggers an immediate replan", "m", ge=0)
    send_loss: float = param("fault injection: probability of dropping an outgoing HIL datagram", ge=0, le=1)
    recv_loss: float = param("fault injection: probability of dropping an incoming HIL datagram", ge=0, le=1)
    sim_restart_gap: float = param("sensor time going back by more than this means the simulator restarted", "s", gt=0)
    lockstep_busy_poll: float = param(
        "lockstep: wait for the next sensor frame polling the socket this long before sleeping on it "
        "(common.udp.BusyPoll; 0 = sleep at once)", "s", ge=0, le=0.1)
    mission_done: Literal["loiter", "hold"] = param(
        "after the final goal: loiter (hold position at the goal, as ArduPilot boats do in LOITER) or hold "
        "(thrusters off, drift)", default="loiter")
    station_keeping: Literal["into-current", "drift-and-return"] = param(
        "how the boat keeps station (LOITER, mission end, RTL/GUIDED arrival): into-current (point into the water "
        "velocity needed, feed the current forward: autopilot_bridge/station_keeping.py) or drift-and-return "
        "(ArduRover's boats: drift within the radius, then steer back bow first; kept for comparison, hil bench "
        "station)", default="into-current")
    loiter_radius: float = param("loiter: drifting this far from the final goal starts the way back", "m", gt=0,
                                 default=3.0)
    loiter_speed: float = param("loiter: speed set-point of the way back to the goal", "m/s", gt=0, default=0.8)

    def __post_init__(self) -> None:
        if self.planning_deadline >= self.planning_period:
            raise ValueError("planning_deadline: must be shorter than planning_period")
