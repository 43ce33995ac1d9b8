"""The online planning process of section 4.2 (Figures 9 and 10): plan, smooth, move, repeat.

Pure: no sockets, no processes, no global random state; the clock is injected. One planning
cycle (:func:`plan_cycle`) is

1. select the subgoal on the global reference path from the vessel position with the
   perceptual radius (section 3.1, :func:`planner.subgoal.select_subgoal`); a subgoal inside an
   obstacle (the reference path may cross obstacles, Figure 9) is moved back along the reference
   path to the nearest free point, else to the nearest free cell;
2. build the local problem inside the perceptual domain (a circle of ``perceptual_radius``
   around the vessel) on the obstacle map inflated by the safety radius and, section 3.3, by
   the velocity estimated from the reference path;
3. plan with the chosen algorithm within the cycle's budget (iterations and/or seconds);
4. prune (section 2.4) and smooth with Dubins curves of radius ``turn_radius_factor * speed``;
   a smoothed path that is not collision-free falls back to the pruned polyline.

:func:`advance` then moves the vessel ``speed * cycle_time`` metres along the smoothed path (a
kinematic model is enough here; the HIL loop replaces it with the simulator) and
:func:`run_online` repeats until the final goal is within ``goal_tolerance`` or a cap is hit.

Table 3's "time" is :attr:`OnlineResult.search_time_s`: the sum over cycles of each cycle's time
to its first solution (the whole cycle's planning time when it found none) - "the sum of the
search durations of paths before the subgoals were reached". Its "cost", Σcos α_y, Σsin α_y and
cf(π) are measured on the executed path resampled every ``metric_spacing`` metres.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable
from dataclasses import dataclass, replace
from dataclasses import field as dc_field
from typing import TYPE_CHECKING, Literal

import numpy as np
import numpy.typing as npt
from scipy import ndimage

from planner import make_planner
from planner.core import free_regions
from planner.cost import path_cost_fn, path_length
from planner.field import DisturbanceField
from planner.gridmap import OccupancyGrid
from planner.metrics import path_metrics, waypoint_alpha_sums
from planner.params import PlannerParams
from planner.postprocess import check_and_replan, prune
from planner.problem import PlanningProblem
from planner.result import PlannerResult
from planner.subgoal import select_subgoal
from planner.termination import Termination

if TYPE_CHECKING:
    from planner.traffic_map import TrafficSnapshot


def _p(help: str, unit: str = "", **bounds: float) -> dict[str, object]:
    return {"help": help, "unit": unit, **bounds}


EXECUTION_MODELS = ("receding", "whole-path")
LOCAL_CLOCKS = ("wall", "thread-cpu")


@dataclass(frozen=True)
class OnlineParams:
    """Settings of the online process (scenario ``[online]`` table; CLI options override)."""

    cycle_time: float = dc_field(default=6.0, metadata=_p(
        "vessel motion per planning cycle: the vessel sails speed * cycle_time along each local path", "s", gt=0))
    local_iterations: int = dc_field(default=1500, metadata=_p(
        "iteration budget of each local planning cycle (deterministic: the Monte Carlo default)", "", ge=0))
    local_time: float = dc_field(default=0.0, metadata=_p(
        "time budget of each local planning cycle, on local_clock; 0 = iterations only", "s", ge=0, le=600))
    local_clock: Literal["wall", "thread-cpu"] = dc_field(default="wall", metadata=_p(
        "the clock of local_time: 'wall' (CLOCK_MONOTONIC, the paper's) or 'thread-cpu' (the planning "
        "thread's CPU time, CLOCK_THREAD_CPUTIME_ID: time the thread waits or is preempted does not count, "
        "so an equal CPU budget is the same on a loaded machine); both are checked inside the compiled "
        "search before every iteration"))
    max_cycles: int = dc_field(default=120, metadata=_p("cap on planning cycles per run", "", gt=0))
    max_failures: int = dc_field(default=6, metadata=_p(
        "consecutive cycles without any local path before the run is declared failed", "", gt=0))
    metric_spacing: float = dc_field(default=2.0, metadata=_p(
        "waypoint spacing of the executed path for cost, Σcos, Σsin and cf(π)", "m", gt=0))
    clearance_sigma: float = dc_field(default=1.0, metadata=_p(
        "standard deviation of the vessel's deviation from the path, for cf(π) (eq. 14): GPS 0.5 m per axis "
        "plus path-following error", "m", gt=0))
    smoothing: bool = dc_field(default=True, metadata=_p("Dubins smoothing of each local path"))
    subgoal_arc_limit: bool = dc_field(default=True, metadata=_p(
        "accept a subgoal only within one perceptual radius along the reference path (see select_local_subgoal)"))
    velocity_inflation: bool = dc_field(default=True, metadata=_p(
        "extra obstacle inflation from the velocity estimated on the reference path (section 3.3)"))
    execution: Literal["receding", "whole-path"] = dc_field(default="receding", metadata=_p(
        "how much of each local path the vessel sails before the next cycle plans: 'receding' (speed * "
        "cycle_time, then replan) or 'whole-path' (the whole local path, the next planned from its end, as "
        "section 3.5 executes it; the tree is reused only with tree_reuse)"))
    tree_reuse: bool = dc_field(default=False, metadata=_p(
        "whole-path execution only: start each cycle's tree from the subtree of the previous tree rooted at "
        "the node where the vessel now is (section 3.5, line 3), the nodes still valid on the new map kept"))

    def __post_init__(self) -> None:
        if self.execution not in EXECUTION_MODELS:
            raise ValueError(f"execution: must be one of {', '.join(EXECUTION_MODELS)} (got {self.execution!r})")
        if self.tree_reuse and self.execution != "whole-path":
            raise ValueError("tree_reuse: needs execution = \"whole-path\" (a receding cycle stops between tree "
                             "nodes, so no subtree starts where the vessel is)")
        if self.local_clock not in LOCAL_CLOCKS:
            raise ValueError(f"local_clock: must be one of {', '.join(LOCAL_CLOCKS)} (got {self.local_clock!r})")
        if self.local_iterations == 0 and self.local_time == 0:
            raise ValueError("local_iterations: a cycle needs a budget (local_iterations or local_time > 0)")


@dataclass(frozen=True)
class VesselState:
    """Kinematic vessel state in the map frame: position (m), heading (rad from +x), time (s)."""

    x: float
    y: float
    heading: float
    t: float = 0.0


@dataclass
class CycleRecord:
    """Everything one planning cycle produced (kept for Figure 10 plots and diagnostics)."""

    index: int
    start: VesselState
    subgoal: tuple[float, float]
    subgoal_rule: int
    status: str
    search_time_s: float           # time to first solution, or the whole planning time if none
    planning_time_s: float
    iterations: int
    local_path: np.ndarray         # pruned polyline (N, 2)
    smooth_path: np.ndarray        # dense Dubins polyline (or the pruned path when it collided)
    smoothed_ok: bool
    tree_nodes: np.ndarray
    tree_parents: np.ndarray
    travelled: np.ndarray = dc_field(default_factory=lambda: np.zeros((0, 2)))
    reason: str = ""
    speed_factor: float = 1.0      # traffic: sail this path at this fraction of the planned speed
    # search_time_s measured three more ways (issue 34 point 4): the thread's CPU time, the
    # iterations and the collision checks to the first solution (the whole cycle's when none)
    search_cpu_s: float = 0.0
    search_iterations: int = 0
    search_checks: int = 0
    reused_nodes: int = 0          # nodes of the previous cycle's tree this one started with (tree_reuse)


@dataclass
class OnlineResult:
    """Outcome of a whole online run."""

    reached: bool
    reason: str
    cycles: list[CycleRecord]
    executed: np.ndarray           # (N, 2) the path the vessel sailed, dense
    final: VesselState
    search_time_s: float           # Table 3 "time"
    planning_time_s: float         # total planning time of all cycles
    metrics: dict[str, float]      # cost, length, sum_cos, sum_sin, cf, turns, ... (executed path)
    search_cpu_s: float = 0.0      # Table 3 "time" as thread CPU time, iterations and collision checks
    search_iterations: int = 0
    search_checks: int = 0
    # the waypoints of the local paths the vessel left (each cycle's pruned path, its vertices
    # before the distance sailed in that cycle) and the direction of the leg leaving each
    waypoints: np.ndarray = dc_field(default_factory=lambda: np.zeros((0, 2)))
    waypoint_directions: np.ndarray = dc_field(default_factory=lambda: np.zeros((0, 2)))


@dataclass
class OnlineContext:
    """The fixed inputs of a run: maps (raw and inflated), field, reference path and parameters."""

    grid: OccupancyGrid            # raw obstacle map
    goal: tuple[float, float]
    reference_path: np.ndarray
    params: PlannerParams
    online: OnlineParams
    field: DisturbanceField | None = None   # the current in the map frame
    wave_drift: tuple[float, float] | None = None  # m/s, map frame (PlannerParams.alpha_y = "resultant")
    safe_grid: OccupancyGrid | None = None
    _free_index: np.ndarray | None = None
    _velocity_grids: dict = dc_field(default_factory=dict)
    _distance: np.ndarray | None = None
    progress: int = 0              # index of the reference point the vessel was last nearest (see select_local_subgoal)

    def __post_init__(self) -> None:
        self.set_reference(self.reference_path)
        if self.safe_grid is None:
            radius = self.params.safety_radius
            self.safe_grid = self.grid.inflate(radius) if radius > 0 else self.grid

    def set_reference(self, reference_path: npt.ArrayLike) -> None:
        """The reference path to follow, within reach of the perceptual radius (:func:`within_reach`):
        set it after ``params`` when both change."""
        self.reference_path = within_reach(reference_path, self.params.perceptual_radius)

    @property
    def safe(self) -> OccupancyGrid:
        """The safety-inflated map (set by ``__post_init__``)."""
        assert self.safe_grid is not None
        return self.safe_grid

    def planning_grid(self, velocity: tuple[float, float]) -> OccupancyGrid:
        """The safety-inflated map plus the section 3.3 velocity inflation (cached per direction)."""
        if not self.online.velocity_inflation or self.params.velocity_inflation_gain <= 0:
            return self.safe
        key = (round(velocity[0], 1), round(velocity[1], 1))
        if key not in self._velocity_grids:
            if len(self._velocity_grids) > 32:
                self._velocity_grids.clear()
            self._velocity_grids[key] = self.grid.inflate_velocity(
                key, self.params.velocity_inflation_gain, self.params.safety_radius)
        return self._velocity_grids[key]

    def recovery_grid(self, pos: tuple[float, float]) -> OccupancyGrid | None:
        """The map for a vessel inside the safety inflation (tracking error or the current put it
        there): the inflation radius grows linearly with the distance from the vessel, from the
        largest multiple of the resolution that leaves the vessel's cell free to the full safety
        radius at ``recovery_radius``. None when that is no inflation at all (the vessel touches
        an obstacle: raw map).

        Planning on the raw map instead (as before) let every new path run along the obstacle at
        the vessel's distance or closer; the next cycle then started closer still, a ratchet that
        walked the lockstep runs into labyrinth walls. A constant reduced radius near the vessel
        still allowed a slower ratchet (a path parallel to the wall at the vessel's clearance,
        tracking error a cell inwards, the next path a cell closer): the ramp makes every path
        gain clearance as it goes."""
        res = self.grid.resolution
        dist = self._centre_distance()
        r, c = self.grid.cell_of(*pos)
        if not (0 <= r < dist.shape[0] and 0 <= c < dist.shape[1]):
            return None
        radius = math.floor((float(dist[r, c]) - 1e-9) / res) * res
        if radius <= 0.0:
            return None
        full = self.params.safety_radius
        radius = min(radius, full)
        rows, cols = dist.shape
        yy = (np.arange(rows) + 0.5) * res - pos[1]
        xx = (np.arange(cols) + 0.5) * res - pos[0]
        away = np.sqrt(yy[:, None] ** 2 + xx[None, :] ** 2)
        allowed = radius + (full - radius) * np.minimum(away / self.recovery_radius, 1.0)
        return OccupancyGrid(dist <= allowed + 1e-12, res)

    @property
    def recovery_radius(self) -> float:
        """Distance (m) from the vessel at which a path must be back outside the full inflation:
        one tree extension (4 m: a lateral step of 1 m on the 3 m turning circle takes ~3.5 m)."""
        return self.params.step

    def _centre_distance(self) -> np.ndarray:
        """Distance (m) of each cell centre from the nearest obstacle cell centre or the map's edge
        (the measure of :meth:`OccupancyGrid.inflate`)."""
        if self._distance is None:
            self._distance = ndimage.distance_transform_edt(~np.pad(self.grid.occ, 1, constant_values=True))[1:-1,
                                                                                                             1:-1] \
                * self.grid.resolution
        return self._distance

    def nearest_free(self, grid: OccupancyGrid, point: tuple[float, float]) -> tuple[float, float] | None:
        """The centre of the free cell of ``grid`` nearest to ``point`` (None if the map is full)."""
        occ = grid.occ
        if occ.all():
            return None
        _, idx = ndimage.distance_transform_edt(occ, return_indices=True)
        res = grid.resolution
        r = min(max(int(point[1] / res), 0), occ.shape[0] - 1)
        c = min(max(int(point[0] / res), 0), occ.shape[1] - 1)
        rr, cc = idx[0][r, c], idx[1][r, c]
        return (float((cc + 0.5) * res), float((rr + 0.5) * res))


def within_reach(reference_path: npt.ArrayLike, radius: float) -> np.ndarray:
    """The reference path with points added where two waypoints lie more than half the perceptual
    ``radius`` (m) apart; every waypoint kept, and the path itself where no gap is that wide.

    Section 3.1 chooses subgoals among the reference waypoints. With a gap wider than the domain, the
    only waypoint in reach is q_j, the one the vessel is at, and every cycle planned back to it: with
    PLN_PERCEPT_RAD = 6.5 m on a route of 10 m spacing, the chaos ground station's boat dithered
    beside the quay for minutes, never past the midpoint that would make the next waypoint q_j, until
    the current set it on (2026-11-29)."""
    path = np.asarray(reference_path, dtype=float).reshape(-1, 2)
    if len(path) < 2 or not np.any(np.hypot(*np.diff(path, axis=0).T) > 0.5 * radius):
        return path
    return _densify(path, 0.5 * radius)


def resample(path: np.ndarray, spacing: float) -> np.ndarray:
    """Points every ``spacing`` m along a polyline (first and last point kept)."""
    path = np.asarray(path, dtype=float).reshape(-1, 2)
    if len(path) < 2:
        return path.copy()
    seg = np.hypot(*np.diff(path, axis=0).T)
    keep = np.concatenate([[True], seg > 1e-9])
    path = path[keep]
    if len(path) < 2:
        return path.copy()
    s = np.concatenate([[0.0], np.cumsum(np.hypot(*np.diff(path, axis=0).T))])
    n = max(int(math.ceil(s[-1] / spacing)), 1)
    t = np.linspace(0.0, s[-1], n + 1)
    return np.column_stack([np.interp(t, s, path[:, 0]), np.interp(t, s, path[:, 1])])


def advance(path: np.ndarray, distance: float) -> tuple[np.ndarray, float]:
    """Sail ``distance`` m along ``path``: the travelled polyline and the final heading (rad)."""
    path = np.asarray(path, dtype=float).reshape(-1, 2)
    if len(path) < 2 or distance <= 0:
        return path[:1].copy(), math.nan
    out = [path[0]]
    left = distance
    heading = math.nan
    for a, b in zip(path[:-1], path[1:], strict=True):
        d = math.hypot(b[0] - a[0], b[1] - a[1])
        if d <= 1e-12:
            continue
        heading = math.atan2(b[1] - a[1], b[0] - a[0])
        if d >= left:
            out.append(a + (b - a) * (left / d))
            return np.array(out), heading
        out.append(b)
        left -= d
    return np.array(out), heading


def reference_velocity(reference_path: np.ndarray, point: tuple[float, float], speed: float) -> tuple[float, float]:
    """Velocity (m/s) estimated from the reference path: ``speed`` along the nearest segment."""
    ref = reference_path
    if len(ref) < 2:
        return (0.0, 0.0)
    a, b = ref[:-1], ref[1:]
    ab = b - a
    L2 = np.maximum(np.sum(ab * ab, axis=1), 1e-12)
    t = np.clip(np.sum((np.asarray(point) - a) * ab, axis=1) / L2, 0.0, 1.0)
    d = np.hypot(*(a + ab * t[:, None] - np.asarray(point)).T)
    i = int(np.argmin(d))
    n = math.sqrt(L2[i])
    return (speed * ab[i, 0] / n, speed * ab[i, 1] / n)


def _free_subgoal(ctx: OnlineContext, grid: OccupancyGrid, position: tuple[float, float],
                  index: int, point: tuple[float, float]) -> tuple[float, float] | None:
    """A free stand-in for a subgoal inside an obstacle: back along the reference path towards
    the vessel (inside the perceptual domain, and at least one tree step away from the vessel),
    else the nearest free cell to the subgoal.

    Without the minimum distance, an obstacle (or its inflation) that covers the reference path
    from just ahead of the vessel gave a stand-in at the vessel itself: every cycle then planned
    "start is the goal" and the run failed without moving (24 of 1,000 random-map runs per
    planner, `hil montecarlo --scenario random --runs 1000 --seed 1`, before this rule)."""
    if grid.is_free(*point):
        return point
    ref = ctx.reference_path
    radius = ctx.params.perceptual_radius
    min_gap = ctx.params.step
    pts = [np.asarray(point)]
    # Walk back along the reference path from the subgoal (and along the segment into it).
    for k in range(min(index, len(ref) - 1), 0, -1):
        a, b = ref[k - 1], ref[k] if k < len(ref) else ref[-1]
        n = max(int(math.hypot(*(b - a)) / (0.5 * grid.resolution)), 1)
        pts.extend(b + (a - b) * (i / n) for i in range(1, n + 1))
    for q in pts:
        if not min_gap <= math.hypot(q[0] - position[0], q[1] - position[1]) <= radius:
            continue
        if grid.is_free(float(q[0]), float(q[1])):
            return (float(q[0]), float(q[1]))
    return ctx.nearest_free(grid, point)


def _connects(ctx: OnlineContext, grid: OccupancyGrid, position: tuple[float, float], index: int,
              point: tuple[float, float]) -> bool:
    """True if the vessel at ``position`` and its subgoal's free stand-in on ``grid`` lie in the
    same free region of ``grid`` (4-connected, as the search checks).

    The global route is planned on the safety-inflated chart, which may leave a passage only a
    metre wide; section 3.3's velocity inflation on top can close it. The search on that map then
    stops at once ("different free regions"), the vessel does not move, and every later cycle
    fails the same way: runs 54 and 374 of `hil montecarlo --scenario random-global --runs 1000
    --seed 1` were lost so by every planner. Such a cycle plans on the safety-inflated map."""
    goal = _free_subgoal(ctx, grid, position, index, point)
    if goal is None:
        return False
    labels = free_regions(grid)
    return bool(labels[grid.cell_of(*position)] == labels[grid.cell_of(*goal)])


def _arc_from_nearest(ref: np.ndarray, pos: tuple[float, float], progress: int = 0,
                      window: float = math.inf, radius: float = math.inf) -> tuple[int, np.ndarray]:
    """Index j of the reference waypoint nearest ``pos`` and the arc length (m) from q_j to every
    waypoint (negative before j).

    j is searched from ``progress`` (the vessel's last q_j) to ``window`` metres of arc beyond it,
    so that a route that passes the same water twice (out to a waypoint and back, a route that
    crosses itself) is followed in order rather than jumping to the other pass; if no waypoint of
    that stretch lies within ``radius`` (the vessel is far off it, or a restarted worker lost its
    progress), the whole path is searched."""
    s = np.concatenate([[0.0], np.cumsum(np.hypot(*np.diff(ref, axis=0).T))]) if len(ref) > 1 else np.zeros(1)
    d = np.hypot(ref[:, 0] - pos[0], ref[:, 1] - pos[1])
    lo = min(max(int(progress), 0), len(ref) - 1)
    hi = int(np.searchsorted(s, s[lo] + window, side="right"))
    hi = min(max(hi, lo + 1), len(ref))
    j = lo + int(np.argmin(d[lo:hi]))
    if d[j] > radius:
        j = int(np.argmin(d))
    return j, s - s[j]


def select_local_subgoal(ctx: OnlineContext, pos: tuple[float, float]) -> tuple[tuple[float, float], int, int]:
    """Section 3.1's subgoal (point, reference index, rule) for a vessel at ``pos``.

    Rule 1 also applies when the reference path ends elsewhere than the goal. With
    ``OnlineParams.subgoal_arc_limit`` (default on) a candidate is only accepted if it lies at
    most one perceptual radius *along the reference path* from q_j: where the reference path
    folds back (a labyrinth wall shorter than the radius), the waypoints behind the wall are
    inside the domain but not reachable inside it, and the literal rules 1 and 3 would send the
    vessel into the dead end in front of the wall. The chosen waypoint is then the last one of
    the rule's chain within that arc length."""
    params = ctx.params
    ref = ctx.reference_path
    radius = params.perceptual_radius
    limit = radius if ctx.online.subgoal_arc_limit else math.inf
    j, arc = _arc_from_nearest(ref, pos, ctx.progress, 2.0 * radius, radius)
    ctx.progress = j
    goal_arc = arc[-1] if np.allclose(ref[-1], ctx.goal) else 0.0
    if math.hypot(ctx.goal[0] - pos[0], ctx.goal[1] - pos[1]) <= radius and goal_arc <= limit:
        return ctx.goal, len(ref) - 1, 1
    # Section 3.1's rules on the reference path from q_j on (q_j found in order, above).
    sub = select_subgoal(ref[j:], pos, radius)
    idx, rule = sub.index + j, sub.rule
    if arc[idx] > limit:
        within = np.nonzero((arc <= limit) & (np.arange(len(ref)) >= j))[0]
        idx = int(within[-1]) if len(within) else j
        if rule == 1:       # the goal was rejected: the chain from q_j decides, as in rule 3
            rule = 3
    return (float(ref[idx, 0]), float(ref[idx, 1])), idx, rule


def plan_cycle(ctx: OnlineContext, state: VesselState, index: int, seed: int,
               clock: Callable[[], float] = time.monotonic, traffic: TrafficSnapshot | None = None,
               reuse: tuple[np.ndarray, np.ndarray] | None = None) -> CycleRecord:
    """One planning cycle from ``state`` (see the module docstring); does not move the vessel.

    ``traffic`` (a :class:`planner.traffic_map.TrafficSnapshot`): moving ships, painted into the
    planning map at the time the vessel would reach each cell, with their COLREGs zones; the
    chosen path is then checked with its own arrival times (section 3.3). Arrival times depend
    on the speed, so the cycle tries the speed factors of ``traffic.speed_factors`` in turn (full
    speed first) and keeps the first that reaches the subgoal where it lies without traffic: a
    give-way ship that cannot turn away in time slows down instead.

    ``reuse``: a tree to start from, (nodes, parents) rooted at the vessel (:func:`reusable_subtree`;
    without traffic only)."""
    if traffic is None or not traffic.obstacles:
        return _plan_cycle_once(ctx, state, index, seed, clock, None, reuse)
    fallback: CycleRecord | None = None
    for k, factor in enumerate(traffic.speed_factors):
        snap = replace(traffic, speed=traffic.speed * factor)
        rec = _plan_cycle_once(ctx, state, index, seed + k, clock, snap)
        rec.speed_factor = factor
        if rec.status == "exact" and len(rec.smooth_path) >= 2 and rec.reason != "traffic moved the subgoal":
            return rec
        if fallback is None or (len(fallback.smooth_path) < 2 and len(rec.smooth_path) >= 2):
            fallback = rec
    assert fallback is not None, "traffic.speed_factors is empty"
    return fallback


def _plan_cycle_once(ctx: OnlineContext, state: VesselState, index: int, seed: int,
                     clock: Callable[[], float], traffic: TrafficSnapshot | None,
                     reuse: tuple[np.ndarray, np.ndarray] | None = None) -> CycleRecord:
    params, online = ctx.params, ctx.online
    pos = (state.x, state.y)
    sub_point, sub_index, rule = select_local_subgoal(ctx, pos)

    # Planning map: velocity-inflated, else only safety-inflated, else (the vessel itself is
    # inside the inflation: pushed there, it must still get out) the recovery map, else raw.
    # Where the velocity inflation parts the vessel from its subgoal, the safety-inflated map
    # (the global route's) if it joins them; never a thinner one for that reason.
    velocity = reference_velocity(ctx.reference_path, sub_point, params.speed)
    recovery = None if ctx.safe.is_free(*pos) else ctx.recovery_grid(pos)
    moving = ctx.planning_grid(velocity)
    grid = next((g for g in (moving, ctx.safe_grid, recovery, ctx.grid) if g is not None and g.is_free(*pos)), None)
    if (grid is moving and moving is not ctx.safe_grid and ctx.safe.is_free(*pos)
            and not _connects(ctx, moving, pos, sub_index, sub_point)
            and _connects(ctx, ctx.safe, pos, sub_index, sub_point)):
        grid = ctx.safe
    empty = np.zeros((0, 2))
    if grid is None:
        return CycleRecord(index, state, sub_point, rule, "none", 0.0, 0.0, 0, empty, empty, False,
                           empty, np.zeros(0, dtype=int), reason="vessel inside an obstacle")
    traffic_grid = None
    if traffic is not None and traffic.obstacles:
        from planner.traffic_map import paint, relax_for_start

        traffic = relax_for_start(traffic)
        keep = 2.0 * grid.resolution
        def traffic_grid(g: OccupancyGrid) -> OccupancyGrid:
            return paint(g, traffic, pos, params.perceptual_radius, keep_free=pos, keep_radius=keep)
        plain_goal = _free_subgoal(ctx, grid, pos, sub_index, sub_point)
        grid = traffic_grid(grid)
        if plain_goal is not None and not grid.is_free(*plain_goal):
            # A ship occupies the subgoal when we would get there (e.g. she sails along our
            # reference path): look beside it, starboard side first, before giving up ground.
            side = _beside_free(grid, pos, plain_goal, params.perceptual_radius, traffic)
            if side is not None:
                sub_point = plain_goal = side
    goal = _free_subgoal(ctx, grid, pos, sub_index, sub_point)
    moved = traffic_grid is not None and goal != plain_goal
    if goal is None:
        return CycleRecord(index, state, sub_point, rule, "none", 0.0, 0.0, 0, empty, empty, False,
                           empty, np.zeros(0, dtype=int), reason="no free subgoal")

    r = params.perceptual_radius
    xmin, xmax = max(0.0, pos[0] - r), min(grid.width, pos[0] + r)
    ymin, ymax = max(0.0, pos[1] - r), min(grid.height, pos[1] + r)
    problem = PlanningProblem(
        grid=grid, start=pos, goal=goal, start_heading=state.heading, field=ctx.field,
        reference_path=ctx.reference_path, bounds=(xmin, xmax, ymin, ymax),
        domain_center=pos, domain_radius=r, wave_drift=ctx.wave_drift, initial_tree=reuse,
    )
    termination = _termination(online, clock)
    planner = make_planner(params.algorithm, replace(params, seed=int(seed)))
    result: PlannerResult = planner.solve(problem, termination)
    reused = int((result.diagnostics or {}).get("reused_nodes", 0))
    search = result.time_to_first_solution_s
    if search is None:
        search = result.planning_time_s
    measures = _search_measures(result)
    if result.status == "none" and state.heading is not None:
        # Boxed in by the turning-radius fan (e.g. heading into a wall): the twin-thruster vessel
        # can turn on the spot, so plan once more without the heading limit at the root.
        termination = _termination(online, clock)
        retry = make_planner(params.algorithm, replace(params, seed=int(seed) ^ 0x5A5A5A5)).solve(
            replace(problem, start_heading=None, initial_tree=None), termination)
        reused = 0
        first = retry.time_to_first_solution_s
        search += first if first is not None else retry.planning_time_s
        measures = tuple(a + b for a, b in zip(measures, _search_measures(retry), strict=True))  # type: ignore[assignment]
        retry.planning_time_s += result.planning_time_s
        retry.iterations += result.iterations
        result = retry
    if result.status == "none" or len(result.path) < 2:
        return _measured(CycleRecord(index, state, goal, rule, result.status, float(search), result.planning_time_s,
                                     result.iterations, empty, empty, False, result.tree_nodes, result.tree_parents,
                                     reason=result.reason or "no local path"), measures, reused)

    local = prune(result.path, grid, path_cost_fn(ctx.field, params))
    radius = params.turn_radius_factor * params.speed
    # The bypass of a short leg must be clear of the safety-inflated map (the velocity
    # inflation is a planning margin; the smoothed path is checked against the same map).
    check_grid = next(g for g in (ctx.safe_grid, recovery, ctx.grid) if g is not None and g.is_free(*pos))
    if traffic_grid is not None:
        check_grid = traffic_grid(check_grid)
    local = drop_short_legs(local, check_grid, radius)
    smoothed, ok = _densify(local, 0.5), False
    if online.smoothing and len(local) >= 2:
        # Section 2.4: Dubins smoothing, then the constraints are re-checked on the smoothed
        # path (collision against the safety-inflated map, curvature); violating legs are
        # refined by check_and_replan. If that still fails, sail the pruned polyline.
        sm = check_and_replan(local, check_grid, radius,
                              start_heading=state.heading, step=0.5)
        if sm.ok:
            smoothed, ok = sm.dense, True
    if traffic_grid is not None and traffic is not None:
        from planner.traffic_map import first_conflict

        if ok and first_conflict(smoothed, traffic, ignore_within=keep) is not None:
            smoothed, ok = _densify(local, 0.5), False
        when = first_conflict(local, traffic, ignore_within=keep)
        if when is not None:
            return _measured(CycleRecord(index, state, goal, rule, "none", float(search), result.planning_time_s,
                                         result.iterations, empty, empty, False, result.tree_nodes,
                                         result.tree_parents, reason=f"traffic conflict {when:.1f} s along the path"),
                             measures, reused)
    return _measured(CycleRecord(index, state, goal, rule, result.status, float(search), result.planning_time_s,
                                 result.iterations, local, smoothed, ok, result.tree_nodes, result.tree_parents,
                                 reason="traffic moved the subgoal" if moved else result.reason), measures, reused)


def _search_measures(result: PlannerResult) -> tuple[float, int, int]:
    """(thread CPU s, iterations, collision checks) to the first solution, or of the whole search
    when there was none: search_time_s counted three more ways."""
    d = result.diagnostics or {}
    if result.status == "exact" and d.get("first_solution_iteration") is not None:
        return (float(d.get("first_solution_cpu_s") or 0.0), int(d["first_solution_iteration"]),
                int(d.get("first_solution_checks") or 0))
    return float(d.get("thread_cpu_s", 0.0)), int(result.iterations), int(d.get("collision_checks", 0))


def _measured(rec: CycleRecord, measures: tuple[float, int, int], reused: int = 0) -> CycleRecord:
    rec.search_cpu_s, rec.search_iterations, rec.search_checks = measures
    rec.reused_nodes = reused
    return rec


def _beside_free(grid: OccupancyGrid, pos: tuple[float, float], point: tuple[float, float], radius: float,
                 traffic: TrafficSnapshot) -> tuple[float, float] | None:
    """The free point nearest ``point`` across the direction of travel (starboard offsets first),
    inside the perceptual domain, or None."""
    dx, dy = point[0] - pos[0], point[1] - pos[1]
    d = math.hypot(dx, dy)
    if d < 1e-9:
        return None
    sx, sy = dy / d, -dx / d                      # starboard of the direction of travel (map frame)
    step = max(grid.resolution, 1.0)
    reach = max((ob.radius for ob in traffic.obstacles), default=0.0) * 3.0
    for k in range(1, int(reach / step) + 1):
        for sign in (1.0, -1.0):
            q = (point[0] + sign * k * step * sx, point[1] + sign * k * step * sy)
            if math.hypot(q[0] - pos[0], q[1] - pos[1]) <= radius and grid.is_free(*q):
                return q
    return None


def drop_short_legs(path: np.ndarray, grid: OccupancyGrid, min_leg: float) -> np.ndarray:
    """Remove interior waypoints next to a leg shorter than ``min_leg`` (m) when the bypass is
    collision free. A Dubins curve between poses closer than about one turning radius needs a
    full loop; this is the section 2.4 re-check applied before smoothing rather than after."""
    wp = [np.asarray(p, dtype=float) for p in np.asarray(path, dtype=float).reshape(-1, 2)]
    if min_leg <= 0:
        return np.array(wp).reshape(-1, 2)
    changed = True
    while changed and len(wp) > 2:
        changed = False
        for i in range(1, len(wp) - 1):
            short = (math.hypot(*(wp[i] - wp[i - 1])) < min_leg or math.hypot(*(wp[i + 1] - wp[i])) < min_leg)
            if short and grid.segment_free(float(wp[i - 1][0]), float(wp[i - 1][1]),
                                           float(wp[i + 1][0]), float(wp[i + 1][1])):
                del wp[i]
                changed = True
                break
    return np.array(wp).reshape(-1, 2)


def _densify(path: np.ndarray, step: float) -> np.ndarray:
    """The polyline with extra points at most ``step`` m apart (keeps every vertex)."""
    path = np.asarray(path, dtype=float).reshape(-1, 2)
    if len(path) < 2:
        return path.copy()
    out = [path[:1]]
    for a, b in zip(path[:-1], path[1:], strict=True):
        n = max(int(math.ceil(math.hypot(*(b - a)) / step)), 1)
        out.append(a + (b - a) * (np.arange(1, n + 1) / n)[:, None])
    return np.concatenate(out)


def _termination(online: OnlineParams, clock: Callable[[], float]) -> Termination:
    """The budget of one local planning run: iterations and/or a deadline on ``clock`` (or, with
    ``local_clock = "thread-cpu"``, on this thread's CPU clock; ``clock`` is then not read)."""
    conds = []
    if online.local_iterations > 0:
        conds.append(Termination.iterations(online.local_iterations))
    if online.local_time > 0:
        conds.append(Termination.thread_cpu_deadline(online.local_time) if online.local_clock == "thread-cpu"
                     else Termination.deadline(online.local_time, clock))
    return conds[0] if len(conds) == 1 else Termination.any_of(*conds)


def run_online(ctx: OnlineContext, start: VesselState, seed: int,
               clock: Callable[[], float] = time.monotonic,
               on_cycle: Callable[[CycleRecord], None] | None = None) -> OnlineResult:
    """Repeat :func:`plan_cycle` and :func:`advance` until the goal is reached or a cap is hit.

    ``seed`` seeds every cycle's planner (cycle ``i`` uses a seed derived from ``(seed, i)``),
    so a run with an iteration budget is reproducible.
    """
    params, online = ctx.params, ctx.online
    seeds = np.random.SeedSequence(int(seed)).generate_state(online.max_cycles, dtype=np.uint32)
    state = start
    cycles: list[CycleRecord] = []
    executed = [np.array([[start.x, start.y]])]
    waypoints: list[np.ndarray] = []
    directions: list[np.ndarray] = []
    failures = 0
    reuse: tuple[np.ndarray, np.ndarray] | None = None
    reached, reason = False, f"gave up after {online.max_cycles} cycles"
    step = params.speed * online.cycle_time
    for i in range(online.max_cycles):
        if math.hypot(ctx.goal[0] - state.x, ctx.goal[1] - state.y) <= params.goal_tolerance:
            reached, reason = True, "goal reached"
            break
        rec = plan_cycle(ctx, state, i, int(seeds[i]), clock, reuse=reuse)
        reuse = None
        cycles.append(rec)
        if len(rec.smooth_path) < 2:
            failures += 1
            if on_cycle:
                on_cycle(rec)
            if failures >= online.max_failures:
                reason = f"no local path in {failures} consecutive cycles ({rec.reason})"
                break
            state = replace(state, t=state.t + online.cycle_time)
            continue
        failures = 0
        travelled, heading = advance(rec.smooth_path, step if online.execution == "receding"
                                     else path_length(rec.smooth_path))
        rec.travelled = travelled
        executed.append(travelled[1:])
        sailed = path_length(travelled)
        wp, wd = sailed_waypoints(rec.local_path, sailed)
        waypoints.append(wp)
        directions.append(wd)
        end = travelled[-1]
        state = VesselState(float(end[0]), float(end[1]),
                            state.heading if math.isnan(heading) else heading,
                            state.t + (sailed / params.speed if params.speed > 0 else online.cycle_time))
        if online.tree_reuse:
            reuse = reusable_subtree(rec.tree_nodes, rec.tree_parents, (state.x, state.y),
                                     REUSE_TOLERANCE * ctx.grid.resolution)
        if on_cycle:
            on_cycle(rec)
    else:
        if math.hypot(ctx.goal[0] - state.x, ctx.goal[1] - state.y) <= params.goal_tolerance:
            reached, reason = True, "goal reached"
    path = np.concatenate(executed)
    sampled = resample(path, online.metric_spacing)
    # Table 3 measures every path with eq. (12), whatever objective the planner optimised.
    metrics = (path_metrics(sampled, ctx.field, ctx.grid, replace(params, objective="current"), online.clearance_sigma)
               if len(sampled) >= 2 else {})
    wps = np.concatenate(waypoints) if waypoints else np.zeros((0, 2))
    wds = np.concatenate(directions) if directions else np.zeros((0, 2))
    metrics["sum_cos_wp"], metrics["sum_sin_wp"] = waypoint_alpha_sums(wps, wds, ctx.field)
    metrics["waypoints_wp"] = float(len(wps))
    return OnlineResult(
        reached=reached, reason=reason, cycles=cycles, executed=path, final=state,
        search_time_s=float(sum(c.search_time_s for c in cycles)),
        planning_time_s=float(sum(c.planning_time_s for c in cycles)),
        search_cpu_s=float(sum(c.search_cpu_s for c in cycles)),
        search_iterations=int(sum(c.search_iterations for c in cycles)),
        search_checks=int(sum(c.search_checks for c in cycles)),
        metrics={k: float(v) for k, v in metrics.items() if np.isscalar(v)},  # type: ignore[arg-type]  # real numbers
        waypoints=wps, waypoint_directions=wds,
    )


REUSE_TOLERANCE = 0.5  # of a grid cell: how near the vessel's end of path a tree node must be to root the reused tree


def reusable_subtree(nodes: np.ndarray, parents: np.ndarray, position: tuple[float, float],
                     tolerance: float) -> tuple[np.ndarray, np.ndarray] | None:
    """Section 3.5, line 3: the part of a cycle's tree "not affected by the present USV motion":
    the subtree rooted at the node where the vessel now is (the node nearest ``position``, if
    within ``tolerance`` m; None otherwise). Returned as (nodes, parents) in breadth-first order,
    root first and moved to ``position`` exactly, parents re-indexed (-1 for the root); the
    next search keeps what is still valid there (``PlanningProblem.initial_tree``)."""
    X = np.asarray(nodes, dtype=float).reshape(-1, 2)
    P = np.asarray(parents, dtype=np.int64).reshape(-1)
    if len(X) == 0 or len(X) != len(P):
        return None
    d = np.hypot(X[:, 0] - position[0], X[:, 1] - position[1])
    root = int(np.argmin(d))
    if d[root] > tolerance:
        return None
    children: dict[int, list[int]] = {}
    for i, p in enumerate(P.tolist()):
        if p >= 0:
            children.setdefault(p, []).append(i)
    order = [root]
    k = 0
    while k < len(order):
        order.extend(children.get(order[k], ()))
        k += 1
    new_index = {old: new for new, old in enumerate(order)}
    out_x = X[order].copy()
    out_x[0] = position
    out_p = np.array([-1] + [new_index[int(P[i])] for i in order[1:]], dtype=np.int64)
    return out_x, out_p


def sailed_waypoints(local_path: np.ndarray, sailed: float) -> tuple[np.ndarray, np.ndarray]:
    """The waypoints of a cycle's pruned local path that the vessel left in that cycle (those
    before ``sailed`` metres along the path, its last point never: the next cycle starts there
    or the run ends) and the direction of the leg leaving each (unit vectors)."""
    p = np.asarray(local_path, dtype=float).reshape(-1, 2)
    if len(p) < 2:
        return np.zeros((0, 2)), np.zeros((0, 2))
    legs = np.diff(p, axis=0)
    lengths = np.hypot(legs[:, 0], legs[:, 1])
    arc = np.concatenate([[0.0], np.cumsum(lengths)[:-1]])
    keep = (arc < sailed) & (lengths > 1e-12)
    return p[:-1][keep], legs[keep] / lengths[keep, None]


def make_context(grid: OccupancyGrid, goal: tuple[float, float], reference_path: np.ndarray,
                 params: PlannerParams, online: OnlineParams, algorithm: str,
                 field: DisturbanceField | None = None) -> OnlineContext:
    """An :class:`OnlineContext` for ``algorithm`` (one of ``planner.ALGORITHMS``)."""
    return OnlineContext(grid=grid, goal=(float(goal[0]), float(goal[1])), reference_path=reference_path,
                         params=replace(params, algorithm=algorithm), online=online, field=field)
