"""Monte Carlo over sparse routes on random maps: whole lockstep HIL runs, judged goal-without-collision.

Each run draws a scenario instance (map, start, goal and 1-2 intermediate waypoints: scenario
``random-route``) from ``numpy.random.default_rng([seed, run])``, writes it as a fixed scenario
(``scenario.toml`` + ``map.npy``) into the run's folder, and runs ``hil run`` on it in lockstep, so
a campaign is repeatable, does not depend on ``--jobs``, and every run can be replayed alone with
``hil run --scenario DIR/runNNNN/scenario.toml --lockstep --seed S``.
"""

from __future__ import annotations

import csv
import json
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, TypedDict

import numpy as np

if TYPE_CHECKING:
    from hil.executors import Executor
    from hil.run_summary import RunSummary
    from hil.scenario import Scenario, ScenarioSpec
    from simulator.config import CurrentParams


def _toml_value(v: object) -> str:
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, (int, float, np.floating, np.integer)):
        return repr(float(v)) if isinstance(v, (float, np.floating)) else str(int(v))
    if isinstance(v, str):
        return json.dumps(v)
    if isinstance(v, (list, tuple, np.ndarray)):
        return "[" + ", ".join(_toml_value(x) for x in v) + "]"
    raise TypeError(f"cannot write {type(v).__name__} to TOML")


def write_instance(scen: Scenario, spec: ScenarioSpec, folder: Path, name: str) -> Path:
    """``scen`` (a random instance) as a fixed scenario file in ``folder``; returns its path."""
    folder.mkdir(parents=True, exist_ok=True)
    np.save(folder / "map.npy", scen.occ)
    lines = [f"name = {_toml_value(name)}", f"description = {_toml_value(spec.description)}", 'kind = "fixed"',
             f"map = {_toml_value(str((folder / 'map.npy').resolve()))}",
             f"resolution = {_toml_value(scen.resolution)}",
             f"start = {_toml_value(scen.start)}", f"start_heading = {_toml_value(scen.start_heading)}",
             f"goal = {_toml_value(scen.goal)}",
             f"reference_path = {_toml_value(np.asarray(scen.waypoints).tolist())}",
             f"route_spacing = {_toml_value(spec.route_spacing)}"]
    for table in ("current", "planner", "online"):
        lines.append(f"\n[{table}]")
        lines.extend(f"{k} = {_toml_value(v)}" for k, v in getattr(spec, table).items())
    path = folder / "scenario.toml"
    path.write_text("\n".join(lines) + "\n")
    return path


@dataclass(frozen=True)
class RouteJob:
    """One whole lockstep HIL run of a routes campaign, picklable for any executor
    (:mod:`hil.executors`): called with ``(run, scenario_file, run_folder)`` it returns the run's
    summary. Each run picks its own UDP ports (reserved host-wide), so runs sharing a host never collide."""

    seed: int
    duration: float            # s of simulated time at most
    config: str | tuple[str, ...] | None   # --config file(s), as hil.settings.load takes them
    overrides: tuple[str, ...]

    def __call__(self, item: tuple[int, str, str]) -> RunSummary:
        from hil import settings
        from hil.hilrun import NO_GCS, RunOptions, run_loop

        i, scenario_file, folder = item
        opts = RunOptions(scenario=scenario_file, lockstep=True, duration=self.duration, seed=self.seed * 1000 + i,
                          config=self.config, overrides=list(self.overrides) + NO_GCS, out=Path(folder) / "hil",
                          plot=False, cpus="off")  # runs share the host: none is placed (hil.placement)
        return run_loop(opts, settings.load(self.config, list(self.overrides) + NO_GCS))


class RouteRow(TypedDict):
    """One run of a route campaign (a row of runs.csv)."""

    run: int
    outcome: str
    reached: bool
    collisions: int
    min_clearance_m: float | None      # m
    sim_time_s: float
    waypoints: int
    longest_leg_m: float
    route_length_m: float
    path_length_m: float
    fallbacks: int | None
    scenario: str                       # the instance's scenario file


def run_campaign(scenario: str, runs: int, seed: int, out: Path, executor: Executor, safety_radius: float,
                 base_current: CurrentParams | None, run_one: Callable[[tuple[int, str, str]], RunSummary],
                 progress: Callable[[int, RunSummary], None] = lambda _i, _s: None) -> dict[str, object]:
    """``runs`` HIL runs of ``run_one((run, scenario_file, folder))`` on instances of the random
    ``scenario``, on ``executor``; writes ``runs.csv`` and ``summary.json``. Ctrl-C or SIGTERM keeps
    the finished runs (``interrupted``, ``runs_done``; rates over the runs done)."""
    from hil import scenario as scenarios

    spec = scenarios.load_spec(scenario)
    plans = []
    for i in range(runs):
        scen = scenarios.instance(spec, np.random.default_rng([int(seed), i]), base_current, safety_radius)
        folder = out / f"run{i:04d}"
        plans.append((i, scen, write_instance(scen, spec, folder, f"{spec.name}-{seed}-{i}"), folder))

    from hil.executors import collect

    rows: list[RouteRow] = []
    items = [(i, str(path), str(folder)) for i, _, path, folder in plans]

    def take(i: int, s: RunSummary) -> None:
        _, scen, path, _ = plans[i]
        wps = np.asarray(scen.waypoints)
        legs = np.hypot(*np.diff(wps, axis=0).T)
        rows.append({"run": i, "outcome": s.outcome, "reached": bool(s.reached_goal),
                     "collisions": s.collisions, "min_clearance_m": s.min_clearance_m,
                     "sim_time_s": s.sim_time_s, "waypoints": len(wps) - 1,
                     "longest_leg_m": round(float(legs.max()), 1), "route_length_m":
                     round(float(np.sum(np.hypot(*np.diff(scen.reference_path, axis=0).T))), 1),
                     "path_length_m": s.path_length_m, "fallbacks": s.fallback_activations,
                     "scenario": str(path)})
        progress(len(rows), s)

    interrupted = collect(executor, run_one, items, take)
    rows.sort(key=lambda r: r["run"])
    out.mkdir(parents=True, exist_ok=True)
    with open(out / "runs.csv", "w", newline="") as fh:
        w = csv.DictWriter(fh, fieldnames=list(rows[0]) if rows else ["run"])
        w.writeheader()
        w.writerows(rows)
    ok = sum(1 for r in rows if r["reached"])
    clear = [r["min_clearance_m"] for r in rows if r["min_clearance_m"] is not None]
    summary = {
        "scenario": scenario, "runs": runs, "seed": seed, "interrupted": interrupted, "runs_done": len(rows),
        "success_rate": round(ok / max(len(rows), 1), 4), "reached_without_collision": ok,
        "outcomes": {k: sum(1 for r in rows if r["outcome"] == k) for k in sorted({r["outcome"] for r in rows})},
        "collisions": sum(1 for r in rows if r["collisions"]),
        "failed_runs": [r["run"] for r in rows if not r["reached"]],
        "waypoints": {k: sum(1 for r in rows if r["waypoints"] == k) for k in sorted({r["waypoints"] for r in rows})},
        "longest_leg_m_median": round(float(np.median([r["longest_leg_m"] for r in rows])), 1) if rows else None,
        "min_clearance_m": round(float(min(clear)), 3) if clear else None,
        "mean_sim_time_s": round(float(np.mean([r["sim_time_s"] for r in rows])), 1) if rows else None,
    }
    (out / "summary.json").write_text(json.dumps(summary, indent=1))
    return summary
