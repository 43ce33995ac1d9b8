"""Which local plans the vessel computer follows (step 2's answer, checked before it steers the boat).

A plan is followed only if it starts where the vessel now is, is free on the chart and of what was
sensed since it was asked for, and - plan commitment (:mod:`autopilot_bridge.plan_commitment`) - does not
swing round the other side of an obstacle the followed path already passes. Accepted plans are kept for
the run's record (``local_paths``).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from autopilot_bridge.behaviour import Behaviour
from autopilot_bridge.computer_setup import AutopilotStats
from autopilot_bridge.config import AutopilotParams
from autopilot_bridge.course import Course
from autopilot_bridge.guidance import LineOfSight
from autopilot_bridge.local_planning import LocalPlan, map_to_ned_path
from autopilot_bridge.navigation import NavState
from autopilot_bridge.obstacle_map import SensedObstacles, path_blocked
from autopilot_bridge.plan_commitment import CommitmentParams, keep_current
from autopilot_bridge.plan_handoff import PlanHandoff
from planner.gridmap import OccupancyGrid


@dataclass(frozen=True)
class AcceptedPath:
    """One accepted local path, for the run's record: vehicle time (s), cycle, planner status, NED points."""

    t: float
    cycle: int
    status: str
    path_ned: list[list[float]]


class PlanAcceptance:
    def __init__(self, params: AutopilotParams, grid: OccupancyGrid, sensed: SensedObstacles, planning: PlanHandoff,
                 course: Course, stats: AutopilotStats) -> None:
        self.p, self.grid, self.sensed, self.planning = params, grid, sensed, planning
        self.course, self.stats = course, stats
        self.local_paths: list[AcceptedPath] = []

    def accept(self, plan: LocalPlan, s: NavState) -> bool:
        """Follow ``plan`` from the estimate ``s`` if it passes every check (else count why not)."""
        rejected = self.stats.plans_rejected
        if plan.status == "none" or len(plan.path) < 2:
            rejected[f"status_{plan.status}"] += 1
            return False
        ned = map_to_ned_path(plan.path)
        # The path must start where the vessel now is (it was planned from a predicted position).
        if math.hypot(ned[0, 0] - s.x, ned[0, 1] - s.y) > 3.0 * self.p.lookahead:
            rejected["starts_too_far"] += 1
            return False
        if not self.grid.polyline_free(plan.path):
            rejected["collides"] += 1
            return False
        since = self.sensed.cells()[self.planning.sensed_at_submit:]
        if path_blocked(ned, since, self.grid.resolution, self.p.sensed_path_clearance):
            # Planned before these obstacles were seen: plan again at once.
            rejected["sensed_since_planning"] += 1
            self.course.next_plan_t = s.t
            return False
        if self._keeps_current_path(ned, s):
            rejected["other_way_round"] += 1
            return False
        c = self.course
        c.path_invalid = False
        c.los = LineOfSight(ned, self.p.lookahead, acceptance_radius=self.p.goal_tolerance)
        c.target = (plan.subgoal[1], plan.subgoal[0])
        c.speed_factor = plan.speed_factor
        self.stats.plans_accepted += 1
        self.local_paths.append(AcceptedPath(s.t, plan.cycle, plan.status,
                                             ned[:: max(1, len(ned) // 200)].round(3).tolist()))
        return True

    def _keeps_current_path(self, ned: np.ndarray, s: NavState) -> bool:
        """Plan commitment: stay on the followed path rather than swing round the other side of an
        obstacle - unless it is blocked, traffic is being planned for, the followed path is not an exact
        one, or the vessel is off it by more than the look-ahead."""
        c = self.course
        if c.behaviour.state is not Behaviour.PLANNED or c.los is None or c.path_invalid \
                or self.planning.traffic_planned:
            return False
        if self.local_paths and self.local_paths[-1].status != "exact":
            # The followed path stopped short of its subgoal (the tree found no way there): it may
            # lead into a dead end, such as along a mole the reference path crosses. No commitment.
            return False
        ahead = c.los.path[c.los.index:]
        if float(np.min(np.hypot(ahead[:, 0] - s.x, ahead[:, 1] - s.y))) > self.p.lookahead:
            return False
        p = self.p
        return keep_current(ahead, ned, self.grid.occ, self.grid.resolution,
                            CommitmentParams(p.commit_compare_length, p.commit_min_remaining, p.commit_shortcut_ratio))
