"""One local planning cycle of section 2.2, as run inside the planner worker process.

The world the vessel computer knows a priori (the chart's obstacle map, the global reference
path, the current measured beforehand) is sent to the worker once, as a :class:`World`; every
cycle then sends the vessel's state, budget and the obstacles sensed so far (which the worker
adds to the chart). The cycle itself is
``planner.online.plan_cycle``: subgoal (section 3.1), local problem in the perceptual domain,
DDRRT* (or RRT*, Informed RRT*), pruning and Dubins smoothing (section 2.4).

Frames: the planner's map frame (x east, y north, headings counter-clockwise from east). The
autopilot converts with :func:`common.frames.ned_to_map` / :func:`common.frames.map_to_ned`.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, replace
from typing import TYPE_CHECKING

import numpy as np

from common.frames import map_to_ned, map_to_ned_path, ned_to_map  # noqa: F401  (re-exported)
from planner.cost import path_length

if TYPE_CHECKING:
    from autopilot_bridge.planning_worker import PlanRequest
    from planner.fence import Fence
    from planner.field import GridField
    from planner.online import OnlineContext, OnlineParams
    from planner.params import PlannerParams
    from planner.traffic_map import TrafficSnapshot


@dataclass(frozen=True)
class World:
    """What the planner worker needs once: map, goal, reference path, field, parameters (map frame)."""

    occ: np.ndarray
    resolution: float
    goal: tuple[float, float]
    reference_path: np.ndarray
    field: GridField | None      # the current, sampled on the map (None: no current)
    params: PlannerParams
    online: OnlineParams
    algorithm: str


@dataclass(frozen=True)
class WorldUpdate:
    """A change of the World since the worker started (map frame): a ground station uploaded a mission
    (new goal and reference path) or changed planner parameters. Sent with every cycle once there is
    one, so a restarted worker (the watchdog) picks it up too; ``version`` tells the worker whether
    it has it already."""

    version: int
    goal: tuple[float, float]
    reference_path: np.ndarray
    planner_overrides: dict[str, float]    # PlannerParams field -> value a ground station set
    fence: Fence | None = None             # the geofence the planner keeps out of (None: none)


@dataclass(frozen=True)
class CycleInput:
    """A cycle's start: map-frame position (m), heading (rad from east), time (s), seed, and the
    obstacles sensed so far (``(K, 2)`` [row, col] cells of the chart's grid; ``sensed_version``
    changes whenever they do). Sent whole each cycle: a restarted worker must know them too."""

    x: float
    y: float
    heading: float
    t: float
    seed: int
    sensed: np.ndarray | None = None
    sensed_version: int = 0
    traffic: TrafficSnapshot | None = None   # the ships, predicted for the cycle; None: none known
    world: WorldUpdate | None = None


@dataclass(frozen=True)
class LocalPlan:
    """What the worker answers: the smoothed local path (map frame) and how it was obtained."""

    cycle: int
    status: str                  # exact | approximate | none
    path: np.ndarray             # (N, 2) dense smoothed path, map frame; empty if none
    subgoal: tuple[float, float]
    subgoal_rule: int
    iterations: int
    planning_time_s: float
    reason: str
    speed_factor: float = 1.0    # sail the path at this fraction of the cruise speed (traffic)


PLANNER_SHARE = 0.7  # of a real-time cycle's deadline; the rest is for post-processing
LOOP_FACTOR = 1.25  # a smoothed path this much longer than its polyline contains a loop


WARM_UP_ITERATIONS = 200
WARM_UP_DEADLINE_S = 0.05


def online_cycle_handler(world: World, warm_up: CycleInput | None = None) \
        -> Callable[[PlanRequest[CycleInput]], LocalPlan]:
    """Worker factory: build the online context once, then plan one cycle per request.

    ``warm_up``: a start to plan short cycles from (both budgets) before the handler
    is returned, so that a freshly forked worker pays its copy-on-write page faults and cache
    loads while it starts up, not in its first real-time cycle; the context is left as new."""
    from planner.gridmap import OccupancyGrid
    from planner.online import VesselState, make_context, plan_cycle

    def context(sensed: np.ndarray | None, fence: Fence | None = None) -> OnlineContext:
        grid = OccupancyGrid(world.occ.copy(), world.resolution)
        if sensed is not None:
            grid.mark(sensed)
        if fence is not None and not fence.empty:
            grid.replace(grid.occ | fence.forbidden(grid.occ.shape, grid.resolution))
        return make_context(grid, world.goal, world.reference_path, world.params, world.online,
                            world.algorithm, world.field)

    ctx = context(None)
    version = 0

    applied: dict[str, int | None] = {"version": None}
    applied_fence: list[int | None] = [None]     # the version of the fence the context was built with

    def handle(request: PlanRequest[CycleInput]) -> LocalPlan:
        nonlocal ctx, version
        start: CycleInput = request.problem
        rebuilt = False
        update = start.world
        fence = update.fence if update is not None else None
        fence_key = None if fence is None or fence.empty else fence.version
        if start.sensed_version != version or fence_key != applied_fence[0]:
            # The map known a priori plus what is sensed, less what the fence forbids: inflated maps are
            # rebuilt only when they change.
            progress = ctx.progress           # where along the reference path the vessel is
            ctx, version = context(start.sensed, fence), start.sensed_version
            applied_fence[0] = fence_key
            ctx.progress = progress
            rebuilt = True
        if update is not None and (rebuilt or update.version != applied["version"]):
            # Same maps (and their inflation caches); new route and planner parameters.
            ctx.goal = (float(update.goal[0]), float(update.goal[1]))
            ctx.params = replace(ctx.params, **update.planner_overrides)  # type: ignore[arg-type]  # float fields
            ctx.set_reference(update.reference_path)   # within reach of the (new) perceptual radius
            if update.version != applied["version"]:
                ctx.progress = 0              # a new route begins where the vessel is
            applied["version"] = update.version
        if request.iterations is not None:
            ctx.online = replace(world.online, local_iterations=int(request.iterations), local_time=0.0)
        else:
            # The planner gets 70% of the deadline: subgoal, pruning and smoothing take the rest.
            ctx.online = replace(world.online, local_iterations=0, local_time=PLANNER_SHARE * float(request.deadline_s))
        rec = plan_cycle(ctx, VesselState(start.x, start.y, start.heading, start.t), request.cycle, start.seed,
                         traffic=start.traffic)
        path = rec.local_path
        if len(rec.smooth_path) >= 2 and rec.smoothed_ok:
            # Dubins curves between waypoints closer than ~2 R_min can loop; a loop is worse to follow
            # than the pruned polyline (whose turns the planner's fan limit already bounds).
            if path_length(rec.smooth_path) <= LOOP_FACTOR * path_length(rec.local_path) + 1e-9:
                path = rec.smooth_path
        return LocalPlan(cycle=request.cycle, status=rec.status, path=np.asarray(path, dtype=float).reshape(-1, 2),
                         subgoal=(float(rec.subgoal[0]), float(rec.subgoal[1])), subgoal_rule=rec.subgoal_rule,
                         iterations=rec.iterations,
                         planning_time_s=rec.planning_time_s, reason=rec.reason, speed_factor=rec.speed_factor)

    if warm_up is not None:
        from autopilot_bridge.planning_worker import PlanRequest

        # Both budgets: an iteration count (lockstep) and a wall-clock deadline (real time) take
        # different compiled paths, each loaded on its first use.
        handle(PlanRequest(0, warm_up, deadline_s=1.0, iterations=WARM_UP_ITERATIONS))
        handle(PlanRequest(0, warm_up, deadline_s=WARM_UP_DEADLINE_S))
        ctx.progress = 0
    return handle
