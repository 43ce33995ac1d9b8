"""`hil montecarlo`: the paper's online planning experiment (Table 3, Figures 10 and 11)."""

from __future__ import annotations

import argparse
import math
import time
from pathlib import Path
from typing import TYPE_CHECKING

from hil import console, executors
from hil.errors import RunFailed, UsageError
from hil.files import check_output_folder
from hil.scenario_names import available as scenario_names
from planner.params import ALGORITHM_NAMES

if TYPE_CHECKING:
    from hil.experiment import Campaign
    from hil.run_summary import RunSummary
    from hil.scenario import ScenarioSpec


def _algorithms(text: str) -> tuple[str, ...]:
    names = tuple(a.strip() for a in text.split(",") if a.strip())
    bad = [a for a in names if a not in ALGORITHM_NAMES]
    if bad or not names:
        raise argparse.ArgumentTypeError(
            f"unknown algorithm(s) {', '.join(bad) or '(none)'}; choose from {','.join(ALGORITHM_NAMES)}")
    if len(set(names)) != len(names):
        raise argparse.ArgumentTypeError("an algorithm is listed twice")
    return names


def add_parser(sub: argparse._SubParsersAction, parents: list[argparse.ArgumentParser]) -> None:
    p = sub.add_parser(
        "montecarlo", parents=parents,
        help="Monte Carlo of the online planning process (Table 3, Figures 10 and 11)",
        description="Run the online planning process of section 4.2 (subgoals on the global reference path, "
                    "local planning in the perceptual domain, prune + Dubins smoothing, the vessel sailing each "
                    "local path for one cycle) RUNS times per algorithm on a scenario, on J worker processes. "
                    "Writes DIR/runs.csv (one row per run), DIR/table3.csv and DIR/table3.md (Table 3 with the "
                    "changes vs RRT*), DIR/figure10.png (trees, paths, perceptual circles, current arrows of run 0) "
                    "and DIR/figure11.png (the paths of the first runs), and DIR/summary.json. Every run is seeded "
                    "from --seed and its index only, so results do not depend on --jobs; with the default iteration "
                    "budget per cycle they are reproducible (only the measured times vary). Ctrl-C stops the workers "
                    "and keeps the finished runs (so does SIGTERM).",
    )
    p.add_argument("--scenario", metavar="NAME", default="labyrinth",
                   help=f"scenario in configs/scenarios/ (default labyrinth; {', '.join(scenario_names())})")
    p.add_argument("--runs", metavar="N", type=int, default=20, help="runs per algorithm (default 20; the paper: 1000)")
    p.add_argument("--algorithms", metavar="LIST", type=_algorithms, default=ALGORITHM_NAMES,
                   help="comma-separated algorithms (default rrt-star,informed-rrt-star,ddrrt-star)")
    p.add_argument("--jobs", "-j", metavar="J", type=int, default=executors.default_jobs(),
                   help=f"worker processes (default: the CPUs available, {executors.default_jobs()})")
    p.add_argument("--seed", metavar="S", type=int, default=1, help="master seed (default 1)")
    p.add_argument("--executor", choices=executors.EXECUTORS, default="local",
                   help="where the runs execute: 'local' (default) = J processes of this machine (threads with "
                        "--traffic); 'dask' = a Dask cluster, a LocalCluster of J single-threaded worker processes "
                        f"unless --scheduler names one (needs the optional extra: {executors.DASK_HINT})")
    p.add_argument("--scheduler", metavar="ADDRESS", default=None,
                   help="address of a running Dask scheduler, e.g. tcp://10.0.0.5:8786 (implies --executor dask; "
                        "--jobs is then ignored: the cluster's workers run the campaign). Results are the same "
                        "as with local processes for the same seed")
    p.add_argument("--out", metavar="DIR", type=Path, default=None,
                   help="output folder (default runs/montecarlo-SCENARIO-sSEED)")
    g = p.add_argument_group("online process (defaults: planner.online.OnlineParams, then the scenario's [online])")
    g.add_argument("--local-iterations", metavar="N", type=int, default=None,
                   help="iteration budget of each local planning cycle (reproducible)")
    g.add_argument("--local-time", metavar="S", type=float, default=None,
                   help="time budget of each local planning cycle (s, on --local-clock). With --local-iterations 0 "
                        "the runs are timed like the paper's but no longer reproducible")
    g.add_argument("--local-clock", choices=("wall", "thread-cpu"), default=None,
                   help="the clock of --local-time: 'wall' (default, monotonic) or 'thread-cpu' (the planning "
                        "thread's CPU time: an equal CPU budget per cycle, which waiting on a loaded machine "
                        "does not consume)")
    g.add_argument("--cycle-time", metavar="S", type=float, default=None,
                   help="simulated seconds the vessel sails along each local path before replanning")
    g.add_argument("--execution", choices=("receding", "whole-path"), default=None,
                   help="receding: sail speed x cycle time of each local path, then replan (default); whole-path: "
                        "sail the whole local path and plan the next from its end, as the paper (see --tree-reuse)")
    g.add_argument("--tree-reuse", action="store_true", default=None,
                   help="with --execution whole-path: start each cycle's tree from the subtree of the previous one "
                        "rooted where the vessel now is (section 3.5, line 3); default: a fresh tree each cycle")
    g.add_argument("--baseline-objective", choices=("current", "length"), default=None,
                   help="objective of RRT* and IRRT* (default: the [planner] objective, as DDRRT*). 'length' "
                        "makes them optimise Euclidean length as in their original papers while DDRRT* keeps "
                        "eq. (12); every path is still measured with eq. (12)")
    g.add_argument("--figure-runs", metavar="K", type=int, default=9,
                   help="runs drawn in figure11.png (default 9)")
    g.add_argument("--no-plots", action="store_true", help="skip the figures")
    t = p.add_argument_group(
        "ship traffic (--traffic): whole HIL runs in lockstep, each with ships drawn from the run's seed "
        "(hil.traffic_montecarlo); reports the collision rate, the mean CPA and the COLREGs compliance rate")
    t.add_argument("--traffic", action="store_true",
                   help="randomise ship traffic on the scenario's route (e.g. --scenario colregs-head-on) instead of "
                        "the planner-only Table 3 experiment")
    t.add_argument("--ships", metavar="K", type=int, default=1, help="ships per run (default 1)")
    t.add_argument("--bearing", metavar="LO,HI", type=_range, default=(0.0, 360.0),
                   help="direction a ship comes from, deg clockwise from the USV's course (default 0,360)")
    t.add_argument("--speed", metavar="LO,HI", type=_range, default=(0.5, 2.0), help="ship speed, m/s (default 0.5,2)")
    t.add_argument("--miss", metavar="LO,HI", type=_range, default=(-6.0, 6.0),
                   help="un-manoeuvred CPA, m to her starboard (negative: port) (default -6,6)")
    t.add_argument("--duration", metavar="S", type=float, default=240.0,
                   help="simulated seconds per run at most (default 240 with --traffic, 300 with --routes)")
    r = p.add_argument_group(
        "sparse routes (--routes): whole HIL runs in lockstep on random maps, each with a route of 2-3 waypoints "
        "after the start (legs of 35 m or more) drawn from the run's seed (hil.route_montecarlo); reports the "
        "success rate (goal reached without collision)")
    r.add_argument("--routes", action="store_true",
                   help="sail random sparse routes (scenario random-route unless --scenario names another random "
                        "scenario with [random] waypoints) instead of the planner-only Table 3 experiment")
    p.set_defaults(func=run)


def _range(text: str) -> tuple[float, float]:
    try:
        lo, hi = (float(v) for v in text.split(","))
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r}: expected LO,HI (two numbers)") from None
    if not (math.isfinite(lo) and math.isfinite(hi)) or lo > hi:
        raise argparse.ArgumentTypeError(f"{text!r}: expected LO <= HI")
    return lo, hi


def run_traffic(args: argparse.Namespace) -> int:
    """`hil montecarlo --traffic`: HIL runs over randomised ship traffic."""
    from hil import scenario as scenarios
    from hil.traffic_montecarlo import TrafficDraw, TrafficJob, run_campaign

    if args.ships < 1:
        raise UsageError("--ships must be >= 1")
    if args.duration <= 0:
        raise UsageError("--duration must be > 0")
    cfg = console.load_settings(args)
    spec = scenarios.load_spec(args.scenario)
    if spec.kind != "fixed":
        raise UsageError(f"--traffic needs a fixed scenario (its route is the USV's voyage); {spec.name!r} is random")
    out = args.out or Path("runs") / f"montecarlo-traffic-{spec.name}-s{args.seed}"
    check_output_folder(out, "--out")
    draw = TrafficDraw(ships=args.ships, bearing=args.bearing, speed=args.speed, miss=args.miss,
                       cruise_speed=cfg.autopilot.cruise_speed)
    bar = console.ProgressBar(args.runs, "montecarlo traffic", every_s=2.0)
    bad = [0]

    def progress(done: int, s: RunSummary) -> None:
        bad[0] += 1 if s.collisions else 0
        bar.update(done, f"collisions {bad[0]}")

    job = TrafficJob(scenario=args.scenario, seed=args.seed, duration=args.duration, config=args.config,
                     overrides=tuple(args.overrides), out=str(out.resolve()))
    with executors.make(args.executor, min(args.jobs, args.runs), args.scheduler, threads=True) as ex:
        console.progress(f"hil montecarlo --traffic: {args.runs} lockstep HIL runs on {spec.name}, {args.ships} "
                         f"ship(s) each, on {ex.description}, seed {args.seed} -> {out}")
        t0 = time.monotonic()
        summary = run_campaign(args.scenario, args.runs, args.seed, draw, out, ex, job, progress)
    return _finish(args, out, summary, t0,
                   f"traffic: collision rate {summary['collision_rate']:.3f}, mean CPA {summary['mean_cpa_m']} m, "
                   f"compliance {summary['compliance_rate']} over {summary['encounters']} encounters")


def run_routes(args: argparse.Namespace, argv_scenario: str | None) -> int:
    """`hil montecarlo --routes`: HIL runs on random sparse routes."""
    from hil import scenario as scenarios
    from hil.route_montecarlo import RouteJob, run_campaign

    name = argv_scenario or "random-route"
    spec = scenarios.load_spec(name)
    if spec.kind != "random" or spec.random is None or spec.random.waypoints[1] < 1:
        raise UsageError(f"--routes needs a random scenario with [random] waypoints (e.g. random-route); "
                         f"{spec.name!r} has none")
    duration = 300.0 if args.duration == 240.0 else args.duration
    if duration <= 0:
        raise UsageError("--duration must be > 0")
    cfg = console.load_settings(args)
    out = args.out or Path("runs") / f"montecarlo-routes-{spec.name}-s{args.seed}"
    check_output_folder(out, "--out")
    bar = console.ProgressBar(args.runs, "montecarlo routes", every_s=2.0)
    ok = [0]

    def progress(done: int, s: RunSummary) -> None:
        ok[0] += 1 if s.reached_goal else 0
        bar.update(done, f"reached {ok[0]}/{done}")

    job = RouteJob(seed=args.seed, duration=duration, config=args.config, overrides=tuple(args.overrides))
    with executors.make(args.executor, min(args.jobs, args.runs), args.scheduler, threads=True) as ex:
        console.progress(f"hil montecarlo --routes: {args.runs} lockstep HIL runs on {spec.name}, on "
                         f"{ex.description}, seed {args.seed} -> {out}")
        t0 = time.monotonic()
        summary = run_campaign(name, args.runs, args.seed, out, ex, cfg.planner.safety_radius, cfg.current, job,
                               progress)
    return _finish(args, out, summary, t0,
                   f"routes: {summary['reached_without_collision']}/{summary['runs_done']} reached the goal without "
                   f"collision "
                   f"(success rate {summary['success_rate']:.3f}); outcomes {summary['outcomes']}")


def _finish(args: argparse.Namespace, out: Path, summary: dict, t0: float, line: str) -> int:
    """The end of a HIL campaign: wall time and files into summary.json, one line, the summary."""
    summary["wall_time_s"] = round(time.monotonic() - t0, 1)
    summary["files"] = {"runs": str(out / "runs.csv"), "summary": str(out / "summary.json")}
    (out / "summary.json").write_text(console.to_json(summary))
    console.emit(args, summary)
    if summary.get("interrupted"):
        console.progress(f"interrupted: kept the {summary['runs_done']} of {summary['runs']} runs that finished "
                         f"(runs.csv, summary.json in {out}); over them, {line}")
        return 130
    console.progress(line)
    return 0


def run(args: argparse.Namespace) -> int:
    from hil import experiment
    from hil import scenario as scenarios

    if args.runs < 1:
        raise UsageError("--runs must be >= 1")
    if args.jobs < 1:
        raise UsageError("--jobs must be >= 1")
    if args.routes:
        if args.traffic:
            raise UsageError("--routes and --traffic are separate campaigns: give one")
        return run_routes(args, None if args.scenario == "labyrinth" else args.scenario)
    if args.traffic:
        return run_traffic(args)
    if args.seed < 0:
        raise UsageError("--seed must be >= 0")
    if args.figure_runs < 0:
        raise UsageError("--figure-runs must be >= 0")
    settings = console.load_settings(args)
    spec = scenarios.load_spec(args.scenario)
    online_ov = {k: v for k, v in (("local_iterations", args.local_iterations), ("local_time", args.local_time),
                                   ("local_clock", args.local_clock), ("cycle_time", args.cycle_time),
                                   ("execution", args.execution),
                                   ("tree_reuse", args.tree_reuse))
                 if v is not None}
    # Validate everything once in this process (one-line errors) before starting workers.
    online = scenarios.online_params({**spec.online, **online_ov}, "command line")
    scenarios.planner_params(scenarios.base_planner_params(settings), spec.planner, f"scenario {spec.name}")
    if spec.kind == "fixed":
        experiment.scenario_instance(args.scenario, args.seed, 0, args.config, tuple(args.overrides))

    out = args.out or Path("runs") / f"montecarlo-{spec.name}-s{args.seed}"
    check_output_folder(out, "--out")
    out.mkdir(parents=True, exist_ok=True)
    tasks = experiment.make_tasks(args.scenario, args.runs, args.algorithms, args.seed, online_ov, args.config,
                                  args.overrides, args.figure_runs, args.baseline_objective)
    jobs = min(args.jobs, len(tasks))
    ex = executors.make(args.executor, jobs, args.scheduler)
    console.progress(f"hil montecarlo: {args.runs} runs x {len(args.algorithms)} algorithms on {spec.name}, "
                     f"on {ex.description}, seed {args.seed}, budget/cycle: "
                     f"{online.local_iterations or '-'} iterations, "
                     f"{online.local_time or '-'} s ({online.local_clock}); "
                     f"cycle {online.cycle_time:g} s -> {out}")
    bar = console.ProgressBar(len(tasks), "montecarlo", every_s=2.0)
    failed = [0]

    def on_row(done: int, row: dict) -> None:
        failed[0] += 0 if row["reached"] else 1
        bar.update(done, f"failed {failed[0]}")

    t0 = time.monotonic()
    with ex:
        camp = experiment.run_campaign(tasks, jobs, out / "runs.csv", progress=on_row, executor=ex)
    wall = time.monotonic() - t0
    if not camp.rows:
        raise RunFailed("interrupted before any run finished" if camp.interrupted else "no run finished")
    experiment.write_runs_csv(out / "runs.csv", camp.rows)
    table = experiment.table3(camp.rows, args.algorithms)
    title = (f"Table 3 on scenario '{spec.name}': {len(camp.rows)} runs "
             f"({'INTERRUPTED, partial' if camp.interrupted else 'complete'}), seed {args.seed}, "
             f"{online.local_iterations or '-'} iterations/cycle"
             + (f", RRT*/IRRT* objective '{args.baseline_objective}'" if args.baseline_objective else ""))
    experiment.write_table_csv(out / "table3.csv", table)
    experiment.write_table_md(out / "table3.md", table, title)
    figures = {}
    if not args.no_plots:
        figures = _figures(args, spec, camp, out)
    summary = {
        "scenario": spec.name, "runs_requested": args.runs, "tasks_done": len(camp.rows),
        "runs_done": {a: sum(1 for r in camp.rows if r["algorithm"] == a) for a in args.algorithms},
        "interrupted": camp.interrupted, "algorithms": list(args.algorithms), "jobs": jobs, "seed": args.seed,
        "executor": "dask" if isinstance(ex, executors.DaskExecutor) else "local", "workers": ex.workers,
        "baseline_objective": args.baseline_objective,
        "online": {"local_iterations": online.local_iterations, "local_time_s": online.local_time,
                   "local_clock": online.local_clock,
                   "cycle_time_s": online.cycle_time},
        "wall_time_s": wall, "out": str(out),
        "files": {"runs": str(out / "runs.csv"), "table_csv": str(out / "table3.csv"),
                  "table_md": str(out / "table3.md"), **figures},
        "table3": table,
    }
    (out / "summary.json").write_text(console.to_json(summary))
    markdown = experiment.table_markdown(table, title)
    if args.json:
        console.progress(markdown)
        console.emit(args, summary)
    else:  # the table itself, as Markdown, is the human summary (the same text as table3.md)
        print(markdown.rstrip("\n"), flush=True)
        print(f"\n{len(camp.rows)} runs ({args.runs} per algorithm) in {wall:.0f} s; files in {out} "
              f"(table3.md, table3.csv, runs.csv"
              f"{', figures' if figures else ''}, summary.json)", flush=True)
    if camp.interrupted:
        return 130
    return 0


def _figures(args: argparse.Namespace, spec: ScenarioSpec, camp: Campaign, out: Path) -> dict[str, str]:
    from hil import experiment, plots
    from hil import scenario as scenarios

    files = {}
    algs = [a for a in reversed(experiment.ALGORITHMS) if a in camp.details]  # every registered planner
    if algs:
        sc = experiment.scenario_instance(args.scenario, args.seed, 0, args.config, tuple(args.overrides))
        from planner.gridmap import OccupancyGrid
        params = scenarios.planner_params(scenarios.base_planner_params(console.load_settings(args)),
                                          sc.planner_overrides)
        inflated = OccupancyGrid(sc.occ, sc.resolution).inflate(params.safety_radius).occ
        files["figure10"] = str(plots.plot_online(
            out / "figure10.png", sc.occ, sc.resolution,
            [(experiment.LABELS[a], camp.details[a]) for a in algs], sc.reference_path, sc.start, sc.goal,
            params.perceptual_radius, inflated=inflated, field=sc.map_field(),
            title=f"Figure 10 style: scenario {spec.name}, run 0 (seed {args.seed})"))
    runs = sorted({r for r, _ in camp.paths})[: args.figure_runs]
    if runs:
        panels = []
        for r in runs:
            sc = experiment.scenario_instance(args.scenario, args.seed, r, args.config, tuple(args.overrides))
            paths = [(a, *camp.paths[(r, a)]) for a in args.algorithms if (r, a) in camp.paths]
            panels.append({"occ": sc.occ, "resolution": sc.resolution, "start": sc.start, "goal": sc.goal,
                           "reference_path": sc.reference_path, "paths": paths, "title": f"run {r}"})
        files["figure11"] = str(plots.plot_runs_grid(
            out / "figure11.png", panels, title=f"Figure 11 style: scenario {spec.name}, first {len(runs)} runs "
                                               f"(dashed = goal not reached)"))
    return files
