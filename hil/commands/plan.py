"""`hil plan`: one planning query on a map (or a scenario), printed as JSON and optionally plotted."""

from __future__ import annotations

import argparse
import math
import time
from pathlib import Path
from typing import TYPE_CHECKING

from hil import console
from hil.errors import UsageError
from hil.files import PLOT_SUFFIXES, check_output_file
from hil.scenario_names import available as scenario_names
from planner.params import ALGORITHM_NAMES, SEED_MAX

if TYPE_CHECKING:
    import numpy as np

    from hil.scenario import Scenario
    from hil.settings import HilConfig
    from planner.field import DisturbanceField
    from planner.gridmap import OccupancyGrid
    from planner.params import PlannerParams
    from planner.result import PlannerResult

ALGORITHMS = ALGORITHM_NAMES


def _point(text: str) -> tuple[float, float]:
    parts = text.split(",")
    try:
        if len(parts) != 2:
            raise ValueError
        x, y = float(parts[0]), float(parts[1])
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected X,Y in metres (e.g. 5,12.5), got {text!r}") from None
    if not (math.isfinite(x) and math.isfinite(y)):
        raise argparse.ArgumentTypeError(f"expected finite X,Y, got {text!r}")
    return x, y


def _angle(text: str) -> float:
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected an angle in radians, got {text!r}") from None
    if not math.isfinite(value):
        raise argparse.ArgumentTypeError(f"expected a finite angle in radians, got {text!r}")
    return value


def _current(text: str) -> str | tuple[float, float]:
    if text in ("none", "config"):
        return text
    try:
        return _point(text)
    except argparse.ArgumentTypeError:
        raise argparse.ArgumentTypeError(f"expected none, config or VE,VN in m/s (e.g. 0.3,-0.1), got {text!r}") \
            from None


def wave_drift(settings: HilConfig) -> tuple[float, float] | None:
    """The vessel's steady drift under the mean wave force of eq. (6) (m/s, map frame: x east,
    y north), or None with waves off: the following-seas surge force 0.5 rho alpha^2 L C_X over the
    surge damping d_u, towards the waves' mean direction (NED, clockwise from north). The drift
    the current causes is the current itself, so the two add as velocities: alpha_y = "resultant"
    measures eq. (12)'s angle against their sum."""
    w, v = settings.waves, settings.vessel
    if not w.enabled:
        return None
    speed = 0.5 * v.rho * w.amplitude ** 2 * v.L * w.C_X / v.d_u
    return speed * math.sin(w.direction), speed * math.cos(w.direction)


def add_parser(sub: argparse._SubParsersAction, parents: list[argparse.ArgumentParser]) -> None:
    p = sub.add_parser(
        "plan", parents=parents,
        help="plan one path on a map or a scenario (RRT*, Informed-RRT*, DDRRT*)",
        description="Plan one path from --start to --goal on an occupancy map (x east, y north, metres; "
                    "map row 0 at y = 0) or on a scenario of configs/scenarios/. Obstacles are inflated by "
                    "the [planner] safety_radius (or --inflate). Exit 0 with a path to the goal, 1 when none "
                    "was found within the budget (status 'approximate': the path to the node closest to the "
                    "goal, still printed; or 'none'), 2 on bad input.",
    )
    src = p.add_argument_group("problem (either --scenario or --map/--resolution/--start/--goal)")
    src.add_argument("--scenario", metavar="NAME",
                     help=f"take map, start, goal, heading and current from configs/scenarios/NAME.toml "
                          f"({', '.join(scenario_names('fixed'))})")
    src.add_argument("--map", metavar="FILE", type=Path,
                     help="occupancy map: .npy (bool/0-1) or .png (dark = obstacle)")
    src.add_argument("--resolution", metavar="R", type=float, help="map cell size (m per cell, > 0)")
    src.add_argument("--start", metavar="X,Y", type=_point, help="start position (m, map frame)")
    src.add_argument("--goal", metavar="X,Y", type=_point, help="goal position (m, map frame)")
    src.add_argument("--heading", metavar="RAD", type=_angle, default=None,
                     help="start heading (rad, counter-clockwise from east); enables the turning-radius fan at the "
                          "root (default: the scenario's, none with --map)")
    src.add_argument("--current", metavar="C", type=_current, default=None,
                     help="the current eq. (12) is costed in: 'config' (the [current] of the configuration, eq. (13), "
                          "frozen at t = 0), VE,VN (uniform, m/s east and north) or 'none'. Default: the scenario's "
                          "current (built from [current] and its --set overrides), none with --map")
    alg = p.add_argument_group("planner")
    alg.add_argument("--algorithm", choices=ALGORITHMS, default=None,
                     help="planner (default: [planner] algorithm of the configuration)")
    alg.add_argument("--objective", choices=("length", "current"), default=None,
                     help="path cost: Euclidean length, or eq. (12) with the scenario's current "
                          "(default: [planner] objective; 'current' without a current field is the length)")
    alg.add_argument("--deadline", metavar="S", type=float, default=1.0,
                     help="time budget of the search (s, default 1.0). The clock starts after the one-off set-up "
                          "(loading or compiling the planner, inflating and labelling the map), which is timed and "
                          "reported separately (warm_up_s, setup_s)")
    alg.add_argument("--iterations", metavar="N", type=int, default=0,
                     help="also stop after N iterations (0 = no iteration cap, the default)")
    alg.add_argument("--seed", metavar="N", type=int, default=None, help="random seed (default: [planner] seed)")
    alg.add_argument("--inflate", metavar="M", type=float, default=None,
                     help="obstacle inflation radius (m, default: [planner] safety_radius)")
    out = p.add_argument_group("output")
    out.add_argument("--plot", metavar="PNG", type=Path, help="write a plot of the map, tree and path")
    out.add_argument("--tree", action="store_true", help="include the tree (nodes, parents) in the JSON")
    p.set_defaults(func=run)


# (occ, resolution m/cell, start, goal m, heading rad or None, scenario or None, planner overrides, label)
ProblemInputs = tuple["np.ndarray", float, tuple[float, float], tuple[float, float], "float | None",
                      "Scenario | None", dict[str, object], str]


def _problem_inputs(args: argparse.Namespace, settings: HilConfig) -> ProblemInputs:
    """(occ, resolution, start, goal, heading (None: --map without --heading), the scenario or None,
    its planner overrides, label)"""
    from hil import scenario as scenarios

    if args.scenario:
        if args.map is not None or args.resolution is not None:
            raise UsageError("--scenario already names the map: do not combine it with --map/--resolution")
        spec = scenarios.load_spec(args.scenario)
        sc = scenarios.instance(spec, None, base_current=settings.current,
                                safety_radius=settings.planner.safety_radius)
        start = args.start or sc.start
        goal = args.goal or sc.goal
        heading = args.heading if args.heading is not None else sc.start_heading
        return sc.occ, sc.resolution, start, goal, heading, sc, sc.planner_overrides, sc.name
    missing = [o for o, v in (("--map", args.map), ("--resolution", args.resolution), ("--start", args.start),
                              ("--goal", args.goal)) if v is None]
    if missing:
        raise UsageError(f"missing {', '.join(missing)} (or use --scenario NAME)")
    if not (args.resolution > 0) or not math.isfinite(args.resolution):
        raise UsageError(f"--resolution must be > 0 m per cell (got {args.resolution:g})")
    if not args.map.exists():
        raise UsageError(f"--map {args.map}: no such file")
    occ = scenarios.load_occupancy(args.map, args.resolution)
    return occ, args.resolution, args.start, args.goal, args.heading, None, {}, args.map.name


def _map_field(args: argparse.Namespace, settings: HilConfig, sc: Scenario | None
               ) -> tuple[DisturbanceField | None, str]:
    """(the map-frame current or None, a phrase saying where it came from)."""
    from hil.scenario import MapFrameCurrent

    choice = args.current
    if choice is None:
        if sc is None:
            return None, "--map has no current of its own"
        f = sc.map_field()
        return f, (f"scenario {sc.name}'s current" if f is not None else f"scenario {sc.name}: current disabled")
    if choice == "none":
        return None, "--current none"
    if choice == "config":
        if not settings.current.enabled:
            return None, "[current] enabled = false"
        from common.current_field import CurrentField
        return MapFrameCurrent(CurrentField(settings.current), 0.0), "[current] of the configuration at t = 0"
    ve, vn = choice
    if not (abs(ve) <= 10.0 and abs(vn) <= 10.0):
        raise UsageError(f"--current {ve:g},{vn:g}: each component must be within +-10 m/s")
    from planner.field import GridField
    return GridField.uniform(ve, vn), f"uniform {ve:g},{vn:g} m/s (east, north)"


def _judged(grid: OccupancyGrid, map_field: DisturbanceField | None, params: PlannerParams,
            start: tuple[float, float], goal: tuple[float, float], path: np.ndarray) -> dict[str, float]:
    """The path's eq. (12) cost and the least one (hil.flow_optimum, independent of the planner),
    computed after the search: the current itself (not the planner's 1 m grid of it), pieces of
    0.25 m."""
    from hil.flow_optimum import FlowJudge

    t0 = time.monotonic()
    judge = FlowJudge(grid.occ, grid.resolution, map_field, params.d_alpha, params.gamma_alpha)
    best = judge.optimum((float(start[0]), float(start[1])), (float(goal[0]), float(goal[1])))
    cost = judge.path_cost(path)
    console.progress(f"hil plan: eq. (12) optimum {best.cost:.2f} (judge, {time.monotonic() - t0:.1f} s); "
                     f"this path {cost:.2f}: {cost / best.cost:.4f} x the optimum")
    return {"cost_judged": cost, "optimum": best.cost, "cost_over_optimum": cost / best.cost}


def _ddrrt_hint(params: PlannerParams, result: PlannerResult, grid: OccupancyGrid) -> str | None:
    """Why DDRRT* failed where the ESD test threw away most samples, and what to use instead."""
    if params.algorithm != "ddrrt-star" or result.status == "exact" or not result.iterations:
        return None
    if result.samples_rejected < 0.5 * result.iterations:
        return None
    # eq. (11) at its largest (alpha_y = 0)
    esd_max = params.d_alpha * params.dynamic_domain_radius / (1.0 + math.exp(-1.0))
    return (f"DDRRT* rejected {result.samples_rejected} of {result.iterations} samples by its ESD test (a sample "
            f"farther than at most {esd_max:.0f} m from the tree, eq. (11)): it is the paper's local planner for a "
            f"{params.perceptual_radius:g} m perceptual domain, not for a {grid.width:g} m x {grid.height:g} m map; "
            f"use --algorithm rrt-star or informed-rrt-star there")


def run(args: argparse.Namespace) -> int:
    from dataclasses import replace

    from hil import numba_env

    numba_env.apply()   # before the planner's import

    import numpy as np

    from hil import scenario as scenarios
    from hil.first_run import COLD_PLAN_COMPILE_S, PLANNER_SOURCES, compile_notice
    from planner import make_planner, warm_up_info
    from planner.core import free_regions
    from planner.field import GridField
    from planner.gridmap import OccupancyGrid
    from planner.problem import PlanningProblem
    from planner.termination import Termination

    if not (args.deadline > 0) or not math.isfinite(args.deadline):
        raise UsageError(f"--deadline must be a positive number of seconds (got {args.deadline:g})")
    if args.iterations < 0:
        raise UsageError("--iterations must be >= 0")
    if args.inflate is not None and not (args.inflate >= 0):
        raise UsageError("--inflate must be >= 0 m")
    if args.plot is not None:
        check_output_file(args.plot, "--plot", PLOT_SUFFIXES)
    settings = console.load_settings(args)
    occ, res, start, goal, heading, sc, overrides, label = _problem_inputs(args, settings)
    params = scenarios.planner_params(scenarios.base_planner_params(settings), overrides,
                                      f"scenario {label}")
    params = scenarios.with_overrides(params, algorithm=args.algorithm, objective=args.objective, seed=args.seed,
                                      safety_radius=args.inflate)
    if not 0 <= params.seed <= SEED_MAX:
        raise UsageError(f"--seed must be in 0..{SEED_MAX} (the planner's generator holds a signed 64-bit integer)")
    raw = OccupancyGrid(occ, res)
    for what, pt in (("--start", start), ("--goal", goal)):
        if not raw.contains(*pt):
            raise UsageError(f"{what} {pt[0]:g},{pt[1]:g}: outside the {raw.width:g} m x {raw.height:g} m map")
        if not raw.is_free(*pt):
            raise UsageError(f"{what} {pt[0]:g},{pt[1]:g}: inside an obstacle")
    # One-off costs first, each timed, so that --deadline is the search alone. The inputs are checked by now: a
    # user's mistake is one line, with no compile notice before it.
    notice = compile_notice("hil plan", COLD_PLAN_COMPILE_S, PLANNER_SOURCES, algorithm=params.algorithm)
    if notice:
        console.progress(notice)
    warm = warm_up_info((params.algorithm,))   # only the kernels this planner runs
    if warm.compiled:
        console.progress(f"hil plan: compiled the planner (cold numba cache) in {warm.seconds:.1f} s, "
                         f"before the clock started")
    t_setup = time.monotonic()
    grid = raw.inflate(params.safety_radius) if params.safety_radius > 0 else raw
    for what, pt in (("--start", start), ("--goal", goal)):
        if not grid.is_free(*pt):  # the planner neither starts nor ends in the inflated map's obstacles
            raise UsageError(f"{what} {pt[0]:g},{pt[1]:g}: within the {params.safety_radius:g} m safety margin of an "
                             f"obstacle or the map edge (the map inflated by [planner] safety_radius); move it "
                             f"or lower --inflate")
    free_regions(grid)  # labelled once here (cached on the grid), not inside the search budget
    map_field, current_source = _map_field(args, settings, sc)
    field = None
    if params.objective == "current" and map_field is not None:
        field = GridField.sample(map_field, raw.width, raw.height, 1.0)
    if params.objective == "current" and field is None:
        console.progress(f"hil plan: no current ({current_source}): --objective current costs the length; "
                         f"give --current config or --current VE,VN")
    drift = wave_drift(settings) if params.alpha_y == "resultant" else None
    problem = PlanningProblem(grid=grid, start=(float(start[0]), float(start[1])),
                              goal=(float(goal[0]), float(goal[1])), start_heading=heading, field=field,
                              wave_drift=drift)
    setup_s = time.monotonic() - t_setup
    console.progress(f"hil plan: {params.algorithm} on {label} ({raw.width:g} m x {raw.height:g} m), "
                     f"budget {args.deadline:g} s, seed {params.seed}; set-up {setup_s * 1e3:.1f} ms")
    conds = [Termination.deadline(args.deadline)]
    if args.iterations:
        conds.append(Termination.iterations(args.iterations))
    termination = conds[0] if len(conds) == 1 else Termination.any_of(*conds)
    result = make_planner(params.algorithm, replace(params, seed=params.seed)).solve(problem, termination)
    summary = {
        "status": result.status,
        "reason": result.reason,
        "algorithm": params.algorithm,
        "objective": params.objective,
        "seed": params.seed,
        "start": list(start),
        "goal": list(goal),
        "path": np.asarray(result.path).tolist(),
        "cost": result.cost if result.status != "none" else None,
        "length": result.length if result.status != "none" else None,
        "iterations": result.iterations,
        "time_to_first_solution_s": result.time_to_first_solution_s,
        "planning_time_s": result.planning_time_s,
        "iterations_per_s": result.iterations / result.planning_time_s if result.planning_time_s > 0 else None,
        "setup_s": setup_s,
        "warm_up_s": warm.seconds,
        "compiled": warm.compiled,
        "tree_size": int(len(result.tree_nodes)),
        "samples_rejected": result.samples_rejected,
        "current": (current_source if field is not None else f"none ({current_source})"
                    if params.objective == "current" else f"not used: objective length ({current_source})"),
    }
    if field is not None and result.status == "exact":
        summary.update(_judged(grid, map_field, params, start, goal, result.path))
    hint = _ddrrt_hint(params, result, raw)
    if hint:
        summary["hint"] = hint
        console.progress(f"hil plan: hint: {hint}")
    if args.tree:
        summary["tree_nodes"] = np.asarray(result.tree_nodes).tolist()
        summary["tree_parents"] = np.asarray(result.tree_parents).tolist()
    if args.plot:
        from hil.plots import plot_plan
        plot_plan(args.plot, occ, res, start, goal, result, inflated=grid.occ,
                  field=map_field,
                  title=f"{params.algorithm} on {label}: {result.status}")
        summary["plot"] = str(args.plot)
        console.progress(f"hil plan: plot written to {args.plot}")
    console.emit(args, summary)
    return 0 if result.status == "exact" else 1   # 'approximate' stops short of the goal
