"""The Monte Carlo experiment of section 4.2 (Table 3, Figures 10 and 11): tasks, workers, tables.

A *task* is one online planning run (``planner.online.run_online``) of one algorithm on one
scenario instance. Seeds come from ``numpy.random.SeedSequence(seed, spawn_key=(run, k))``:
``k = 0`` draws the scenario instance (random maps, the same for every algorithm of a run) and
``k = 1 + index in ALGORITHMS`` seeds that algorithm's planner, so results depend only on
(seed, run, algorithm), never on the number of worker processes or the order of the work.
"""

from __future__ import annotations

import csv
import math
import signal
import time
from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass, field, replace
from pathlib import Path
from types import FrameType
from typing import TYPE_CHECKING, Any, NoReturn, TypeAlias

import numpy as np

from planner.params import ALGORITHM_NAMES, REGISTRY, Objective

if TYPE_CHECKING:
    from hil.executors import Executor
    from hil.scenario import Scenario, ScenarioSpec
    from hil.settings import HilConfig
    from planner.online import OnlineContext, OnlineResult

ALGORITHMS = ALGORITHM_NAMES  # the planner's registry; the order fixes the per-algorithm seeds
LABELS = {e.name: e.label for e in REGISTRY}

# Per-run CSV columns; DETERMINISTIC ones must be identical for the same seed whatever --jobs is
# (with an iteration budget); the time columns are wall-clock measurements.
DETERMINISTIC = ("run", "algorithm", "planner_seed", "reached", "reason", "cycles", "iterations", "cost", "length",
                 "sum_cos", "sum_sin", "cf", "turns", "total_curvature", "bending_energy", "smoothing_fallbacks",
                 "start_x", "start_y", "goal_x", "goal_y", "search_iterations", "search_checks",
                 "sum_cos_wp", "sum_sin_wp", "waypoints", "reused_nodes")
# sum_cos / sum_sin are taken on the executed path every 2 m (metric_spacing); sum_cos_wp /
# sum_sin_wp at the waypoints of the local paths the vessel left, as section 4.2 counts them
# (planner.metrics.waypoint_alpha_sums; waypoints = how many).
# Table 3's "time" four ways (issue 34): time_s (wall clock), time_cpu_s (the planning thread's CPU
# time), search_iterations and search_checks (iterations and collision checks), each summed over the
# cycles to each cycle's first solution (the whole cycle where it found none).
TIMES = ("time_s", "time_cpu_s", "planning_time_s", "wall_s")
COLUMNS = DETERMINISTIC + TIMES

# A row of runs.csv (COLUMNS) or of table3.csv (TABLE_COLUMNS): cells of several types (text, bool, int,
# float) read and written by column name, read back from files of older versions that lack some columns;
# run_task's row also carries ``_detail`` (OnlineResult) and ``_path`` (the path sailed) when asked.
# Like a JSON document's values (common.tables.JsonValue), its cells are Any to mypy.
CsvRow: TypeAlias = dict[str, Any]

# Table 3 as the paper reports it (its numbers are missing from our copy; only the relative
# figures of section 4.2 survive), percentages relative to RRT*.
PAPER_RELATIVE = {
    "informed-rrt-star": {"sum_cos": +38.81, "sum_sin": -13.54},
    "ddrrt-star": {"sum_cos": +82.09, "sum_sin": -17.23},
}


@dataclass(frozen=True)
class Task:
    """One run of one algorithm (picklable, sent to a worker process)."""

    scenario: str
    run: int
    algorithm: str
    seed: int
    online_overrides: tuple[tuple[str, object], ...] = ()
    config: str | None = None
    config_overrides: tuple[str, ...] = ()
    objective: Objective | None = None  # override of [planner] objective for this algorithm
    detail: bool = False          # return cycles (trees, local paths) for Figure 10
    path: bool = False            # return the executed path for Figure 11


def seed_sequence(seed: int, run: int, k: int) -> np.random.SeedSequence:
    return np.random.SeedSequence(int(seed), spawn_key=(int(run), int(k)))


def planner_seed(seed: int, run: int, algorithm: str) -> int:
    """The planner seed of ``algorithm`` in Monte Carlo run ``run``."""
    return int(seed_sequence(seed, run, 1 + ALGORITHMS.index(algorithm)).generate_state(1)[0] & 0x7FFFFFFF)


# Per worker process: what every task of a campaign shares (loading, inflating a chart are costly).
_SETTINGS: dict[tuple[str | None, tuple[str, ...]], HilConfig] = {}
_SPECS: dict[str, ScenarioSpec] = {}
_FIXED: dict[tuple[str, str | None, tuple[str, ...]], Scenario] = {}
_CONTEXTS: dict[tuple[str, str | None, tuple[str, ...], tuple[tuple[str, object], ...]], OnlineContext] = {}


def _settings(config: str | None, overrides: tuple[str, ...]) -> HilConfig:
    key = (config, overrides)
    if key not in _SETTINGS:
        from hil import settings
        _SETTINGS[key] = settings.load(config, list(overrides))
    return _SETTINGS[key]


def scenario_instance(name: str, seed: int, run: int, config: str | None = None,
                      overrides: tuple[str, ...] = ()) -> Scenario:
    """The scenario instance of run ``run`` (fixed scenarios: the same for every run)."""
    from hil import scenario as scenarios
    cfg = _settings(config, overrides)
    if name not in _SPECS:
        _SPECS[name] = scenarios.load_spec(name)
    spec = _SPECS[name]
    if spec.kind == "fixed":
        key = (name, config, overrides)
        if key not in _FIXED:
            _FIXED[key] = scenarios.instance(spec, None, cfg.current, cfg.planner.safety_radius)
        return _FIXED[key]
    rng = np.random.default_rng(seed_sequence(seed, run, 0))
    return scenarios.instance(spec, rng, cfg.current, cfg.planner.safety_radius)


def _context(task: Task, sc: Scenario) -> OnlineContext:
    """The OnlineContext of a task (cached per process for fixed scenarios: inflation is costly)."""
    from hil import scenario as scenarios
    from planner.gridmap import OccupancyGrid
    from planner.online import make_context

    cfg = _settings(task.config, task.config_overrides)
    params = scenarios.planner_params(scenarios.base_planner_params(cfg), sc.planner_overrides, f"scenario {sc.name}")
    online = scenarios.online_params(dict(sc.online_overrides), f"scenario {sc.name}")
    online = scenarios.online_params(dict(task.online_overrides), "command line", base=online)
    if task.objective is not None:
        params = replace(params, objective=task.objective)
    key = (task.scenario, task.config, task.config_overrides, task.online_overrides)
    fixed = scenarios.load_spec(task.scenario).kind == "fixed"
    if fixed and key in _CONTEXTS:
        base = _CONTEXTS[key]
    else:
        from planner.online import OnlineContext
        field_ = sc.planning_field()    # also needed for the metrics when a planner ignores it
        base = OnlineContext(grid=OccupancyGrid(sc.occ, sc.resolution), goal=sc.goal,
                             reference_path=sc.reference_path, params=params, online=online, field=field_)
        if fixed:
            _CONTEXTS[key] = base
    ctx = make_context(base.grid, sc.goal, sc.reference_path, params, online, task.algorithm, base.field)
    if params.alpha_y == "resultant":
        from hil.commands.plan import wave_drift
        # the planners' alpha_y against the current plus the mean wave drift of [waves] (the
        # metrics stay on the current alone, as in every other campaign row)
        ctx.wave_drift = wave_drift(cfg)
    ctx.safe_grid = base.safe_grid
    ctx._velocity_grids = base._velocity_grids   # the section 3.3 inflations do not depend on the algorithm
    return ctx


def run_task(task: Task) -> CsvRow:
    """Run one task; returns the CSV row (plus ``_detail`` / ``_path`` when asked)."""
    from planner.online import VesselState, run_online

    t0 = time.monotonic()
    sc = scenario_instance(task.scenario, task.seed, task.run, task.config, task.config_overrides)
    ctx = _context(task, sc)
    pseed = planner_seed(task.seed, task.run, task.algorithm)
    res = run_online(ctx, VesselState(sc.start[0], sc.start[1], sc.start_heading), pseed)
    m = res.metrics
    row: CsvRow = {
        "run": task.run, "algorithm": task.algorithm, "planner_seed": pseed, "reached": bool(res.reached),
        "reason": res.reason, "cycles": len(res.cycles), "iterations": int(sum(c.iterations for c in res.cycles)),
        "cost": m.get("cost", math.nan), "length": m.get("length", math.nan),
        "sum_cos": m.get("sum_cos", math.nan), "sum_sin": m.get("sum_sin", math.nan), "cf": m.get("cf", math.nan),
        "turns": m.get("turns", math.nan), "total_curvature": m.get("total_curvature", math.nan),
        "bending_energy": m.get("bending_energy", math.nan),
        "smoothing_fallbacks": int(sum(1 for c in res.cycles if len(c.smooth_path) >= 2 and not c.smoothed_ok)),
        "start_x": sc.start[0], "start_y": sc.start[1], "goal_x": sc.goal[0], "goal_y": sc.goal[1],
        "search_iterations": res.search_iterations, "search_checks": res.search_checks,
        "sum_cos_wp": m.get("sum_cos_wp", math.nan), "sum_sin_wp": m.get("sum_sin_wp", math.nan),
        "waypoints": int(m.get("waypoints_wp", 0)),
        "reused_nodes": int(sum(c.reused_nodes for c in res.cycles)),   # --tree-reuse: nodes kept over the run
        "time_s": res.search_time_s, "time_cpu_s": res.search_cpu_s, "planning_time_s": res.planning_time_s,
        "wall_s": time.monotonic() - t0,
    }
    if task.detail:
        row["_detail"] = res
    if task.path:
        row["_path"] = res.executed
    return row


def warm_up() -> None:
    """``planner.warm_up()``: every compiled planner function loaded (or compiled) in this
    process, so numba's work is not counted in the first run's search time."""
    import planner

    planner.warm_up()


def _fmt(v: object) -> str:
    if isinstance(v, bool):
        return "1" if v else "0"
    if isinstance(v, float):
        return "nan" if math.isnan(v) else repr(round(v, 9))
    return str(v)


class RunsWriter:
    """Appends per-run rows to a CSV as they finish (so an interrupted campaign keeps them)."""

    def __init__(self, path: Path) -> None:
        self.path = path
        path.parent.mkdir(parents=True, exist_ok=True)
        self.fh = path.open("w", newline="")
        self.w = csv.writer(self.fh)
        self.w.writerow(COLUMNS)
        self.fh.flush()

    def add(self, row: CsvRow) -> None:
        self.w.writerow([_fmt(row[c]) for c in COLUMNS])
        self.fh.flush()

    def close(self) -> None:
        self.fh.close()


def write_runs_csv(path: Path, rows: Iterable[CsvRow]) -> Path:
    """All rows, sorted by (run, algorithm order), as CSV."""
    rows = sorted(rows, key=lambda r: (r["run"], ALGORITHMS.index(r["algorithm"])))
    w = RunsWriter(path)
    for r in rows:
        w.add(r)
    w.close()
    return path


def read_runs_csv(path: Path) -> list[CsvRow]:
    """Rows back from :func:`write_runs_csv` with numbers parsed."""
    out = []
    with Path(path).open(newline="") as fh:
        for rec in csv.DictReader(fh):
            row: CsvRow = {}
            for k, v in rec.items():
                if k in ("algorithm", "reason"):
                    row[k] = v
                elif k == "reached":
                    row[k] = v == "1"
                elif k in ("run", "cycles", "iterations", "planner_seed", "smoothing_fallbacks"):
                    row[k] = int(v)
                elif k in ("search_iterations", "search_checks", "reused_nodes"):
                    row[k] = int(float(v))
                else:
                    row[k] = float(v)
            out.append(row)
    return out


def _mean_std(values: Sequence[float]) -> tuple[float, float]:
    a = np.asarray([v for v in values if math.isfinite(v)], dtype=float)
    if len(a) == 0:
        return math.nan, math.nan
    return float(a.mean()), float(a.std(ddof=1)) if len(a) > 1 else 0.0


def table3(rows: Sequence[CsvRow], algorithms: Sequence[str] = ALGORITHMS) -> list[CsvRow]:
    """Aggregate per algorithm: means over the runs that reached the goal (success rate over all).

    Columns: time (s, mean of the per-run sums of search durations), time_std ("time EVP"),
    cost (eq. 12), cost_std ("cost EVP"), sum_cos, sum_sin, cf (cf(π), eq. 14), and each
    mean's change relative to RRT* in percent (``*_vs_rrt_pct``).
    """
    out = []
    for alg in algorithms:
        rs = [r for r in rows if r["algorithm"] == alg]
        ok = [r for r in rs if r["reached"]]
        rec: CsvRow = {"algorithm": alg, "runs": len(rs), "reached": len(ok),
                               "success_rate": len(ok) / len(rs) if rs else math.nan}
        rec["time_s"], rec["time_std_s"] = _mean_std([r["time_s"] for r in ok])
        rec["cost"], rec["cost_std"] = _mean_std([r["cost"] for r in ok])
        for k in ("sum_cos", "sum_sin", "cf", "length", "turns", "bending_energy", "cycles"):
            rec[k] = _mean_std([float(r[k]) for r in ok])[0]
        for k in ("time_cpu_s", "search_iterations", "search_checks",   # absent from runs.csv before issue 34
                  "sum_cos_wp", "sum_sin_wp"):
            rec[k] = _mean_std([float(r.get(k, math.nan)) for r in ok])[0]
        out.append(rec)
    base = next((r for r in out if r["algorithm"] == "rrt-star"), None)
    for rec in out:
        for k in ("time_s", "cost", "sum_cos", "sum_sin", "cf", "time_std_s", "cost_std", "time_cpu_s",
                  "search_iterations", "search_checks", "sum_cos_wp", "sum_sin_wp"):
            b = base[k] if base else math.nan
            rec[f"{k}_vs_rrt_pct"] = (rec[k] - b) / abs(b) * 100.0 if base and b and math.isfinite(b) else math.nan
    return out


TABLE_COLUMNS = ("algorithm", "runs", "reached", "success_rate", "time_s", "time_std_s", "cost", "cost_std",
                 "sum_cos", "sum_sin", "cf", "length", "turns", "bending_energy", "cycles",
                 "time_s_vs_rrt_pct", "cost_vs_rrt_pct", "sum_cos_vs_rrt_pct", "sum_sin_vs_rrt_pct", "cf_vs_rrt_pct",
                 "time_std_s_vs_rrt_pct", "cost_std_vs_rrt_pct", "time_cpu_s", "search_iterations", "search_checks",
                 "time_cpu_s_vs_rrt_pct", "search_iterations_vs_rrt_pct", "search_checks_vs_rrt_pct",
                 "sum_cos_wp", "sum_sin_wp", "sum_cos_wp_vs_rrt_pct", "sum_sin_wp_vs_rrt_pct")


def write_table_csv(path: Path, table: Sequence[CsvRow]) -> Path:
    path.parent.mkdir(parents=True, exist_ok=True)
    with path.open("w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(TABLE_COLUMNS)
        for rec in table:
            w.writerow([_fmt(rec[c]) for c in TABLE_COLUMNS])
    return path


def _n(v: float, digits: int = 3) -> str:
    return "n/a" if v is None or (isinstance(v, float) and not math.isfinite(v)) else f"{v:.{digits}f}"


def _pct(v: float) -> str:
    return "n/a" if v is None or not math.isfinite(v) else f"{v:+.2f}%"


def table_markdown(table: Sequence[CsvRow], title: str = "") -> str:
    """Table 3 in Markdown, with our percentages vs RRT* next to the paper's."""
    lines = []
    if title:
        lines += [f"**{title}**", ""]
    lines += [
        "| algorithm | runs | reached | time (s) | time EVP (s) | cost | cost EVP | Σcos α_y | Σsin α_y | cf(π) | "
        "Σcos α_y (waypoints) | Σsin α_y (waypoints) |",
        "|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|",
    ]
    for r in table:
        lines.append(f"| {LABELS.get(r['algorithm'], r['algorithm'])} | {r['runs']} | {r['reached']} | "
                     f"{_n(r['time_s'], 4)} | {_n(r['time_std_s'], 4)} | {_n(r['cost'], 2)} | {_n(r['cost_std'], 2)} | "
                     f"{_n(r['sum_cos'], 2)} | {_n(r['sum_sin'], 2)} | {_n(r['cf'], 4)} | "
                     f"{_n(r.get('sum_cos_wp', math.nan), 2)} | {_n(r.get('sum_sin_wp', math.nan), 2)} |")
    lines += ["", "Σcos α_y, Σsin α_y: on the executed path every 2 m; (waypoints): at the waypoints of the "
              "local paths the vessel left, as section 4.2 counts them."]
    lines += [
        "",
        "Relative to RRT* (ours; the paper's in brackets where section 4.2 gives it):",
        "",
        "| algorithm | time | cost | time EVP | cost EVP | Σcos α_y | Σsin α_y | cf(π) | CPU time | iterations | "
        "collision checks | Σcos α_y (waypoints) | Σsin α_y (waypoints) |",
        "|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|",
    ]
    for r in table:
        if r["algorithm"] == "rrt-star":
            continue
        paper = PAPER_RELATIVE.get(r["algorithm"], {})
        pc = f" ({paper['sum_cos']:+.2f}%)" if "sum_cos" in paper else ""
        ps = f" ({paper['sum_sin']:+.2f}%)" if "sum_sin" in paper else ""
        lines.append(f"| {LABELS.get(r['algorithm'], r['algorithm'])} | {_pct(r['time_s_vs_rrt_pct'])} | "
                     f"{_pct(r['cost_vs_rrt_pct'])} | {_pct(r['time_std_s_vs_rrt_pct'])} | "
                     f"{_pct(r['cost_std_vs_rrt_pct'])} | {_pct(r['sum_cos_vs_rrt_pct'])}{pc} | "
                     f"{_pct(r['sum_sin_vs_rrt_pct'])}{ps} | {_pct(r['cf_vs_rrt_pct'])} | "
                     f"{_pct(r['time_cpu_s_vs_rrt_pct'])} | {_pct(r['search_iterations_vs_rrt_pct'])} | "
                     f"{_pct(r['search_checks_vs_rrt_pct'])} | {_pct(r.get('sum_cos_wp_vs_rrt_pct', math.nan))}{pc} | "
                     f"{_pct(r.get('sum_sin_wp_vs_rrt_pct', math.nan))}{ps} |")
    return "\n".join(lines) + "\n"


def write_table_md(path: Path, table: Sequence[CsvRow], title: str = "") -> Path:
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(table_markdown(table, title))
    return path


@dataclass
class Campaign:
    """Result of :func:`run_campaign`: the rows finished and what was kept for the figures."""

    rows: list[CsvRow] = field(default_factory=list)
    details: dict[str, OnlineResult] = field(default_factory=dict)      # algorithm -> its run 0
    # (run, algorithm) -> (the path sailed, reached the goal)
    paths: dict[tuple[int, str], tuple[np.ndarray, bool]] = field(default_factory=dict)
    interrupted: bool = False


def make_tasks(scenario: str, runs: int, algorithms: Sequence[str], seed: int, online_overrides: dict[str, object],
               config: str | None, config_overrides: Sequence[str], figure_runs: int,
               baseline_objective: Objective | None = None) -> list[Task]:
    """All (run, algorithm) tasks; ``baseline_objective`` overrides the objective of RRT* and
    IRRT* (DDRRT* keeps the configured one)."""
    ov = tuple(sorted(online_overrides.items()))
    return [Task(scenario, i, alg, seed, ov, config, tuple(config_overrides),
                 objective=baseline_objective if alg != "ddrrt-star" else None,
                 detail=(i == 0), path=(i < figure_runs))
            for i in range(runs) for alg in algorithms]


def run_campaign(tasks: Sequence[Task], jobs: int, out_csv: Path | None = None,
                 progress: Callable[[int, CsvRow], None] | None = None,
                 executor: Executor | None = None) -> Campaign:
    """Run ``tasks`` on ``executor`` (default: ``jobs`` local spawned processes; ``jobs == 1`` runs
    in-process; see :mod:`hil.executors` for Dask).

    Rows are appended to ``out_csv`` as they finish. Ctrl-C (or SIGTERM) cancels the outstanding
    work and returns what finished, with ``interrupted`` set.
    """
    from hil.executors import LocalProcesses

    camp = Campaign()
    writer = RunsWriter(out_csv) if out_csv else None
    ex = executor if executor is not None else LocalProcesses(jobs)

    def take(row: CsvRow) -> None:
        det = row.pop("_detail", None)
        if det is not None:
            camp.details[row["algorithm"]] = det
        p = row.pop("_path", None)
        if p is not None:
            camp.paths[(row["run"], row["algorithm"])] = (p, row["reached"])
        camp.rows.append(row)
        if writer:
            writer.add(row)
        if progress:
            progress(len(camp.rows), row)

    # SIGTERM (e.g. `kill`): stop like Ctrl-C and keep the finished runs
    def on_term(signum: int, frame: FrameType | None) -> NoReturn:
        raise KeyboardInterrupt

    previous = signal.signal(signal.SIGTERM, on_term)
    try:
        try:
            for _i, row in ex.map_unordered(run_task, tasks, warm_up=warm_up):
                take(row)
        except KeyboardInterrupt:
            ex.cancel()
            raise
        finally:
            if executor is None:
                ex.close()
    except KeyboardInterrupt:
        camp.interrupted = True
    finally:
        signal.signal(signal.SIGTERM, previous)
        if writer:
            writer.close()
    return camp
