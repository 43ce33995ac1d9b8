"""Campaign executors: local processes vs Dask (same runs), an existing scheduler, a killed worker,
Ctrl-C on Dask, the missing-Dask error, and host-wide UDP port reservations."""

from __future__ import annotations

import csv
import json
import multiprocessing as mp
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from hil import executors, experiment, ports

FAST = ("--local-iterations", "500", "--cycle-time", "8")
NEEDS_DASK = "dask.distributed is not installed (pip install 'usv-hil[cluster]')"


def _deterministic(path: Path) -> list[dict]:
    with open(path, newline="") as fh:
        rows = list(csv.DictReader(fh))
    return [{k: r[k] for k in experiment.DETERMINISTIC} for r in rows]


def _distributed():
    return pytest.importorskip("distributed", reason=NEEDS_DASK)


def _local_cluster(n: int):
    distributed = _distributed()
    import logging
    return distributed.LocalCluster(n_workers=n, threads_per_worker=1, processes=True, host="127.0.0.1",
                                    dashboard_address="127.0.0.1:0", silence_logs=logging.ERROR)


@pytest.mark.slow   # e2e: two campaigns, one on a LocalCluster of worker processes
def test_local_processes_and_a_two_worker_local_cluster_give_the_same_runs(hil, tmp_path):
    _distributed()
    a, b = tmp_path / "local", tmp_path / "dask"
    pa = hil("montecarlo", "--scenario", "labyrinth", "--runs", "3", "--jobs", "2", "--seed", "3", "--out", str(a),
             *FAST, "--no-plots")
    assert pa.returncode == 0, pa.stderr
    pb = hil("montecarlo", "--scenario", "labyrinth", "--runs", "3", "--jobs", "2", "--seed", "3", "--out", str(b),
             *FAST, "--no-plots", "--executor", "dask", "--json")
    assert pb.returncode == 0, pb.stderr
    ra, rb = _deterministic(a / "runs.csv"), _deterministic(b / "runs.csv")
    assert len(ra) == 9 and ra == rb
    summary = json.loads(pb.stdout)
    assert summary["executor"] == "dask" and summary["workers"] == 2 and summary["tasks_done"] == 9
    assert "Dask LocalCluster of 2 worker" in pb.stderr and "montecarlo: 9/9" in pb.stderr   # progress as before


@pytest.mark.slow   # e2e: campaigns on a LocalCluster of worker processes
def test_scheduler_address_runs_on_an_existing_cluster(hil, tmp_path):
    cluster = _local_cluster(1)
    try:
        p = hil("montecarlo", "--scenario", "labyrinth", "--runs", "1", "--seed", "4", "--out", str(tmp_path / "s"),
                *FAST, "--no-plots", "--scheduler", cluster.scheduler_address, "--json")
        assert p.returncode == 0, p.stderr
        assert json.loads(p.stdout)["executor"] == "dask"
        q = hil("montecarlo", "--scenario", "labyrinth", "--runs", "1", "--seed", "4", "--jobs", "1",
                "--out", str(tmp_path / "l"), *FAST, "--no-plots")
        assert q.returncode == 0, q.stderr
        assert _deterministic(tmp_path / "s" / "runs.csv") == _deterministic(tmp_path / "l" / "runs.csv")
    finally:
        cluster.close()


@pytest.mark.slow   # e2e: waits out the 30 s connect timeout of hil.executors
def test_unreachable_scheduler_is_a_one_line_error(hil, tmp_path):
    _distributed()
    p = hil("montecarlo", "--runs", "1", "--out", str(tmp_path), "--scheduler", "tcp://127.0.0.1:9",
            env={"DASK_DISTRIBUTED__COMM__TIMEOUTS__CONNECT": "2s"}, timeout=120)
    assert p.returncode == 2, p.stderr
    assert "Traceback" not in p.stderr and "cannot connect to the Dask scheduler" in p.stderr


def test_missing_dask_is_a_one_line_error_with_the_install_hint(hil, tmp_path):
    block = tmp_path / "block"
    (block / "distributed").mkdir(parents=True)
    (block / "distributed" / "__init__.py").write_text("raise ImportError('blocked by the test')\n")
    env = {"PYTHONPATH": os.pathsep.join([str(block), os.environ.get("PYTHONPATH", "")])}
    p = hil("montecarlo", "--runs", "1", "--out", str(tmp_path / "o"), "--executor", "dask", env=env)
    assert p.returncode == 2
    assert "Traceback" not in p.stderr and "pip install 'usv-hil[cluster]'" in p.stderr
    assert len(p.stderr.strip().splitlines()) == 1


@pytest.mark.slow   # e2e: a campaign on a LocalCluster of worker processes
def test_a_worker_killed_mid_campaign_loses_no_run_and_duplicates_none(tmp_path):
    _distributed()
    tasks = experiment.make_tasks("labyrinth", 6, experiment.ALGORITHMS, 7, {"local_iterations": 500,
                                  "cycle_time": 8.0}, None, (), 0)
    reference = experiment.run_campaign(tasks, 1)
    ex = executors.DaskExecutor(jobs=2)
    killed: list[int] = []

    def kill_a_busy_worker(done: int, _row: dict) -> None:
        if killed:
            return
        busy = {w: keys for w, keys in ex.client.processing().items() if keys}
        pids = executors.worker_pids(ex)
        victim = next((w for w in busy if w in pids), None)
        if victim is not None:          # a worker with a task in hand: kill its process outright
            os.kill(pids[victim], signal.SIGKILL)
            killed.append(pids[victim])

    with ex:
        camp = experiment.run_campaign(tasks, 2, tmp_path / "runs.csv", progress=kill_a_busy_worker, executor=ex)
        assert killed, "no worker was busy after the first result"
        assert killed[0] not in executors.worker_pids(ex).values()
    assert not camp.interrupted
    keys = [(r["run"], r["algorithm"]) for r in camp.rows]
    assert len(keys) == len(tasks) and len(set(keys)) == len(tasks)
    on_disk = experiment.read_runs_csv(tmp_path / "runs.csv")
    assert len(on_disk) == len(tasks)

    def det(rows):
        return sorted(tuple(str(r[k]) for k in experiment.DETERMINISTIC) for r in rows)
    assert det(camp.rows) == det(reference.rows)


@pytest.mark.slow   # e2e: a campaign on a LocalCluster, interrupted
def test_ctrl_c_on_dask_cancels_and_keeps_finished_runs(repo, tmp_path):
    _distributed()
    out = tmp_path / "mc"
    proc = subprocess.Popen([sys.executable, "-m", "hil", "montecarlo", "--scenario", "labyrinth", "--runs", "300",
                             "--jobs", "2", "--seed", "1", "--out", str(out), *FAST, "--no-plots",
                             "--executor", "dask"],
                            cwd=repo, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            start_new_session=True)
    try:
        runs = out / "runs.csv"
        deadline = time.monotonic() + 240
        while time.monotonic() < deadline:   # wait (bounded) until at least two runs are on disk
            if runs.exists() and len(runs.read_text().splitlines()) >= 3:
                break
            if proc.poll() is not None:
                break
            time.sleep(0.1)
        assert proc.poll() is None, "finished before it could be interrupted"
        os.killpg(proc.pid, signal.SIGINT)   # a terminal's Ctrl-C: the whole group, workers included
        _, err = proc.communicate(timeout=90)
    finally:
        if proc.poll() is None:
            proc.kill()
    assert proc.returncode == 130, err
    assert "Traceback" not in err
    rows = experiment.read_runs_csv(out / "runs.csv")
    assert 2 <= len(rows) < 900
    assert len({(r["run"], r["algorithm"]) for r in rows}) == len(rows)
    assert "INTERRUPTED" in (out / "table3.md").read_text()


def _reserve(n: int, q) -> None:
    q.put([ports.reserve_udp_port() for _ in range(n)])


def test_port_reservations_never_collide_across_processes():
    ctx = mp.get_context("spawn")
    q = ctx.Queue()
    procs = [ctx.Process(target=_reserve, args=(25, q)) for _ in range(4)]
    for p in procs:
        p.start()
    got = [q.get(timeout=60) for _ in procs]
    for p in procs:
        p.join(timeout=30)
    flat = [port for g in got for port in g]
    assert len(flat) == 100 and len(set(flat)) == 100
    band = ports._band()
    if band is not None:   # below the kernel's ephemeral range: no socket bound to port 0 can take them
        assert all(band[0] <= p < band[1] for p in flat)
    mine = [ports.reserve_udp_port() for _ in range(3)]
    assert len(set(mine)) == 3
    with ports._Locked() as entries:
        assert {str(p) for p in mine} <= set(entries)
    ports.release(*mine)
    with ports._Locked() as entries:
        assert not {str(p) for p in mine} & set(entries)


@pytest.mark.slow
def test_traffic_campaign_on_dask_matches_local_threads(hil, tmp_path):
    """Whole HIL runs (two processes each) on a 2-worker LocalCluster: two runs share the host at a
    time (their ports reserved host-wide), and the campaign equals the local one."""
    _distributed()
    common = ("montecarlo", "--traffic", "--scenario", "colregs-head-on", "--runs", "2", "--jobs", "2",
              "--seed", "3", "--duration", "60", "--json")
    a = hil(*common, "--out", str(tmp_path / "local"), timeout=900)
    assert a.returncode == 0, a.stderr
    b = hil(*common, "--out", str(tmp_path / "dask"), "--executor", "dask", timeout=900)
    assert b.returncode == 0, b.stderr
    assert "Dask LocalCluster of 2 worker" in b.stderr
    sa, sb = (json.loads(p.stdout.strip().splitlines()[-1]) for p in (a, b))
    for key in ("runs", "outcomes", "collision_rate", "encounters", "by_type"):
        assert sa[key] == sb[key], key
    assert (tmp_path / "local" / "runs.csv").read_text() == (tmp_path / "dask" / "runs.csv").read_text()
    for run in ("run0000", "run0001"):
        assert (tmp_path / "dask" / run / "summary.json").exists()


@pytest.mark.slow   # e2e: four whole HIL runs
def test_routes_campaign_on_dask_matches_local_threads(hil, tmp_path):
    """`--routes` runs on the executors too: the same rows on local threads and on a LocalCluster."""
    import csv

    _distributed()
    common = ("montecarlo", "--routes", "--runs", "2", "--jobs", "2", "--seed", "4", "--duration", "30", "--json")
    a = hil(*common, "--out", str(tmp_path / "local"), timeout=900)
    assert a.returncode == 0, a.stderr
    b = hil(*common, "--out", str(tmp_path / "dask"), "--executor", "dask", timeout=900)
    assert b.returncode == 0, b.stderr
    assert "Dask LocalCluster of 2 worker" in b.stderr and "local thread" in a.stderr

    def rows(folder):
        with open(folder / "runs.csv") as fh:
            return [{k: v for k, v in r.items() if k != "scenario"} for r in csv.DictReader(fh)]

    ra, rb = rows(tmp_path / "local"), rows(tmp_path / "dask")
    assert [r["run"] for r in ra] == ["0", "1"] and ra == rb
    for run in ("run0000", "run0001"):
        assert (tmp_path / "dask" / run / "hil" / "summary.json").exists()
