"""The anytime solve loop around the compiled tree core (one core, three strategies).

A strategy (RRT*, Informed RRT*, DDRRT*) only chooses the algorithm code and, for DDRRT*, the
PNG sampling node. The loop honours a :class:`~planner.termination.Termination`:

* iteration counts and ``time.monotonic`` deadlines are checked by the compiled core before
  every iteration, so a deadline is overrun by at most one iteration;
* conditions on any other clock (or custom predicates) make the core run one iteration per
  call, and the condition is evaluated in Python after each one.

A termination condition that cannot fire on its own (``exact_solution()`` alone) is refused
with ValueError: every solve is bounded by an iteration count or a deadline.
"""

from __future__ import annotations

import dataclasses
import math
import time

import numpy as np
from scipy import ndimage

from planner import _tree
from planner.cost import min_cost_factor, path_cost, path_length
from planner.field import GridField
from planner.gridmap import OccupancyGrid
from planner.params import PlannerParams
from planner.problem import PlanningProblem
from planner.result import PlannerResult
from planner.termination import Termination

FIELD_SAMPLE_RESOLUTION = 1.0  # m; a callable current is sampled this finely for the compiled core
_BIG = 1 << 62
_NO_FIELD = np.zeros((1, 1))
_NO_FIELD.flags.writeable = False  # the same array type as a GridField's: one compiled specialisation


_CLOCK_OK: bool | None = None


def compiled_clock_ok() -> bool:
    """True if the compiled core's CLOCK_MONOTONIC (Linux clock id 1) is time.monotonic's clock;
    otherwise deadlines are polled from Python after every iteration (same one-iteration bound)."""
    global _CLOCK_OK
    if _CLOCK_OK is None:
        from planner._kernels import monotonic_ns

        buf = np.zeros(2, dtype=np.int64)
        a = time.monotonic_ns()
        b = monotonic_ns(buf)
        c = time.monotonic_ns()
        _CLOCK_OK = bool(a - 5_000_000 <= b <= c + 5_000_000)
    return _CLOCK_OK


def _none(reason: str, t0: float, start=None) -> PlannerResult:
    nodes = np.zeros((0, 2)) if start is None else np.asarray([start], dtype=np.float64)
    return PlannerResult(
        status="none", path=np.zeros((0, 2)), cost=math.inf, length=math.inf, iterations=0,
        time_to_first_solution_s=None, planning_time_s=time.monotonic() - t0, reason=reason,
        tree_nodes=nodes, tree_parents=-np.ones(len(nodes), dtype=np.int64), samples_rejected=0,
    )


def free_regions(grid: OccupancyGrid) -> np.ndarray:
    """4-connected labels of the free cells (cached on the grid). 4-connectivity matches the
    segment check, which never lets a path through a corner shared by two obstacle cells."""
    labels = grid._free_labels
    if labels is None:
        labels, _ = ndimage.label(~grid.occ)
        grid._free_labels = labels
    return labels


def sampled_field(problem: PlanningProblem, params: PlannerParams | None = None) -> GridField | None:
    """The disturbance alpha_y is measured against, on a grid: the current, or (``params.alpha_y``
    = "resultant" and a wave drift given) the current plus the wave drift."""
    f = problem.field
    drift = problem.wave_drift if params is not None and params.alpha_y == "resultant" else None
    if f is None and drift is None:
        return None
    if f is None:
        return GridField.uniform(float(drift[0]), float(drift[1])) if drift is not None else None
    g = f if isinstance(f, GridField) else GridField.sample(
        f, problem.grid.width, problem.grid.height, max(FIELD_SAMPLE_RESOLUTION, problem.grid.resolution))
    if drift is None:
        return g
    return g.shifted(float(drift[0]), float(drift[1]))


def disturbance(problem: PlanningProblem, params: PlannerParams):
    """The field eq. (12)'s alpha_y is measured against (see :func:`sampled_field`); problem.field
    itself when alpha_y = "current" (the costs stay those of the caller's field)."""
    if params.alpha_y == "resultant" and problem.wave_drift is not None:
        return sampled_field(problem, params)
    return problem.field


class TreePlanner:
    """Shared solve loop. Subclasses set ``algorithm_code`` and may override :meth:`png_node`."""

    algorithm_code = _tree.RRT_STAR
    name = "rrt-star"
    uses_png = False

    def __init__(self, params: PlannerParams, seed: int | None = None) -> None:
        self.params = params
        self.seed = params.seed if seed is None else int(seed)

    # -- hooks -------------------------------------------------------------------------------
    def png_node(self, problem: PlanningProblem) -> tuple[float, float] | None:
        return None

    # -- the loop ----------------------------------------------------------------------------
    def solve(self, problem: PlanningProblem, termination: Termination, seed: int | None = None) -> PlannerResult:
        """Grow the tree until ``termination`` fires; return the best path found."""
        if not termination.is_bounded():
            raise ValueError("termination has no iteration or time bound: combine it with "
                             "Termination.iterations(n) or Termination.deadline(s)")
        t0 = time.monotonic()
        cpu0_ns = time.thread_time_ns()  # the thread's CPU clock, from the same instant as t0
        termination.reset()
        p = self.params
        grid = problem.grid
        sx, sy = map(float, problem.start)
        gx, gy = map(float, problem.goal)
        if not grid.is_free(sx, sy):
            return _none("start inside an obstacle or outside the map", t0)
        if not grid.is_free(gx, gy):
            return _none("goal inside an obstacle or outside the map", t0, (sx, sy))
        labels = free_regions(grid)
        if labels[grid.cell_of(sx, sy)] != labels[grid.cell_of(gx, gy)]:
            return _none("goal not reachable: start and goal lie in different free regions of the map "
                         "(start enclosed or goal enclosed)", t0, (sx, sy))
        if math.hypot(gx - sx, gy - sy) < 1e-9:
            path = np.array([[sx, sy]])
            return PlannerResult("exact", path, 0.0, 0.0, 0, 0.0, time.monotonic() - t0, "start is the goal",
                                 path.copy(), np.array([-1]), 0)

        field = sampled_field(problem, p) if p.objective == "current" else None
        bx0, bx1, by0, by1 = problem.sampling_box()
        if not (bx1 > bx0 and by1 > by0):
            return _none("empty sampling domain (bounds/perceptual domain outside the map)", t0, (sx, sy))
        cap = int(p.max_nodes)
        bucket = p.step
        nbx = int(math.ceil(grid.width / bucket)) + 1
        nby = int(math.ceil(grid.height / bucket)) + 1

        png = self.png_node(problem) if self.uses_png and p.png_probability > 0 else None
        self.last_png = png
        free_area = float((~grid.occ).mean()) * (bx1 - bx0) * (by1 - by0)
        gamma_star = 2.0 * math.sqrt(1.5) * math.sqrt(max(free_area, 1e-9) / math.pi)  # K&F 2011, d = 2

        fc = np.zeros(_tree.N_FCFG)
        fc[_tree.C_STEP] = p.step
        fc[_tree.C_MAXTURN] = p.max_turn_angle
        fc[_tree.C_GOALTOL] = p.goal_tolerance
        fc[_tree.C_GOALBIAS] = p.goal_bias
        fc[_tree.C_PNGP] = p.png_probability if png is not None else 0.0
        if png is not None:
            fc[_tree.C_PNGX], fc[_tree.C_PNGY] = png
        fc[_tree.C_DR] = p.dynamic_domain_radius
        fc[_tree.C_DALPHA] = p.d_alpha
        fc[_tree.C_GAMMA] = p.gamma_alpha
        fc[_tree.C_RGAMMA] = p.rewire_gamma * gamma_star
        fc[_tree.C_KGROW] = p.k_growth
        if p.dynamic_domain == "off":
            fc[_tree.C_DD0] = math.inf
        else:
            fc[_tree.C_DD0] = p.dynamic_domain_start
        adaptive = p.dynamic_domain == "adaptive"
        fc[_tree.C_DDGROW] = 1.0 + p.dd_alpha if adaptive else 1.0
        fc[_tree.C_DDSHRINK] = 1.0 - p.dd_alpha if adaptive else 1.0
        fc[_tree.C_DDMIN] = min(p.dd_min_factor * p.step, p.dynamic_domain_start)
        fc[_tree.C_FMIN] = min_cost_factor(p.d_alpha, p.gamma_alpha) if field is not None else 1.0
        fc[_tree.C_BUCKET] = bucket
        fc[_tree.C_BX0], fc[_tree.C_BX1], fc[_tree.C_BY0], fc[_tree.C_BY1] = bx0, bx1, by0, by1
        if problem.domain_center is not None and problem.domain_radius is not None:
            fc[_tree.C_DCX], fc[_tree.C_DCY] = problem.domain_center
            fc[_tree.C_DR_DOM] = problem.domain_radius
        fc[_tree.C_GX], fc[_tree.C_GY] = gx, gy
        fc[_tree.C_SX], fc[_tree.C_SY] = sx, sy
        fc[_tree.C_RES] = grid.resolution
        if field is not None:
            fvx, fvy = field.vx, field.vy
            fc[_tree.C_FRES] = field.resolution
            fc[_tree.C_FOX], fc[_tree.C_FOY] = field.origin
        else:
            fvx = fvy = _NO_FIELD
            fc[_tree.C_FRES] = 1.0
        ic = np.zeros(_tree.N_ICFG, dtype=np.int64)
        ic[_tree.I_ALGO] = self.algorithm_code
        ic[_tree.I_FIELD] = 1 if field is not None else 0
        ic[_tree.I_K] = p.k_nearest
        ic[_tree.I_NBX] = nbx
        ic[_tree.I_NBY] = nby
        ic[_tree.I_CAP] = cap
        ic[_tree.I_PNG] = 1 if png is not None else 0
        ic[_tree.I_FAILTURN] = 1 if p.failed_extension == "collision+turn" else 0
        ic[_tree.I_PNGREPAIR] = 1 if p.png_repair else 0

        # node arrays are filled as nodes are added (np.empty: no page touching for unused capacity)
        X = np.empty((cap, 2))
        parent = np.empty(cap, dtype=np.int64)
        cost = np.empty(cap)
        head = np.empty(cap)
        dd = np.empty(cap)
        first_child = np.empty(cap, dtype=np.int64)
        next_sib = np.empty(cap, dtype=np.int64)
        bucket_head = -np.ones(nbx * nby, dtype=np.int64)
        node_next = np.empty(cap, dtype=np.int64)
        st = np.zeros(_tree.N_ISTATE, dtype=np.int64)
        fs = np.zeros(_tree.N_FSTATE)
        stack = np.empty(cap, dtype=np.int64)
        nv = np.empty((cap, 2)) if field is not None else np.zeros((1, 2))  # current direction at each node
        X[0] = (sx, sy)
        if field is not None:
            _tree.node_direction(0, sx, sy, nv, fvx, fvy, fc)
        parent[0] = -1
        cost[0] = 0.0
        dd[0] = np.inf
        first_child[0] = -1
        next_sib[0] = -1
        head[0] = np.nan if problem.start_heading is None else float(problem.start_heading)
        st[_tree.S_N] = 1
        st[_tree.S_GOAL] = -1
        st[_tree.S_CLOSEST] = 0
        fs[_tree.F_CLOSEST_D] = math.hypot(gx - sx, gy - sy)
        fs[_tree.F_FIRST_NS] = -1.0
        bucket_head[:] = -1
        node_next[0] = -1
        bx, by = min(int(sx / bucket), nbx - 1), min(int(sy / bucket), nby - 1)
        bucket_head[by * nbx + bx] = 0

        bounds = termination.bounds()
        deadline_ns = -1 if bounds.monotonic_deadline is None else int(bounds.monotonic_deadline * 1e9)
        if deadline_ns >= 0 and not compiled_clock_ok():
            deadline_ns = -1
            bounds = dataclasses.replace(bounds, poll_python=True)
        occ = grid._u8
        _tree.seed_rng(self.seed)
        why = "termination condition met"
        while True:
            termination.notify(int(st[_tree.S_ITER]), bool(st[_tree.S_GOAL] >= 0))
            if termination():
                break
            if bounds.poll_python:
                budget = 1
            elif bounds.max_iterations is not None:
                budget = max(0, bounds.max_iterations - int(st[_tree.S_ITER]))
            else:
                budget = _BIG
            code = _tree.grow(occ, fvx, fvy, fc, ic, X, parent, cost, head, dd, first_child, next_sib,
                              bucket_head, node_next, st, fs, stack, nv, budget, deadline_ns, bounds.stop_on_exact)
            if code == _tree.DONE_DEADLINE:
                why = "deadline reached"
                break
            if code == _tree.DONE_FULL:
                why = f"tree full (max_nodes = {cap})"
                break
        termination.notify(int(st[_tree.S_ITER]), bool(st[_tree.S_GOAL] >= 0))
        cpu_s = (time.thread_time_ns() - cpu0_ns) * 1e-9
        return self._result(problem, t0, X, parent, cost, st, fs, why, dd, cpu_s, cpu0_ns, png)

    def _result(self, problem, t0, X, parent, cost, st, fs, why, dd, cpu_s=0.0, cpu0_ns=0, png=None) -> PlannerResult:
        n = int(st[_tree.S_N])
        goal = int(st[_tree.S_GOAL])
        if goal >= 0:
            status, end = "exact", goal
            reason = f"goal reached; {why}"
        else:
            end = int(st[_tree.S_CLOSEST])
            if end == 0:
                status, reason = "none", f"no progress towards the goal from the start; {why}"
            else:
                status = "approximate"
                reason = f"goal not reached; path to the closest node ({fs[_tree.F_CLOSEST_D]:.2f} m away); {why}"
        path = np.zeros((0, 2))
        if status != "none":
            chain: list[int] = []
            i = end
            while i >= 0 and len(chain) <= n:
                chain.append(i)
                i = int(parent[i])
            path = X[chain[::-1]].copy()
        first = None
        if fs[_tree.F_FIRST_NS] >= 0:
            first = max(0.0, fs[_tree.F_FIRST_NS] * 1e-9 - t0)
        c = path_cost(path, disturbance(problem, self.params), self.params) if len(path) else math.inf
        length = path_length(path) if len(path) else math.inf
        return PlannerResult(
            status=status, path=path, cost=c, length=length, iterations=int(st[_tree.S_ITER]),
            time_to_first_solution_s=first, planning_time_s=time.monotonic() - t0, reason=reason,
            tree_nodes=X[:n].copy(), tree_parents=parent[:n].copy(), samples_rejected=int(st[_tree.S_REJ]),
            diagnostics={"collision_checks": int(st[_tree.S_CHECKS]),
                         "tree_cost": float(cost[end]) if status != "none" else math.inf,
                         "first_solution_iteration": int(st[_tree.S_FIRST_ITER]) if goal >= 0 else None,
                         "algorithm": self.name,
                         "dynamic_domains": int(np.sum(np.isfinite(dd[:n]))),  # DDRRT* nodes with a bounded DD
                         "failed_extensions": int(st[_tree.S_FAILED]),  # DDRRT*: failed parent attempts
                         "failed_turns": int(st[_tree.S_FAILED_TURN]),  # of which refused by the fan
                         # time to the first solution measured four ways (issue 34 point 4)
                         "first_solution_checks": int(st[_tree.S_FIRST_CHECKS]) if goal >= 0 else None,
                         "first_solution_cpu_s": max(0.0, (fs[_tree.F_FIRST_CPU_NS] - cpu0_ns) * 1e-9)
                         if goal >= 0 else None,
                         "thread_cpu_s": cpu_s,  # thread CPU time of the search (as planning_time_s, less the result)
                         "png_node": None if png is None else [float(png[0]), float(png[1])],
                         "png_reached": bool(st[_tree.S_PNG_HIT]),
                         "png_wasted": int(st[_tree.S_PNG_WASTED]),  # PNG samples on an existing node
                         },
        )
