"""Issue 34's pre-registered campaign: cells, the commands that run them, and the verdicts.

The design (docs/experiments.md, "The pre-registered campaign (issue 34)") is one factor at a
time from the paper's setting ``paper``: each other cell changes one factor. Every cell is one
``hil montecarlo`` command (:func:`command`), so a cell is re-run from its line alone. The
decision rule, fixed before any run: for each claim, the 95 % confidence interval of the
DDRRT* - RRT* difference of means (Welch; for the EVPs, a seeded bootstrap of the difference of
standard deviations) excluding 0 in the paper's direction: *reproduced*; in the other direction:
*refuted*; otherwise *no difference*. Means over the runs that reached the goal, as Table 3.

    python -m hil.campaign --runs 20 --out docs/experiments/campaign34   # every cell, then verdicts
    python -m hil.campaign --verdicts-only --out docs/experiments/campaign34
    python -m hil.campaign --runs 200 --algorithms rrt-star,ddrrt-star --out docs/experiments/campaign34-full

Besides verdicts.md and verdicts.json, ``summary.md`` gives the verdicts as one table, a column
per cell. Cells added after the first runs are marked so in :data:`CELLS`.
"""

from __future__ import annotations

import argparse
import json
import math
import shlex
import subprocess
import sys
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, NotRequired, TypedDict

import numpy as np

if TYPE_CHECKING:
    from hil.experiment import CsvRow

# The paper's setting: RRT* and IRRT* on length, DDRRT* on eq. (12); 1,500 iterations a cycle;
# P = 0.7 (the audit's), k = 5 fixed, DD = DR constant, none of issue 34's fixes; receding horizon.
PAPER = ("--set", "planner.png_probability=0.7", "--set", "planner.k_growth=0",
         "--set", "planner.dynamic_domain=\"constant\"")
FIXES = ("--set", "planner.png_repair=true", "--set", "planner.failed_extension=\"collision+turn\"",
         "--set", "planner.dd_radius=8.0")


@dataclass(frozen=True)
class Cell:
    name: str
    factor: str
    args: tuple[str, ...]
    scenario: str = "labyrinth"


CELLS: tuple[Cell, ...] = (
    Cell("paper", "the paper's setting", ()),
    Cell("fixes", "issue 34's fixes on (PGNode repair, fan failures, DD 8 m)", FIXES),
    Cell("eq12", "baseline objective eq. (12) (RRT*, IRRT* on current)", ("--baseline-objective", "current")),
    Cell("p02", "P = 0.2", ("--set", "planner.png_probability=0.2")),
    Cell("p0", "P = 0", ("--set", "planner.png_probability=0.0")),
    Cell("kgrow", "k growing (k_growth = 2)", ("--set", "planner.k_growth=2.0")),
    Cell("it300", "300 iterations a cycle", ("--local-iterations", "300")),
    Cell("it150", "150 iterations a cycle", ("--local-iterations", "150")),
    # added after the cells above had run (the execution model was implemented then; same rule)
    Cell("whole", "whole-path execution (no tree reuse)", ("--execution", "whole-path")),
    # random maps (Figure 11's generator, straight reference path), added with `whole`
    Cell("random", "random maps", (), "random"),
    Cell("random-fixes", "random maps, issue 34's fixes on", FIXES, "random"),
    # added after the 200-run campaign of the cells above (same rule): the whole-path model with
    # the subtree reused (section 3.5, line 3)
    Cell("whole-reuse", "whole-path execution, the subtree rooted at the new start reused",
         ("--execution", "whole-path", "--tree-reuse")),
    # Figure 11's random maps with the global route as reference path (the same maps, start and
    # goal per run as `random`); added with `whole-reuse`
    Cell("random-global", "random maps, the global route on", (), "random-global"),
    # the equal CPU-time budget (issue 34's fourth budget), added after the 200-run campaign of the
    # cells above (same rule): no iteration budget, each cycle stops at S of the planning thread's
    # CPU time. S = 0.44 ms, RRT*'s median thread CPU a cycle in `paper` (time_cpu_s / cycles of the
    # 200-run paper/runs.csv, median over RRT*'s runs; time_cpu_s is per run, to each cycle's first
    # solution). Thread CPU is not reproducible bit for bit: the rows vary a little between runs.
    Cell("cpu-equal", "an equal thread-CPU budget of 0.44 ms a cycle (no iteration budget)",
         ("--local-iterations", "0", "--local-time", "0.00044", "--local-clock", "thread-cpu")),
    # a second equal thread-CPU budget, at the paper's budget: S = 2.69 ms, the median thread CPU of
    # RRT*'s whole 1,500-iteration search a cycle in `paper` (353 searches of its runs 0-19,
    # docs/experiments/campaign34-full/measure_cycle_cpu.py); added after `cpu-equal` had run, same rule
    Cell("cpu-cycle", "an equal thread-CPU budget of 2.69 ms a cycle (RRT*'s 1,500 iterations; no iteration budget)",
         ("--local-iterations", "0", "--local-time", "0.00269", "--local-clock", "thread-cpu")),
    # alpha_y of eqs. (11)-(12) against the resultant of the current and the mean wave drift of
    # [waves] (section 3.4), added with `cpu-equal` (same rule): the drift of the default waves is
    # 0.036 m/s towards the north-east; the metrics stay on the current alone
    Cell("resultant", "alpha_y against the resultant of current and wave drift",
         ("--set", "planner.alpha_y=\"resultant\"")),
)

# claim: (column, the paper's direction of DDRRT* - RRT*: -1 lower, +1 higher, statistic)
CLAIMS: tuple[tuple[str, str, int, str], ...] = (
    ("time (wall)", "time_s", -1, "mean"),
    ("time (thread CPU)", "time_cpu_s", -1, "mean"),
    ("time (iterations)", "search_iterations", -1, "mean"),
    ("time (collision checks)", "search_checks", -1, "mean"),
    ("cost", "cost", -1, "mean"),
    ("Σcos α_y", "sum_cos", +1, "mean"),
    ("Σsin α_y", "sum_sin", -1, "mean"),
    # the same two claims at the waypoints of the local paths (section 4.2's count), beside the
    # per-2 m sums above; added after the 50-run campaign, same rule
    ("Σcos α_y (waypoints)", "sum_cos_wp", +1, "mean"),
    ("Σsin α_y (waypoints)", "sum_sin_wp", -1, "mean"),
    ("cf(π)", "cf", +1, "mean"),
    ("time EVP", "time_s", -1, "std"),
    ("cost EVP", "cost", -1, "std"),
    ("fewer turns", "turns", -1, "mean"),
)


def command(cell: Cell, runs: int, out: Path, jobs: int = 2, seed: int = 1,
            algorithms: str | None = None) -> list[str]:
    """The `hil montecarlo` command of one cell (``algorithms``: a comma-separated subset; the
    verdicts need rrt-star and ddrrt-star only, and each run's seed does not depend on the others)."""
    base = ["hil", "montecarlo", "--scenario", cell.scenario, "--runs", str(runs), "--jobs", str(jobs),
            "--seed", str(seed), "--baseline-objective", "length", "--no-plots", "--out", str(out / cell.name)]
    if algorithms:
        base[6:6] = ["--algorithms", algorithms]
    return base + list(PAPER) + list(cell.args)


def _ci_mean(a: np.ndarray, b: np.ndarray) -> tuple[float, float, float]:
    """Difference of means a - b and its Welch 95 % interval (normal quantile)."""
    d = float(a.mean() - b.mean())
    se = math.sqrt(a.var(ddof=1) / len(a) + b.var(ddof=1) / len(b))
    return d, d - 1.96 * se, d + 1.96 * se


def _ci_std(a: np.ndarray, b: np.ndarray, seed: int = 34, n: int = 2000) -> tuple[float, float, float]:
    """Difference of standard deviations a - b and its bootstrap 95 % interval (percentile)."""
    rng = np.random.default_rng(seed)
    d = float(a.std(ddof=1) - b.std(ddof=1))
    boots = [rng.choice(a, len(a)).std(ddof=1) - rng.choice(b, len(b)).std(ddof=1) for _ in range(n)]
    lo, hi = np.percentile(boots, [2.5, 97.5])
    return d, float(lo), float(hi)


class Verdict(TypedDict):
    """One claim's verdict (verdicts.json): a measured claim has its difference DDRRT* - RRT*, its 95 %
    interval, the difference relative to RRT* (%) and the runs (DDRRT*, RRT*) that reached the goal; the
    success rate has the goals reached and the runs of each, (reached, runs)."""

    claim: str
    verdict: str          # reproduced, refuted, no difference, not measured, reported
    difference: NotRequired[float]
    ci_low: NotRequired[float]
    ci_high: NotRequired[float]
    relative_pct: NotRequired[float]
    runs: NotRequired[tuple[int, int]]
    ddrrt: NotRequired[tuple[int, int]]
    rrt: NotRequired[tuple[int, int]]


def verdicts(rows: Sequence[CsvRow], a: str = "ddrrt-star", b: str = "rrt-star") -> list[Verdict]:
    """Each claim's difference a - b (relative to b's mean too), interval and verdict."""
    out: list[Verdict] = []
    for claim, col, direction, stat in CLAIMS:
        va = np.array([float(r[col]) for r in rows if r["algorithm"] == a and r["reached"] and col in r])
        vb = np.array([float(r[col]) for r in rows if r["algorithm"] == b and r["reached"] and col in r])
        va, vb = va[np.isfinite(va)], vb[np.isfinite(vb)]
        if len(va) < 2 or len(vb) < 2:
            out.append({"claim": claim, "verdict": "not measured"})
            continue
        d, lo, hi = (_ci_mean if stat == "mean" else _ci_std)(va, vb)
        base = float(vb.mean() if stat == "mean" else vb.std(ddof=1))
        if lo > 0 or hi < 0:
            verdict = "reproduced" if (lo > 0) == (direction > 0) else "refuted"
        else:
            verdict = "no difference"
        out.append({"claim": claim, "difference": d, "ci_low": lo, "ci_high": hi,
                    "relative_pct": 100.0 * d / abs(base) if base else math.nan, "verdict": verdict,
                    "runs": (len(va), len(vb))})
    success = {alg: (sum(1 for r in rows if r["algorithm"] == alg and r["reached"]),
                     sum(1 for r in rows if r["algorithm"] == alg)) for alg in (a, b)}
    out.append({"claim": "success rate", "ddrrt": success[a], "rrt": success[b], "verdict": "reported"})
    return out


def verdict_markdown(cells: dict[str, list[Verdict]]) -> str:
    lines = ["| cell | claim | DDRRT* − RRT* | 95 % interval | vs RRT* | verdict |", "|---|---|---:|---|---:|---|"]
    for name, vs in cells.items():
        for v in vs:
            if "difference" not in v:
                extra = f"DDRRT* {v['ddrrt'][0]}/{v['ddrrt'][1]}, RRT* {v['rrt'][0]}/{v['rrt'][1]}" \
                    if "ddrrt" in v else ""
                lines.append(f"| {name} | {v['claim']} | {extra} | | | {v['verdict']} |")
                continue
            lines.append(f"| {name} | {v['claim']} | {v['difference']:+.4g} | "
                         f"[{v['ci_low']:+.4g}, {v['ci_high']:+.4g}] | {v['relative_pct']:+.1f} % | {v['verdict']} |")
    return "\n".join(lines) + "\n"


_MARK = {"reproduced": "**R**", "refuted": "✗", "no difference": "="}


def summary_markdown(cells: dict[str, list[Verdict]]) -> str:
    """The verdicts as one table, a column per cell: the mark (**R** reproduced, ✗ refuted,
    = no difference) and DDRRT* - RRT* relative to RRT*; the last row the goals reached."""
    names = list(cells)
    claims = [c for c, *_ in CLAIMS]
    lines = ["| claim | " + " | ".join(f"`{n}`" for n in names) + " |", "|---|" + "---:|" * len(names)]
    for claim in claims:
        row = []
        for n in names:
            v = next((x for x in cells[n] if x["claim"] == claim), None)
            row.append(f"{_MARK[v['verdict']]} {v['relative_pct']:+.0f} %" if v and "difference" in v else "n/a")
        lines.append(f"| {claim} | " + " | ".join(row) + " |")
    row = []
    for n in names:
        v = next((x for x in cells[n] if x["claim"] == "success rate"), None)
        row.append(f"{v['ddrrt'][0]} / {v['rrt'][0]} of {v['rrt'][1]}" if v else "n/a")
    lines.append("| reached (DDRRT* / RRT*) | " + " | ".join(row) + " |")
    return "\n".join(lines) + "\n"


def main(argv: Sequence[str] | None = None) -> int:
    from hil import experiment

    ap = argparse.ArgumentParser(prog="python -m hil.campaign", description=__doc__.split("\n\n")[0])
    ap.add_argument("--runs", type=int, default=20)
    ap.add_argument("--jobs", type=int, default=2)
    ap.add_argument("--out", type=Path, default=Path("docs/experiments/campaign34"))
    ap.add_argument("--cells", default=",".join(c.name for c in CELLS))
    ap.add_argument("--algorithms", default=None,
                    help="comma-separated planners (default: hil montecarlo's three; the verdicts use "
                         "rrt-star and ddrrt-star)")
    ap.add_argument("--verdicts-only", action="store_true")
    args = ap.parse_args(argv)
    chosen = [c for c in CELLS if c.name in args.cells.split(",")]
    if not args.verdicts_only:
        for cell in chosen:
            cmd = command(cell, args.runs, args.out, args.jobs, algorithms=args.algorithms)
            print(shlex.join(cmd), file=sys.stderr, flush=True)
            subprocess.run([sys.executable, "-m", *cmd], check=True, stdout=subprocess.DEVNULL)
    result = {}
    for cell in chosen:
        path = args.out / cell.name / "runs.csv"
        if path.exists():
            result[cell.name] = verdicts(experiment.read_runs_csv(path))
    (args.out / "verdicts.md").write_text(verdict_markdown(result))
    (args.out / "verdicts.json").write_text(json.dumps(result, indent=1))
    (args.out / "summary.md").write_text(summary_markdown(result))
    print(verdict_markdown(result))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
