"""The anytime solve loop around the compiled tree core (one core, three strategies).

A strategy (RRT*, Informed RRT*, DDRRT*) only chooses the algorithm code and, for DDRRT*, the
PNG sampling node. The loop honours a :class:`~planner.termination.Termination`:

* iteration counts, ``time.monotonic`` deadlines and deadlines on the thread's CPU clock
  (``Termination.thread_cpu_deadline``) are checked by the compiled core before every
  iteration, so a deadline is overrun by at most one iteration;
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
from planner.field import DisturbanceField, GridField
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
_CPU_CLOCK_OK: bool | None = None


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


def compiled_cpu_clock_ok() -> bool:
    """True if the compiled core's thread CPU clock (Linux clock id 3, CLOCK_THREAD_CPUTIME_ID) is
    ``time.thread_time``'s; otherwise thread-CPU deadlines are polled from Python after every
    iteration (same one-iteration bound)."""
    global _CPU_CLOCK_OK
    if _CPU_CLOCK_OK is None:
        from planner._kernels import thread_cpu_ns

        buf = np.zeros(2, dtype=np.int64)
        thread_cpu_ns(buf)  # compiled (or loaded) before the comparison
        a = time.thread_time_ns()
        b = thread_cpu_ns(buf)
        c = time.thread_time_ns()
        _CPU_CLOCK_OK = bool(a - 5_000_000 <= b <= c + 5_000_000)
    return _CPU_CLOCK_OK


def _none(reason: str, t0: float, start: tuple[float, float] | None = None) -> PlannerResult:
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


def disturbance(problem: PlanningProblem, params: PlannerParams) -> DisturbanceField | None:
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

        cfg = _tree.new_config()
        c = cfg[0]
        c["step"] = p.step
        c["max_turn"] = p.max_turn_angle
        c["goal_tol"] = p.goal_tolerance
        c["goal_bias"] = p.goal_bias
        c["png_p"] = p.png_probability if png is not None else 0.0
        if png is not None:
            c["png_x"], c["png_y"] = png
        c["dr"] = p.dynamic_domain_radius
        c["d_alpha"] = p.d_alpha
        c["gamma"] = p.gamma_alpha
        c["rewire_gamma"] = p.rewire_gamma * gamma_star
        c["k_growth"] = p.k_growth
        c["dd0"] = math.inf if p.dynamic_domain == "off" else p.dynamic_domain_start
        adaptive = p.dynamic_domain == "adaptive"
        c["dd_grow"] = 1.0 + p.dd_alpha if adaptive else 1.0
        c["dd_shrink"] = 1.0 - p.dd_alpha if adaptive else 1.0
        c["dd_min"] = min(p.dd_min_factor * p.step, p.dynamic_domain_start)
        c["f_min"] = min_cost_factor(p.d_alpha, p.gamma_alpha) if field is not None else 1.0
        c["bucket"] = bucket
        c["bx0"], c["bx1"], c["by0"], c["by1"] = bx0, bx1, by0, by1
        if problem.domain_center is not None and problem.domain_radius is not None:
            c["dom_cx"], c["dom_cy"] = problem.domain_center
            c["dom_r"] = problem.domain_radius
        c["gx"], c["gy"] = gx, gy
        c["sx"], c["sy"] = sx, sy
        c["res"] = grid.resolution
        if field is not None:
            world = _tree.World(grid._u8, field.vx, field.vy)
            c["field_res"] = field.resolution
            c["field_ox"], c["field_oy"] = field.origin
        else:
            world = _tree.World(grid._u8, _NO_FIELD, _NO_FIELD)
            c["field_res"] = 1.0
        c["algo"] = self.algorithm_code
        c["use_field"] = 1 if field is not None else 0
        c["k"] = p.k_nearest
        c["nbx"] = nbx
        c["nby"] = nby
        c["cap"] = cap
        c["use_png"] = 1 if png is not None else 0
        c["fail_turn"] = 1 if p.failed_extension == "collision+turn" else 0
        c["png_repair"] = 1 if p.png_repair else 0

        tree = _tree.new_tree(cap, nbx * nby, field is not None)
        tree.X[0] = (sx, sy)
        if field is not None:
            _tree.node_direction(0, sx, sy, world, cfg, tree)
        tree.parent[0] = -1
        tree.cost[0] = 0.0
        tree.dd[0] = np.inf
        tree.first_child[0] = -1
        tree.next_sib[0] = -1
        tree.head[0] = np.nan if problem.start_heading is None else float(problem.start_heading)
        tree.node_next[0] = -1
        bx, by = min(int(sx / bucket), nbx - 1), min(int(sy / bucket), nby - 1)
        tree.bucket_head[by * nbx + bx] = 0
        state = _tree.new_state()
        st = state[0]
        st["n"] = 1
        st["goal"] = -1
        st["closest"] = 0
        st["closest_d"] = math.hypot(gx - sx, gy - sy)
        st["first_ns"] = -1.0
        scratch = _tree.new_scratch()
        reused = 0
        if problem.initial_tree is not None:
            nodes, parents = problem.initial_tree
            nodes = np.ascontiguousarray(nodes, dtype=np.float64).reshape(-1, 2)
            parents = np.ascontiguousarray(parents, dtype=np.int64).reshape(-1)
            if len(nodes) != len(parents):
                raise ValueError("initial_tree: nodes and parents differ in length")
            if len(nodes) > 1:
                reused = int(_tree.seed_tree(world, cfg, tree, state, scratch.clock, nodes, parents))

        bounds = termination.bounds()
        deadline_ns = -1 if bounds.monotonic_deadline is None else int(bounds.monotonic_deadline * 1e9)
        if deadline_ns >= 0 and not compiled_clock_ok():
            deadline_ns = -1
            bounds = dataclasses.replace(bounds, poll_python=True)
        cpu_deadline_ns = -1 if bounds.thread_cpu_deadline is None else int(bounds.thread_cpu_deadline * 1e9)
        if cpu_deadline_ns >= 0 and not compiled_cpu_clock_ok():
            cpu_deadline_ns = -1
            bounds = dataclasses.replace(bounds, poll_python=True)
        _tree.seed_rng(self.seed)
        grow = _tree.grow_kernel(int(cfg[0]["algo"]))
        why = "termination condition met"
        while True:
            termination.notify(int(st["iter"]), bool(st["goal"] >= 0))
            if termination():
                break
            if bounds.poll_python:
                budget = 1
            elif bounds.max_iterations is not None:
                budget = max(0, bounds.max_iterations - int(st["iter"]))
            else:
                budget = _BIG
            code = grow(world, cfg, tree, state, scratch, budget, deadline_ns, bounds.stop_on_exact,
                              cpu_deadline_ns)
            if code == _tree.DONE_DEADLINE:
                why = "deadline reached"
                break
            if code == _tree.DONE_FULL:
                why = f"tree full (max_nodes = {cap})"
                break
        termination.notify(int(st["iter"]), bool(st["goal"] >= 0))
        cpu_s = (time.thread_time_ns() - cpu0_ns) * 1e-9
        res = self._result(problem, t0, tree, st, why, cpu_s, cpu0_ns, png)
        res.diagnostics["reused_nodes"] = reused
        return res

    def _result(self, problem: PlanningProblem, t0: float, tree: _tree.Tree, st: np.void, why: str, cpu_s: float = 0.0,
                cpu0_ns: int = 0, png: tuple[float, float] | None = None) -> PlannerResult:
        """The result of a search: the path to the goal (or to the closest node), the tree, the
        kernel's counters; ``st`` is the kernel's state record."""
        X, parent, cost, dd = tree.X, tree.parent, tree.cost, tree.dd
        n = int(st["n"])
        goal = int(st["goal"])
        if goal >= 0:
            status, end = "exact", goal
            reason = f"goal reached; {why}"
        else:
            end = int(st["closest"])
            if end == 0:
                status, reason = "none", f"no progress towards the goal from the start; {why}"
            else:
                status = "approximate"
                reason = f"goal not reached; path to the closest node ({st['closest_d']:.2f} m away); {why}"
        path = np.zeros((0, 2))
        if status != "none":
            chain: list[int] = []
            i = end
            while i >= 0 and len(chain) <= n:
                chain.append(i)
                i = int(parent[i])
            path = X[chain[::-1]].copy()
        first = None
        if st["first_ns"] >= 0:
            first = max(0.0, st["first_ns"] * 1e-9 - t0)
        c = path_cost(path, disturbance(problem, self.params), self.params) if len(path) else math.inf
        length = path_length(path) if len(path) else math.inf
        return PlannerResult(
            status=status, path=path, cost=c, length=length, iterations=int(st["iter"]),
            time_to_first_solution_s=first, planning_time_s=time.monotonic() - t0, reason=reason,
            tree_nodes=X[:n].copy(), tree_parents=parent[:n].copy(), samples_rejected=int(st["rejected"]),
            diagnostics={"collision_checks": int(st["checks"]),
                         "tree_cost": float(cost[end]) if status != "none" else math.inf,
                         "first_solution_iteration": int(st["first_iter"]) if goal >= 0 else None,
                         "algorithm": self.name,
                         "dynamic_domains": int(np.sum(np.isfinite(dd[:n]))),  # DDRRT* nodes with a bounded DD
                         "failed_extensions": int(st["failed"]),  # DDRRT*: failed parent attempts
                         "failed_turns": int(st["failed_turn"]),  # of which refused by the fan
                         # time to the first solution measured four ways (issue 34 point 4)
                         "first_solution_checks": int(st["first_checks"]) if goal >= 0 else None,
                         "first_solution_cpu_s": max(0.0, (st["first_cpu_ns"] - cpu0_ns) * 1e-9)
                         if goal >= 0 else None,
                         "thread_cpu_s": cpu_s,  # thread CPU time of the search (as planning_time_s, less the result)
                         "png_node": None if png is None else [float(png[0]), float(png[1])],
                         "png_reached": bool(st["png_hit"]),
                         "png_wasted": int(st["png_wasted"]),  # PNG samples on an existing node
                         },
        )
