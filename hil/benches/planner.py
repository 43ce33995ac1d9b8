"""`hil bench planner`: speed and convergence of the three planners, against the exact optimum and OMPL.

For each map (sparse discs, a bug trap, a maze with narrow doors: the ``bench_*`` scenarios)
and algorithm, in one process, length objective, no inflation, no turning-radius fan:

* iterations per second (the 1 s runs: iterations / planning time);
* time to the first solution (median over seeds; stop at the first exact solution);
* path length at the 0.05, 0.2 and 1 s budgets as a ratio to the optimum (median over seeds),
  the optimum being the visibility-graph shortest path of ``hil.optimum`` on the same grid.

* the end-to-end wait of ``hil plan --scenario MAP --deadline B`` for every budget B: the whole
  process as a user sees it (interpreter start, imports, loading the compiled planner, set-up,
  search, output), with the one-off costs reported apart (``warm_up_s``, ``setup_s`` and the
  rest, ``startup_s``) next to the search time.

If the ``ompl`` Python package is importable, OMPL's geometric RRT* (RealVector(2) space, a
Python state-validity checker on the same grid, the same range and goal) runs on the same maps
and budgets, and the report gives our/OMPL ratios. ``ompl`` is not a project dependency
(``pip install ompl`` to include it).
"""

from __future__ import annotations

import argparse
import importlib
import math
import statistics
import time
from collections.abc import Callable, Sequence
from dataclasses import replace
from typing import TYPE_CHECKING

from common.tables import JsonTable
from hil import console
from hil.errors import UsageError
from planner.params import ALGORITHM_NAMES

if TYPE_CHECKING:
    import numpy as np
    import numpy.typing as npt

    from hil.flow_optimum import FlowJudge
    from planner.field import DisturbanceField, GridField
    from planner.params import PlannerParams
    from planner.problem import PlanningProblem

MAPS = ("bench_discs", "bench_bugtrap", "bench_maze")
CURRENT_MAPS = ("labyrinth", "harbour", "island")
ALGORITHMS = ALGORITHM_NAMES
BUDGETS = (0.05, 0.2, 1.0)
FIRST_SOLUTION_CAP_S = 2.0
TARGETS = {"iterations_per_s": 15000.0, "first_solution_s": 0.040, "ratio_0.2": 1.03, "ratio_1": 1.01}


def _floats(text: str) -> tuple[float, ...]:
    try:
        vals = tuple(float(v) for v in text.split(",") if v.strip())
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected comma-separated seconds, got {text!r}") from None
    if not vals or any(not (v > 0) or not math.isfinite(v) for v in vals):
        raise argparse.ArgumentTypeError("budgets must be positive seconds")
    return vals


def _names(choices: tuple[str, ...]) -> Callable[[str], tuple[str, ...]]:
    def parse(text: str) -> tuple[str, ...]:
        names = tuple(n.strip() for n in text.split(",") if n.strip())
        bad = [n for n in names if n not in choices]
        if bad or not names:
            raise argparse.ArgumentTypeError(f"unknown {', '.join(bad) or '(none)'}; choose from {','.join(choices)}")
        return names
    return parse


def add_parser(sub: argparse._SubParsersAction, parents: list[argparse.ArgumentParser]) -> None:
    p = sub.add_parser(
        "planner", parents=parents,
        help="planner speed and convergence vs the exact optimum (and OMPL's RRT* when installed)",
        description=__doc__.split("\n\n", 1)[1] if __doc__ else None,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument("--maps", type=_names(MAPS + CURRENT_MAPS), default=MAPS, metavar="LIST",
                   help=f"comma-separated maps (default {','.join(MAPS)}; also {','.join(CURRENT_MAPS)}, "
                        f"which have a current)")
    p.add_argument("--algorithms", type=_names(ALGORITHMS), default=ALGORITHMS, metavar="LIST",
                   help=f"comma-separated planners (default {','.join(ALGORITHMS)})")
    p.add_argument("--seeds", type=int, default=5, metavar="N", help="seeds per measurement (median; default 5)")
    p.add_argument("--budgets", type=_floats, default=BUDGETS, metavar="S,S,...",
                   help="time budgets for the cost ratios (s, default 0.05,0.2,1)")
    p.add_argument("--quick", action="store_true",
                   help="CI-size run: 2 seeds, budgets 0.05,0.2 s (overrides --seeds and --budgets)")
    p.add_argument("--no-ompl", action="store_true", help="do not run OMPL even if it is installed")
    p.add_argument("--no-end-to-end", action="store_true",
                   help="skip the end-to-end `hil plan --deadline B` processes")
    p.add_argument("--objective", choices=("length", "current"), default="length",
                   help="length (default; against the exact shortest path) or current: eq. (12) in the scenario's "
                        "current, each path costed by hil.flow_optimum and divided by its optimum (issue 34); "
                        "OMPL and the end-to-end runs are skipped")
    p.add_argument("--step", type=float, default=None, metavar="M",
                   help="extension length / OMPL range (m, default: [planner] step)")
    p.set_defaults(func=run)


class IslandWorld:
    """Issue 34 point 6: a 60 m x 40 m sound with an island (x 15-45 m, y 15-30 m) and a stream
    circling it, 0.5 m/s east in the north channel (y > 22.5 m) and west in the south one. Start
    (3, 10) and goal (57, 10) lie by the south channel: the shortest path (61.0 m) goes south,
    against the stream; eq. (12)'s optimum goes round the north, with it."""

    name = "island"
    resolution = 0.5
    start = (3.0, 10.0)
    goal = (57.0, 10.0)
    start_heading = 0.0

    def __init__(self) -> None:
        import numpy as np

        occ = np.zeros((80, 120), dtype=bool)
        occ[30:60, 30:90] = True
        self.occ = occ

    @staticmethod
    def map_field() -> DisturbanceField:
        import numpy as np

        def stream(x: npt.ArrayLike, y: npt.ArrayLike) -> tuple[np.ndarray, np.ndarray]:
            x = np.asarray(x, dtype=float)
            y = np.asarray(y, dtype=float)
            vx = np.where(y > 22.5, 0.5, -0.5) + 0.0 * x
            return vx, np.zeros_like(vx)
        return stream

    def planning_field(self) -> GridField:
        from planner.field import GridField
        return GridField.sample(self.map_field(), 60.0, 40.0, 0.5)


def _median(values: Sequence[float | None]) -> float | None:
    vals = [v for v in values if v is not None]
    if not vals:
        return None
    return float(statistics.median(vals))


class OursRunner:
    """Runs one of our planners on a fixed problem with a given budget."""

    def __init__(self, algorithm: str, params: PlannerParams, problem: PlanningProblem,
                 judge: FlowJudge | None = None) -> None:
        self.algorithm, self.params, self.problem = algorithm, replace(params, algorithm=algorithm), problem
        self.judge = judge  # hil.flow_optimum.FlowJudge: "length" is then the path's eq. (12) cost

    def solve(self, seed: int, budget_s: float, first: bool = False) -> JsonTable:
        from planner import make_planner
        from planner.termination import Termination
        planner = make_planner(self.algorithm, replace(self.params, seed=seed))
        term = Termination.deadline(budget_s)
        if first:
            term = Termination.any_of(Termination.exact_solution(), term)
        r = planner.solve(self.problem, term)
        value = r.length if self.judge is None else (self.judge.path_cost(r.path) if len(r.path) > 1 else 0.0)
        return {"exact": r.status == "exact", "length": value if r.status == "exact" else math.inf,
                "iterations": r.iterations, "time": r.planning_time_s,
                "first": r.time_to_first_solution_s if r.status == "exact" else None}


class OmplRunner:
    """OMPL's geometric RRT* on the same grid, with a Python state-validity checker."""

    def __init__(self, occ: np.ndarray, resolution: float, start: tuple[float, float], goal: tuple[float, float],
                 step: float) -> None:
        from ompl import base as ob
        from ompl import geometric as og
        from ompl import util as ou
        ou.setLogLevel(ou.LogLevel.LOG_NONE) if hasattr(ou.LogLevel, "LOG_NONE") else None
        self.ob, self.og = ob, og
        self.occ, self.res = occ, resolution
        h, w = occ.shape[0] * resolution, occ.shape[1] * resolution
        space = ob.RealVectorStateSpace(2)
        bounds = ob.RealVectorBounds(2)
        bounds.setLow(0, 0.0)
        bounds.setHigh(0, w)
        bounds.setLow(1, 0.0)
        bounds.setHigh(1, h)
        space.setBounds(bounds)
        self.space = space
        rows, cols = occ.shape
        free = ~occ

        def valid(state: Sequence[float]) -> bool:   # an OMPL state: its coordinates by index
            c, r = int(state[0] / resolution), int(state[1] / resolution)
            return 0 <= r < rows and 0 <= c < cols and bool(free[r, c])

        self._valid = valid
        self.start, self.goal, self.step = start, goal, step
        self.extent = max(w, h)

    def solve(self, seed: int, budget_s: float, first: bool = False) -> JsonTable:
        ob, og = self.ob, self.og
        from ompl import util as ou
        if hasattr(ou, "RNG") and hasattr(ou.RNG, "setSeed"):
            try:
                ou.RNG.setSeed(int(seed) + 1)
            except Exception:  # only allowed before the first RNG is created; then keep OMPL's stream
                pass
        si = ob.SpaceInformation(self.space)
        si.setStateValidityChecker(self._valid)
        # Check motions every quarter cell, as a fraction of the space's extent.
        si.setStateValidityCheckingResolution(0.25 * self.res / self.extent)
        si.setup()
        pdef = ob.ProblemDefinition(si)
        s, g = self.space.allocState(), self.space.allocState()
        s[0], s[1] = self.start
        g[0], g[1] = self.goal
        pdef.setStartAndGoalStates(s, g, 1e-6)
        objective = ob.PathLengthOptimizationObjective(si)
        if first:
            # RRT* stops as soon as the best solution satisfies the objective: any solution does.
            objective.setCostThreshold(ob.Cost(math.inf))
        pdef.setOptimizationObjective(objective)
        planner = og.RRTstar(si)
        planner.setRange(self.step)
        planner.setProblemDefinition(pdef)
        planner.setup()
        t0 = time.monotonic()
        planner.solve(budget_s)
        dt = time.monotonic() - t0
        exact = bool(pdef.hasExactSolution())
        length = pdef.getSolutionPath().length() if exact else math.inf
        return {"exact": exact, "length": length, "iterations": int(planner.numIterations()), "time": dt,
                "first": dt if (first and exact) else None}


def _measure(runner: OursRunner | OmplRunner, seeds: list[int], budgets: tuple[float, ...], optimum: float,
             label: str) -> JsonTable:
    firsts: list[float | None] = []
    ratios: dict[float, list[float]] = {b: [] for b in budgets}
    rates: list[float] = []
    for s in seeds:
        firsts.append(runner.solve(s, FIRST_SOLUTION_CAP_S, first=True)["first"])
        for b in budgets:
            r = runner.solve(s, b)
            ratios[b].append(r["length"] / optimum if r["exact"] else math.inf)
            if b == max(budgets) and r["time"] > 0:
                rates.append(r["iterations"] / r["time"])
        console.progress(f"  {label}: seed {s} done")
    return {
        "iterations_per_s": _median(rates),
        "first_solution_s": _median(firsts),
        "first_solution_found": sum(f is not None for f in firsts),
        "ratio": {f"{b:g}": _median(ratios[b]) for b in budgets},
        "solved": {f"{b:g}": int(sum(math.isfinite(x) for x in ratios[b])) for b in budgets},
    }


def end_to_end(map_name: str, algorithm: str, budget_s: float, args: argparse.Namespace) -> JsonTable:
    """Wall time of one `hil plan --scenario MAP --deadline B` process (s), split into the search
    and the one-off costs the command reports (warm-up, set-up; startup_s = the rest)."""
    import json
    import subprocess
    import sys

    cmd = [sys.executable, "-m", "hil", "plan", "--scenario", map_name, "--algorithm", algorithm, "--objective",
           "length", "--inflate", "0", "--deadline", f"{budget_s:g}", "--seed", "1", "--json"]
    if getattr(args, "config", None):
        cmd[3:3] = ["--config", str(args.config)]
    for ov in getattr(args, "overrides", []) or []:
        cmd[3:3] = ["--set", ov]
    t0 = time.monotonic()
    proc = subprocess.run(cmd, capture_output=True, text=True, timeout=600)
    wall = time.monotonic() - t0
    if proc.returncode not in (0, 1) or not proc.stdout.strip():
        return {"error": (proc.stderr.strip().splitlines() or ["no output"])[-1], "wall_s": wall}
    d = json.loads(proc.stdout)
    search, setup, warm = d["planning_time_s"], d["setup_s"], d["warm_up_s"]
    return {"algorithm": algorithm, "deadline_s": budget_s, "wall_s": wall, "search_s": search, "setup_s": setup,
            "warm_up_s": warm, "compiled": d["compiled"], "startup_s": max(0.0, wall - search - setup - warm),
            "status": d["status"], "length": d["length"]}


def run(args: argparse.Namespace) -> int:
    from hil import scenario as scenarios
    from hil.optimum import shortest_path
    from planner.gridmap import OccupancyGrid
    from planner.problem import PlanningProblem

    seeds_n, budgets = (2, (0.05, 0.2)) if args.quick else (args.seeds, args.budgets)
    if seeds_n < 1:
        raise UsageError("--seeds must be >= 1")
    settings = console.load_settings(args)
    base = scenarios.base_planner_params(settings)
    params = replace(base, objective=args.objective, safety_radius=0.0, turn_radius_factor=0.0,
                     velocity_inflation_gain=0.0, step=args.step if args.step else base.step)
    if not (params.step > 0):
        raise UsageError("--step must be > 0")
    ompl_note = "disabled (--no-ompl)"
    have_ompl = False
    if not args.no_ompl:
        try:
            importlib.import_module("ompl.base")  # the modules OmplRunner uses, not only the package
            importlib.import_module("ompl.geometric")
            have_ompl, ompl_note = True, "ompl " + getattr(importlib.import_module("ompl"), "__version__", "installed")
        except Exception as exc:  # ImportError or a broken binary wheel: report and go on
            ompl_note = f"skipped: cannot import ompl ({type(exc).__name__}: {exc}); pip install ompl to compare"
    console.progress(f"hil bench planner: {len(args.maps)} maps x {len(args.algorithms)} planners, {seeds_n} seeds, "
                     f"budgets {', '.join(f'{b:g}' for b in budgets)} s, step {params.step:g} m; OMPL: {ompl_note}")
    seeds = list(range(1, seeds_n + 1))
    report: JsonTable = {"objective": args.objective, "seeds": seeds_n, "budgets_s": list(budgets),
                              "step_m": params.step,
                              "ompl": ompl_note, "targets": TARGETS, "maps": {}}
    for name in args.maps:
        sc = IslandWorld() if name == "island" else scenarios.load(name, settings.current)
        grid = OccupancyGrid(sc.occ, sc.resolution)
        opt = shortest_path(sc.occ, sc.resolution, sc.start, sc.goal)
        if not math.isfinite(opt.length):
            raise UsageError(f"{name}: no path from start to goal")
        judge = None
        optimum = opt.length
        field = sc.planning_field() if args.objective == "current" else None
        problem = PlanningProblem(grid=grid, start=sc.start, goal=sc.goal, field=field)
        entry: JsonTable = {"optimum_m": opt.length, "optimum_vertices": opt.vertices, "planners": {}}
        console.progress(f"{name}: optimum {opt.length:.2f} m ({opt.vertices} visibility vertices)")
        if args.objective == "current":
            from hil.flow_optimum import FlowJudge
            judge = FlowJudge(sc.occ, sc.resolution, sc.map_field(), params.d_alpha, params.gamma_alpha)
            optimum = judge.optimum(sc.start, sc.goal).cost
            entry["optimum_eq12"] = optimum
            entry["shortest_path_eq12"] = short = judge.path_cost(opt.path)
            console.progress(f"{name}: eq. (12) optimum {optimum:.2f} (hil.flow_optimum); the shortest path "
                             f"costs {short:.2f} = {short / optimum:.3f} x the optimum")
        for alg in args.algorithms:
            runner = OursRunner(alg, params, problem, judge)
            runner.solve(0, 0.05)    # warm-up: numba compilation / cache load outside the timings
            entry["planners"][alg] = _measure(runner, seeds, budgets, optimum, f"{name} {alg}")
        if have_ompl and judge is None:
            try:
                orunner = OmplRunner(sc.occ, sc.resolution, sc.start, sc.goal, params.step)
                entry["ompl_rrt_star"] = m = _measure(orunner, seeds, budgets, opt.length, f"{name} ompl")
                ours = entry["planners"].get("rrt-star")
                if ours and m["iterations_per_s"]:
                    entry["rrt_star_vs_ompl"] = {
                        "iterations_per_s": (ours["iterations_per_s"] or 0) / m["iterations_per_s"],
                        **{f"ratio_{b}": (ours["ratio"][b] / m["ratio"][b]
                                          if ours["ratio"][b] and m["ratio"][b] and math.isfinite(m["ratio"][b])
                                          else None)
                           for b in ours["ratio"]},
                    }
            except Exception as exc:  # an OMPL API mismatch must not lose our own figures
                entry["ompl_rrt_star"] = {"error": f"{type(exc).__name__}: {exc}"}
        if not args.no_end_to_end and judge is None:
            alg = "ddrrt-star" if "ddrrt-star" in args.algorithms else args.algorithms[0]
            entry["end_to_end"] = [end_to_end(name, alg, b, args) for b in budgets]
            for e2e in entry["end_to_end"]:
                if "error" not in e2e:
                    e2e["length_ratio"] = (e2e["length"] / opt.length) if e2e["length"] is not None else None
        report["maps"][name] = entry
    _print_table(report)
    console.emit(args, report)
    return 0


def _f(v: object, fmt: str) -> str:
    width = int(fmt.split(".")[0] or 0)
    if v is None:
        return "-".rjust(width)
    if isinstance(v, float) and not math.isfinite(v):
        return "unsolved".rjust(width)
    return format(v, fmt)


def _print_table(report: JsonTable) -> None:
    budgets = [f"{b:g}" for b in report["budgets_s"]]
    head = (f"{'map':15} {'planner':18} {'iter/s':>9} {'first (ms)':>10} "
            + " ".join(f"{'x@' + b + 's':>8}" for b in budgets))
    lines = [head, "-" * len(head)]
    for name, e in report["maps"].items():
        rows = list(e["planners"].items())
        if isinstance(e.get("ompl_rrt_star"), dict) and "ratio" in e["ompl_rrt_star"]:
            rows.append(("OMPL rrt-star", e["ompl_rrt_star"]))
        for alg, m in rows:
            fs = m["first_solution_s"]
            lines.append(f"{name:15} {alg:18} {_f(m['iterations_per_s'], '9.0f')} "
                         f"{_f(fs * 1000 if fs is not None else None, '10.1f')} "
                         + " ".join(f"{_f(m['ratio'][b], '8.4f')}" for b in budgets))
        if "rrt_star_vs_ompl" in e:
            v = e["rrt_star_vs_ompl"]
            lines.append(f"{'':15} {'ours/OMPL RRT*':18} {_f(v['iterations_per_s'], '9.2f')} {'':>10} "
                         + " ".join(f"{_f(v.get('ratio_' + b), '8.4f')}" for b in budgets))
    e2e_lines = []
    for name, e in report["maps"].items():
        for r in e.get("end_to_end", []):
            if "error" in r:
                e2e_lines.append(f"{name:15} error: {r['error']}")
                continue
            e2e_lines.append(f"{name:15} {r['algorithm']:12} {r['deadline_s']:8g} {r['wall_s']:8.2f} "
                             f"{r['search_s']:8.3f} "
                             f"{r['setup_s'] * 1e3:9.1f} {r['warm_up_s']:8.2f} {r['startup_s']:9.2f} "
                             f"{_f(r.get('length_ratio'), '8.4f')}")
    if e2e_lines:
        lines.append("")
        lines.append(f"{'end to end':15} {'hil plan':12} {'B (s)':>8} {'wall (s)':>8} {'search':>8} {'setup ms':>9} "
                     f"{'warm-up':>8} {'startup':>9} {'x':>8}")
        lines.extend(e2e_lines)
        lines.append("(one `hil plan --scenario MAP --deadline B` process each: wall = what a user waits; search is "
                     "the budget; set-up, warm-up (numba cache load or compile) and startup (interpreter, imports, "
                     "output) are one-off costs)")
    what = "path length" if report.get("objective", "length") == "length" else "eq. (12) cost (hil.flow_optimum)"
    lines.append(f"(x@B = {what} at budget B / optimum, median over {report['seeds']} seeds, 'unsolved' = no "
                 f"exact solution in most seeds; "
                 f"targets: >= 15000 iter/s, first <= 40 ms on bug trap and maze, <= 1.03 @0.2 s, <= 1.01 @1 s)")
    console.progress("\n".join(lines))
