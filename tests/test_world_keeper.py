"""The world keeper alone (autopilot_bridge/world_keeper.py), built from its typed parts in-process: the
grid it changes, the fence and its breach, the route it plans, and what the planner worker is told."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from autopilot_bridge.computer_setup import AutopilotStats
from autopilot_bridge.course import Course
from autopilot_bridge.hil_link import RangeScan
from autopilot_bridge.local_planning import map_to_ned_path, online_cycle_handler
from autopilot_bridge.modes import Mode
from autopilot_bridge.navigation import NavState
from autopilot_bridge.plan_handoff import PlanHandoff
from autopilot_bridge.vehicle import Vehicle, Waypoint
from autopilot_bridge.world_keeper import WorldKeeper
from hil import scenario as scenarios
from hil import settings
from hil.assembly import computer_config, planning_world
from planner.fence import Circle, Fence
from planner.gridmap import OccupancyGrid
from tests.support.vessel_harness import InlineWorker


class Parts:
    """A WorldKeeper on the harbour scenario, armed in AUTO on the scenario's route, and what it acts on."""

    def __init__(self) -> None:
        cfg = settings.load(None, [])
        world = planning_world(cfg, scenarios.load("harbour", cfg.current, cfg.planner.safety_radius, cfg.geodesy))
        params = computer_config(cfg).params
        ref = map_to_ned_path(world.reference_path)
        self.world, self.start = world, (float(ref[0][0]), float(ref[0][1]))
        self.events: list[tuple[float, str, bool]] = []
        self.vehicle = Vehicle([Waypoint(float(n), float(e), params.goal_tolerance) for n, e in ref], armed=True,
                               mode=Mode.AUTO, scenario_route=ref, default_radius=params.goal_tolerance,
                               wp_speed=params.cruise_speed)
        goal = (world.goal[1], world.goal[0])
        self.course = Course(goal_ned=goal, goal_radius=params.goal_tolerance, reference_ned=ref, target=goal)
        self.planning = PlanHandoff(InlineWorker(online_cycle_handler(world)), params, True, 1, AutopilotStats(),
                                    lambda t, text: None, speed=self.vehicle.speed_setpoint)
        self.grid = OccupancyGrid(world.occ.copy(), world.resolution)
        self.keeper = WorldKeeper(world, self.grid, params, self.vehicle, self.course, self.planning,
                                  AutopilotStats(), lambda t, text, warning: self.events.append((t, text, warning)),
                                  lambda text: None)

    def at(self, north: float, east: float) -> NavState:
        return NavState(t=1.0, x=north, y=east, psi=0.0, u=0.0, v=0.0, r=0.0, gyro_bias=0.0, position_std=0.5)

    def cell(self, north: float, east: float) -> tuple[int, int]:
        return self.grid.cell_of(east, north)


@pytest.fixture(scope="module")
def compiled() -> None:
    Parts()   # the sensed-obstacle map's and the route's kernels, compiled once for the module


def test_nothing_changed_tells_the_worker_nothing(compiled: None) -> None:
    p = Parts()
    assert p.keeper.update() is None
    p.keeper.check_fence(1.0, p.at(*p.start))     # no fence: no breach, nothing for the worker
    p.keeper.apply_route(1.0)                     # the scenario's route, which the worker started with
    assert p.keeper.update() is None and p.events == []


def test_a_fence_upload_marks_the_grid_not_the_chart_and_reaches_the_worker(compiled: None) -> None:
    p = Parts()
    n, e = p.start
    chart_before = p.world.occ.copy()
    assert not p.world.occ[p.cell(n + 20.0, e)]                      # open water on the chart
    p.keeper.fence_changed(Fence(exclusion_circles=(Circle(e, n + 20.0, 3.0),)))
    assert p.grid.occ[p.cell(n + 20.0, e)]
    np.testing.assert_array_equal(p.world.occ, chart_before)       # the chart itself is never written
    update = p.keeper.update()
    assert update is not None and update.version == 1 and update.fence is not None
    assert update.fence.exclusion_circles == (Circle(e, n + 20.0, 3.0),)
    # FENCE_ENABLE 0: the next check takes the fence off the grid and tells the worker.
    p.keeper.geofence.enable = 0
    p.keeper.check_fence(1.0, p.at(n, e))
    assert not p.grid.occ[p.cell(n + 20.0, e)]
    update = p.keeper.update()
    assert update is not None and update.version == 2 and update.fence is None


def test_a_breach_acts_once_and_keeps_the_fence_off_the_grid_until_the_boat_is_back(compiled: None) -> None:
    p = Parts()
    n, e = p.start
    p.keeper.geofence.action = 2                                    # FENCE_ACTION 2: hold station
    p.keeper.fence_changed(Fence(exclusion_circles=(Circle(e, n, 5.0),)))
    p.keeper.check_fence(1.0, p.at(n, e))                            # inside the exclusion zone
    assert p.keeper.geofence.breached and p.vehicle.mode == Mode.LOITER
    assert [w for _, text, w in p.events if "breach" in text] == [True]
    assert not p.grid.occ[p.cell(n, e)]                              # the way out can be planned
    update = p.keeper.update()
    assert update is not None and update.fence is None
    p.keeper.check_fence(1.1, p.at(n, e))                            # still inside: no second action
    assert len([t for t in p.events if "breach" in t[1]]) == 1
    p.keeper.check_fence(2.0, p.at(n, e + 8.0))                      # 3 m outside: the breach is over
    assert not p.keeper.geofence.breached and p.grid.occ[p.cell(n, e)]
    assert p.events[-1][1] == "fence: back inside, breach over"


def test_tuning_the_planner_is_sent_once_per_change(compiled: None) -> None:
    p = Parts()
    initial = p.world.params.perceptual_radius
    p.keeper.planner_tuning.perceptual_radius = initial + 10.0       # PLN_PERCEPT_RAD from a ground station
    first = p.keeper.update()
    assert first is not None and first.planner_overrides == {"perceptual_radius": initial + 10.0}
    again = p.keeper.update()
    assert again is not None and again.version == first.version     # the same world: the worker has it
    p.keeper.planner_tuning.perceptual_radius = initial              # back to the start value
    back = p.keeper.update()
    assert back is not None and back.version == first.version + 1 and back.planner_overrides == {}


def test_a_new_vehicle_route_is_routed_on_the_grid_and_restarts_planning(compiled: None) -> None:
    p = Parts()
    n, e = p.start
    p.course.next_plan_t = 99.0
    p.vehicle.set_mode(Mode.GUIDED, (n, e))
    assert p.vehicle.reposition((n + 30.0, e), (n, e))[0]
    p.keeper.apply_route(5.0)
    route = p.course.reference_ned
    assert tuple(route[-1]) == (n + 30.0, e) and p.course.goal_ned == (n + 30.0, e)
    assert p.course.next_plan_t == 5.0                               # plan the new route now
    update = p.keeper.update()
    assert update is not None and update.goal == (e, n + 30.0)       # map frame: x east, y north
    np.testing.assert_array_equal(update.reference_path, route[:, ::-1])
    p.keeper.apply_route(5.1)                                        # the same route: nothing new
    assert p.keeper.update() is not None and p.keeper.update().version == update.version


def test_without_home_a_breachs_rtl_is_refused_and_the_boat_holds_station(compiled: None) -> None:
    p = Parts()                                                      # FENCE_ACTION 1 (RTL), no home yet
    n, e = p.start
    p.keeper.fence_changed(Fence(exclusion_circles=(Circle(e, n, 5.0),)))
    p.keeper.check_fence(1.0, p.at(n, e))
    assert p.vehicle.mode == Mode.LOITER
    assert p.events[-1] == (1.0, "fence breach: RTL refused (RTL: no home position), holding station", True)


def test_a_fence_across_the_route_reroutes_the_course(compiled: None) -> None:
    p = Parts()
    n, e = p.start
    p.vehicle.set_mode(Mode.GUIDED, (n, e))
    assert p.vehicle.reposition((n + 30.0, e), (n, e))[0]
    p.keeper.apply_route(1.0)
    straight = p.course.reference_ned.copy()
    assert len(straight) >= 2
    p.keeper.fence_changed(Fence(exclusion_circles=(Circle(e, n + 15.0, 3.0),)))   # on the way north
    around = p.course.reference_ned
    assert tuple(around[-1]) == (n + 30.0, e)
    clearance = np.hypot(around[:, 0] - (n + 15.0), around[:, 1] - e).min()
    assert clearance > 3.0 and not np.array_equal(around, straight)


def test_a_sensed_obstacle_on_the_route_is_marked_and_the_route_replanned(compiled: None) -> None:
    p = Parts()
    n, e = p.start
    leg = p.course.reference_ned[1] - p.course.reference_ned[0]
    s = dataclasses.replace(p.at(n, e), psi=math.atan2(leg[1], leg[0]))   # heading along the route's first leg
    before = p.course.reference_ned.copy()
    scan = RangeScan((0.0,), (6.0,), 20.0, 0.0)                         # a return 6 m ahead, off the chart
    for k in range(p.keeper.p.sensed_confirm_hits):
        assert p.keeper.sensed.count == 0 and p.keeper.update() is None  # not yet confirmed
        p.keeper.sense(1.0 + k, scan, s)
    cells = p.keeper.sensed.cells()
    assert len(cells) == 1 and p.grid.occ[cells[0][0], cells[0][1]] and not p.world.occ[cells[0][0], cells[0][1]]
    confirmed_at = float(p.keeper.p.sensed_confirm_hits)                 # the scan that confirmed the cell
    assert p.events == [(confirmed_at, "sensed obstacle on the global route: route re-planned", False)]
    assert not np.array_equal(p.course.reference_ned, before) and p.keeper.routes.replans == 1
    update = p.keeper.update()
    assert update is not None and update.version == 1
