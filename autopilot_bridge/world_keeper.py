"""The vessel computer's world as it changes on the way, and what the planner worker is told of it.

The chart's grid gains the obstacles the range scans find (:mod:`autopilot_bridge.obstacle_map`) and
the geofence a ground station uploads (:mod:`autopilot_bridge.geofence`); the global route is planned
over that grid (:mod:`autopilot_bridge.route_planning`) whenever the vehicle's route changes and
re-planned when a sensed obstacle blocks it. Each of these changes, and a ground station's tuning of
the planner (:mod:`autopilot_bridge.planner_tuning`), bumps the world's version: the planner worker
started with the scenario's :class:`autopilot_bridge.local_planning.World` and from then on gets
:meth:`WorldKeeper.update` with every cycle.

A fence breach acts here too (FENCE_ACTION), since it is the fence that leaves the planning grids
while the boat is outside it.
"""

from __future__ import annotations

from collections.abc import Callable

from autopilot_bridge.behaviour import Behaviour
from autopilot_bridge.computer_setup import AutopilotStats
from autopilot_bridge.config import AutopilotParams
from autopilot_bridge.course import Course
from autopilot_bridge.geofence import FENCE_HOLD, FENCE_RTL, GeoFence
from autopilot_bridge.hil_link import RangeScan
from autopilot_bridge.local_planning import World, WorldUpdate
from autopilot_bridge.modes import Mode
from autopilot_bridge.navigation import NavState
from autopilot_bridge.obstacle_map import SensedObstacles, path_blocked
from autopilot_bridge.plan_handoff import PlanHandoff
from autopilot_bridge.planner_tuning import PlannerTuning
from autopilot_bridge.route_planning import RouteKeeper
from autopilot_bridge.vehicle import Vehicle
from planner.fence import Fence
from planner.gridmap import OccupancyGrid


class WorldKeeper:
    """The grid (chart + sensed + fence), the global route over it, the fence and the planner's tuning.

    ``grid`` is the chart's occupancy grid (a copy of ``world``'s, built by the assembly), changed in
    place; the course's reference path follows the route planned here."""

    def __init__(self, world: World, grid: OccupancyGrid, params: AutopilotParams, vehicle: Vehicle,
                 course: Course, planning: PlanHandoff, stats: AutopilotStats,
                 event: Callable[[float, str, bool], None],
                 log: Callable[[str], None]) -> None:
        self.chart, self.grid, self.p = world.occ, grid, params
        self.vehicle, self.course, self.planning, self.stats, self._event = vehicle, course, planning, stats, event
        self.sensed = SensedObstacles(world.occ, world.resolution, params.sensed_confirm_hits,
                                      params.sensed_explain_radius)
        self.routes = RouteKeeper(grid, world.params.safety_radius, log=log)
        self.routes.adopt(course.reference_ned)
        self.geofence = GeoFence()
        self.planner_tuning = PlannerTuning(world.params)
        vehicle.rally_target = self.geofence.rally_point
        self.version = 0            # changes of the world the worker has not started with
        self._route_version = 0     # the vehicle's route last followed
        self._sent_overrides: dict[str, float] = {}
        self._fence_enabled = 1.0
        self._fence_versions = 0

    # -- the fence ----------------------------------------------------------------------------------
    def fence_changed(self, fence: Fence | None = None) -> None:
        """A new fence (upload, clear) or the fence switched on or off or breached: the grids and the route."""
        if fence is not None:
            self._fence_versions += 1
            self.geofence.fence = Fence(fence.inclusion_polygons, fence.exclusion_polygons, fence.inclusion_circles,
                                        fence.exclusion_circles, version=self._fence_versions)
        occ = self.chart.copy()
        cells = self.sensed.cells()
        if len(cells):
            occ[cells[:, 0], cells[:, 1]] = True
        plan_fence = self.geofence.for_planning()
        if not plan_fence.empty:
            occ |= plan_fence.forbidden(occ.shape, self.grid.resolution)
        self.grid.replace(occ)
        if self.vehicle.route is not None and len(self.routes.waypoints) >= 2:
            self.course.reference_ned = self.routes.set_route(self.routes.waypoints)
        self.version += 1

    def check_fence(self, t: float, s: NavState) -> None:
        """A breach acts once (FENCE_ACTION); the fence leaves the planning grids until the boat is back."""
        if self.geofence.enable != self._fence_enabled:
            self._fence_enabled = self.geofence.enable
            self.fence_changed()
        change = self.geofence.check(s.x, s.y)
        if change is None:
            return
        self.fence_changed()
        if change == "cleared":
            self._event(t, "fence: back inside, breach over", False)
            return
        action = self.geofence.action
        v = self.vehicle
        if action == FENCE_RTL and v.mode != Mode.RTL:
            ok, why = v.set_mode(Mode.RTL, (s.x, s.y))
            self._event(t, f"fence breach: {why if ok else 'RTL refused (' + why + '), holding station'}", True)
            if not ok:
                v.set_mode(Mode.LOITER, (s.x, s.y))
        elif action == FENCE_HOLD:
            v.set_mode(Mode.LOITER, (s.x, s.y))
            self._event(t, "fence breach: holding station (LOITER)", True)
        else:
            self._event(t, "fence breach (FENCE_ACTION 0: reported only)", True)

    # -- the route ----------------------------------------------------------------------------------
    def apply_route(self, t: float) -> None:
        """Follow the vehicle's new global route (mission upload, AUTO/RTL/GUIDED entered), atomically."""
        r = self.vehicle.route
        if r is None or r.version == self._route_version:
            return
        self._route_version = r.version
        c = self.course
        c.reference_ned = self.routes.set_route(r.path)   # legs of any length: routed on the chart
        c.goal_ned = (float(r.path[-1][0]), float(r.path[-1][1]))
        c.goal_radius = r.goal_radius
        c.target = c.goal_ned
        c.los = None
        c.behaviour.new_route()
        c.complete_t = None
        self.planning.route_changed()   # whatever the worker is planning now is for the old route
        c.next_plan_t = t
        self.version += 1

    # -- sensed obstacles ---------------------------------------------------------------------------
    def sense(self, t: float, scan: RangeScan, s: NavState) -> None:
        """Add a range scan's new obstacles to the map; replan at once if they are near the path ahead."""
        new = self.sensed.add_scan(scan.bearings, scan.ranges, s.x, s.y, s.psi, scan.sector_width)
        if len(new) == 0:
            return
        self.grid.mark(new)
        c = self.course
        replanned = self.routes.on_sensed(new, (s.x, s.y))
        if replanned is not None:
            c.reference_ned = replanned
            self.version += 1
            self._event(t, "sensed obstacle on the global route: route re-planned", False)
        if c.behaviour.state is Behaviour.PLANNED and c.los is not None:
            ahead = c.los.path[c.los.index:]
            if path_blocked(ahead, new, self.grid.resolution, self.p.sensed_path_clearance):
                self.stats.sensed_replans += 1
                self._event(t, "sensed obstacle near the local path: replanning", False)
                c.next_plan_t = t
                c.path_invalid = True

    # -- the planner worker's view ------------------------------------------------------------------
    def update(self) -> WorldUpdate | None:
        """What the planner worker must use instead of the World it started with (None: nothing changed)."""
        overrides = self.planner_tuning.overrides()
        if overrides != self._sent_overrides:     # a ground station tuned the planner
            self._sent_overrides = overrides
            self.version += 1
        if self.version == 0:   # no route, re-planned route, fence or parameter since the start
            return None
        ref = self.course.reference_ned[:, ::-1].copy()          # NED -> map (x east, y north)
        fence = self.geofence.for_planning()
        return WorldUpdate(self.version, (float(ref[-1][0]), float(ref[-1][1])), ref, dict(overrides),
                           None if fence.empty else fence)
