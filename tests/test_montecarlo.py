"""`hil montecarlo`: reproducibility across --jobs, the Table 3 writers, figures, Ctrl-C."""

from __future__ import annotations

import csv
import json
import math
import queue
import signal
import subprocess
import sys
import threading
import time

import pytest

from hil import experiment

FAST = ("--local-iterations", "500", "--cycle-time", "8")


def _deterministic(path):
    with open(path, newline="") as fh:
        rows = list(csv.DictReader(fh))
    return [{k: r[k] for k in experiment.DETERMINISTIC} for r in rows]


@pytest.mark.slow   # e2e: three campaigns, on worker processes
def test_reproducible_from_the_seed_whatever_the_jobs(hil, tmp_path):
    a, b, c = tmp_path / "a", tmp_path / "b", tmp_path / "c"
    pa = hil("montecarlo", "--scenario", "labyrinth", "--runs", "2", "--jobs", "2", "--seed", "5", "--out", str(a),
             *FAST, "--json")
    assert pa.returncode == 0, pa.stderr
    pb = hil("montecarlo", "--scenario", "labyrinth", "--runs", "2", "--jobs", "1", "--seed", "5", "--out", str(b),
             *FAST, "--no-plots")
    assert pb.returncode == 0, pb.stderr
    pc = hil("montecarlo", "--scenario", "labyrinth", "--runs", "2", "--jobs", "1", "--seed", "6", "--out", str(c),
             *FAST, "--no-plots")
    assert pc.returncode == 0, pc.stderr
    ra, rb, rc = (_deterministic(d / "runs.csv") for d in (a, b, c))
    assert len(ra) == 6 and ra == rb
    assert [r["cost"] for r in ra] != [r["cost"] for r in rc]

    summary = json.loads(pa.stdout)
    assert summary["tasks_done"] == 6 and not summary["interrupted"]
    assert summary["runs_done"] == {a: 2 for a in experiment.ALGORITHMS}
    assert [t["algorithm"] for t in summary["table3"]] == list(experiment.ALGORITHMS)
    assert "montecarlo:" in pa.stderr                  # progress on stderr
    for name in ("runs.csv", "table3.csv", "table3.md", "figure10.png", "figure11.png", "summary.json"):
        assert (a / name).exists(), name
    import matplotlib.image as mpimg
    for fig in ("figure10.png", "figure11.png"):
        assert (a / fig).stat().st_size > 50_000
        assert mpimg.imread(a / fig).std() > 0.05
    md = (a / "table3.md").read_text()
    assert "DDRRT*" in md and "+82.09%" in md and "Σcos" in md


def test_random_scenario_runs_differ_per_run(hil, tmp_path):
    p = hil("montecarlo", "--scenario", "random", "--runs", "2", "--algorithms", "ddrrt-star", "--jobs", "1",
            "--seed", "2", "--out", str(tmp_path), *FAST, "--figure-runs", "2", "--json")
    assert p.returncode == 0, p.stderr
    rows = experiment.read_runs_csv(tmp_path / "runs.csv")
    assert len(rows) == 2
    assert (rows[0]["start_x"], rows[0]["goal_x"]) != (rows[1]["start_x"], rows[1]["goal_x"])
    assert (tmp_path / "figure11.png").stat().st_size > 30_000


@pytest.mark.parametrize("args", [("--runs", "0"), ("--jobs", "0"), ("--algorithms", "dijkstra"),
                                  ("--scenario", "atlantis"), ("--local-iterations", "0", "--local-time", "0"),
                                  ("--local-iterations", "0"), ("--local-clock", "sundial"),
                                  ("--local-time", "0.00001", "--local-clock", "thread-cpu")])
def test_bad_arguments_exit_2(hil_main, tmp_path, args):
    p = hil_main("montecarlo", "--out", str(tmp_path), *args)
    assert p.returncode == 2
    assert "Traceback" not in p.stderr and p.stderr.strip()


def _row(run, alg, reached=True, **kw):
    base = {c: 0.0 for c in experiment.COLUMNS}
    base.update(run=run, algorithm=alg, planner_seed=run, reached=reached, reason="goal reached", cycles=10,
                iterations=100, smoothing_fallbacks=0)
    base.update(kw)
    return base


def test_table3_aggregation_and_writers(tmp_path):
    rows = [
        _row(0, "rrt-star", time_s=1.0, cost=100.0, sum_cos=10.0, sum_sin=20.0, cf=0.5),
        _row(1, "rrt-star", time_s=3.0, cost=120.0, sum_cos=30.0, sum_sin=40.0, cf=0.7),
        _row(0, "ddrrt-star", time_s=1.0, cost=90.0, sum_cos=36.0, sum_sin=27.0, cf=0.9),
        _row(1, "ddrrt-star", reached=False, time_s=50.0, cost=1e6, sum_cos=0.0, sum_sin=0.0, cf=0.0),
    ]
    table = experiment.table3(rows, ("rrt-star", "ddrrt-star"))
    rrt, dd = table
    assert rrt["time_s"] == 2.0 and rrt["time_std_s"] == pytest.approx(math.sqrt(2.0))
    assert rrt["cost"] == 110.0 and rrt["cost_std"] == pytest.approx(math.sqrt(200.0))
    assert dd["runs"] == 2 and dd["reached"] == 1 and dd["success_rate"] == 0.5
    assert dd["cost"] == 90.0 and dd["cost_std"] == 0.0          # failed runs excluded from the means
    assert dd["sum_cos_vs_rrt_pct"] == pytest.approx(80.0)       # 36 vs 20
    assert dd["sum_sin_vs_rrt_pct"] == pytest.approx(-10.0)      # 27 vs 30
    assert dd["time_s_vs_rrt_pct"] == pytest.approx(-50.0)

    experiment.write_runs_csv(tmp_path / "runs.csv", rows)
    back = experiment.read_runs_csv(tmp_path / "runs.csv")
    assert [(r["run"], r["algorithm"]) for r in back] == [(0, "rrt-star"), (0, "ddrrt-star"), (1, "rrt-star"),
                                                          (1, "ddrrt-star")]
    assert back[3]["reached"] is False and back[1]["cost"] == 90.0

    experiment.write_table_csv(tmp_path / "t.csv", table)
    with open(tmp_path / "t.csv", newline="") as fh:
        t = list(csv.DictReader(fh))
    assert t[1]["algorithm"] == "ddrrt-star" and float(t[1]["sum_cos_vs_rrt_pct"]) == pytest.approx(80.0)
    md = experiment.write_table_md(tmp_path / "t.md", table, "T").read_text()
    assert "| DDRRT* | 2 | 1 |" in md
    assert "+80.00% (+82.09%)" in md and "-10.00% (-17.23%)" in md


def test_seeds_depend_on_run_and_algorithm_only():
    s = {experiment.planner_seed(1, r, a) for r in range(50) for a in experiment.ALGORITHMS}
    assert len(s) == 150
    assert experiment.planner_seed(1, 7, "ddrrt-star") == experiment.planner_seed(1, 7, "ddrrt-star")
    assert experiment.planner_seed(1, 7, "ddrrt-star") != experiment.planner_seed(2, 7, "ddrrt-star")


@pytest.mark.slow   # e2e: a campaign on worker processes, interrupted
@pytest.mark.parametrize("sig", [signal.SIGINT, signal.SIGTERM])
def test_ctrl_c_keeps_finished_runs(repo, tmp_path, sig):
    out = tmp_path / "mc"
    proc = subprocess.Popen([sys.executable, "-m", "hil", "montecarlo", "--scenario", "labyrinth", "--runs", "300",
                             "--jobs", "2", "--seed", "1", "--out", str(out), *FAST, "--no-plots"],
                            cwd=repo, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        runs = out / "runs.csv"
        deadline = time.monotonic() + 180
        while time.monotonic() < deadline:   # wait (bounded) until at least two runs are on disk
            if runs.exists() and len(runs.read_text().splitlines()) >= 3:
                break
            if proc.poll() is not None:
                break
            time.sleep(0.1)
        assert proc.poll() is None, "finished before it could be interrupted"
        proc.send_signal(sig)
        _, err = proc.communicate(timeout=60)
    finally:
        if proc.poll() is None:
            proc.kill()
    assert proc.returncode == 130, err
    assert "Traceback" not in err
    rows = experiment.read_runs_csv(out / "runs.csv")
    assert 2 <= len(rows) < 900
    assert "INTERRUPTED" in (out / "table3.md").read_text()


@pytest.mark.slow   # e2e: whole HIL runs on threads, interrupted
@pytest.mark.parametrize("sig", [signal.SIGINT, signal.SIGTERM])
def test_ctrl_c_keeps_finished_route_runs(repo, tmp_path, sig):
    """`hil montecarlo --routes`: Ctrl-C (SIGINT to the terminal's process group) or SIGTERM keeps the runs
    that finished in runs.csv and summary.json (interrupted, runs_done) and says so, exit 130; it used
    to end with 'hil montecarlo: interrupted' and no runs.csv."""
    import os

    out = tmp_path / "mc"
    proc = subprocess.Popen([sys.executable, "-m", "hil", "montecarlo", "--routes", "--runs", "8", "--jobs", "2",
                             "--seed", "3", "--duration", "20", "--out", str(out), "--json"],
                            cwd=repo, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            start_new_session=True)
    lines: queue.Queue = queue.Queue()
    reader = threading.Thread(target=lambda: [lines.put(x) for x in iter(proc.stderr.readline, "")], daemon=True)
    reader.start()
    seen: list[str] = []
    try:
        # Wait (bounded) until the campaign itself has taken a finished run: its progress line says
        # "1/8". (A run's own summary.json on disk comes a moment before the campaign has it.)
        deadline = time.monotonic() + 240
        while time.monotonic() < deadline and proc.poll() is None:
            try:
                seen.append(lines.get(timeout=1.0))
            except queue.Empty:
                continue
            if seen[-1].startswith("montecarlo routes: 1/8"):
                break
        assert proc.poll() is None and seen and seen[-1].startswith("montecarlo routes: 1/8"), seen
        os.killpg(proc.pid, sig) if sig == signal.SIGINT else proc.send_signal(sig)
        proc.wait(timeout=120)
        stdout = proc.stdout.read()   # one JSON summary: it fits the pipe
        reader.join(timeout=10)
        while not lines.empty():
            seen.append(lines.get())
        err = "".join(seen)
    finally:
        if proc.poll() is None:
            os.killpg(proc.pid, signal.SIGKILL)
            proc.wait()
    assert proc.returncode == 130, err
    assert "Traceback" not in err
    summary = json.loads((out / "summary.json").read_text())
    assert summary == json.loads(stdout)
    assert summary["interrupted"] is True and 1 <= summary["runs_done"] < 8, summary
    with open(out / "runs.csv", newline="") as fh:
        rows = list(csv.DictReader(fh))
    assert len(rows) == summary["runs_done"]
    assert "interrupted" in err.strip().splitlines()[-1] and f"{len(rows)} of 8" in err.strip().splitlines()[-1]


def test_a_thread_cpu_budget_per_cycle_from_the_command_line(hil_main, tmp_path):
    """`--local-iterations 0 --local-time S --local-clock thread-cpu`: issue 34's equal CPU-time cell."""
    p = hil_main("montecarlo", "--scenario", "labyrinth", "--runs", "1", "--jobs", "1", "--algorithms", "rrt-star",
                 "--local-iterations", "0", "--local-time", "0.002", "--local-clock", "thread-cpu", "--no-plots",
                 "--out", str(tmp_path / "cpu"), "--json")
    assert p.returncode == 0, p.stderr
    summary = json.loads(p.stdout)
    assert summary["online"] == {"local_iterations": 0, "local_time_s": 0.002, "local_clock": "thread-cpu",
                                 "cycle_time_s": summary["online"]["cycle_time_s"]}
    row = experiment.read_runs_csv(tmp_path / "cpu" / "runs.csv")[0]
    assert row["cycles"] > 0 and row["iterations"] > 0
