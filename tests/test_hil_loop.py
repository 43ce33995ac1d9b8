"""The whole HIL loop: `hil run` with the simulator and the autopilot as two real processes on UDP."""

from __future__ import annotations

import gc
import json
import os
from typing import Any

import pytest

from common.tables import to_table
from hil import placement, settings
from hil.hilrun import (
    WALL_CLOCK_KEYS,  # figures that depend on the wall clock or the host, not the seed
    RunOptions,
    run_loop,
)
from hil.run_summary import read_summary


def _run(hil, tmp_path, *args: str, name: str = "run", traffic: bool = True) -> tuple[int, dict]:
    out = tmp_path / name
    r = hil("run", "--json", "--out", str(out), "--no-plot", *args, timeout=600)
    assert r.stdout.strip(), r.stderr
    summary = json.loads(r.stdout.strip().splitlines()[-1])
    assert (out / "summary.json").exists() and (out / "run.tlog").exists()
    assert not traffic or (out / "run.tlog").stat().st_size > 0
    typed = read_summary(summary)     # every section as its owner typed it (hil/run_summary.py)
    assert typed.simulator_counters() == typed.simulator and typed.ardurover() is None   # None: no simulator summary
    return r.returncode, summary


@pytest.mark.slow
# Labyrinth seeds 2 and 4 hit a wall while each cycle's path started along the hull's heading instead
# of the course over ground (tests/test_plan_start_course.py).
@pytest.mark.parametrize("scenario, seed", [("harbour", 1), ("harbour", 2), ("labyrinth", 1), ("labyrinth", 2),
                                            ("labyrinth", 4)])
def test_lockstep_run_reaches_the_goal_without_collision(hil, tmp_path, scenario, seed):
    code, s = _run(hil, tmp_path, "--scenario", scenario, "--seed", str(seed))
    assert s["outcome"] == "goal", s["events"]
    assert s["reached_goal"] and s["collisions"] == 0
    assert s["min_clearance_m"] >= 1.0  # the hull's half length
    assert code == 0
    # The autopilot navigated on its own estimate, well inside the GPS noise.
    assert s["navigation_rmse_m"] < 0.5
    assert s["planning_cycles"] > 10 and s["plans_accepted"] > 0.8 * s["planning_cycles"]


@pytest.mark.slow
@pytest.mark.parametrize("seed", [1, 3])
def test_obstacles_missing_from_the_chart_are_sensed_and_avoided(hil, tmp_path, seed):
    """harbour-uncharted: three obstacles on the chart-only track that only the range sensor shows."""
    code, s = _run(hil, tmp_path, "--scenario", "harbour-uncharted", "--seed", str(seed))
    assert s["outcome"] == "goal" and s["collisions"] == 0 and code == 0, s["events"]
    assert s["min_clearance_m"] >= 1.0
    sensed = s["sensed_obstacles"]
    assert sensed["cells"] > 50                     # all three are found (each is tens of cells)
    assert sensed["explained_by_chart"] < sensed["returns"]


@pytest.mark.slow
def test_without_sensing_the_uncharted_obstacle_is_hit(hil, tmp_path):
    """The same run planning on the chart alone: collisions are judged on the truth, so it fails."""
    code, s = _run(hil, tmp_path, "--scenario", "harbour-uncharted", "--seed", "1",
                   "--set", "autopilot.sensed_obstacles=false")
    assert s["outcome"] == "collision" and s["collisions"] == 1 and code == 1
    assert s["sensed_obstacles"]["cells"] == 0


@pytest.mark.slow
def test_same_seed_gives_the_same_summary(hil, tmp_path):
    _, a = _run(hil, tmp_path, "--scenario", "labyrinth", "--seed", "5", name="a")
    _, b = _run(hil, tmp_path, "--scenario", "labyrinth", "--seed", "5", name="b")
    def strip(s):
        return {k: v for k, v in s.items() if k not in WALL_CLOCK_KEYS}
    assert strip(a) == strip(b)


@pytest.mark.slow
@pytest.mark.parametrize("scenario", ["harbour", "labyrinth"])
def test_the_pipelined_lockstep_reaches_the_goal_and_repeats_itself(hil, tmp_path, scenario):
    """`hil run --pipeline`: the simulator one frame ahead, each command one frame late
    (tests/test_sim_pipeline.py); the vessel still reaches the goal, and a rerun is the same run."""
    code, a = _run(hil, tmp_path, "--scenario", scenario, "--seed", "1", "--pipeline", name="a")
    assert a["outcome"] == "goal" and a["collisions"] == 0 and code == 0, a["events"]
    assert a["simulator"]["pipeline_skips"] == 0   # nothing lost on loopback
    assert a["navigation_rmse_m"] < 0.5
    _, b = _run(hil, tmp_path, "--scenario", scenario, "--seed", "1", "--pipeline", name="b")

    def strip(s):
        return {k: v for k, v in s.items() if k not in WALL_CLOCK_KEYS}
    assert strip(a) == strip(b)


def _cpus_of(pid: int) -> set[int]:
    return set(os.sched_getaffinity(pid))


@pytest.mark.slow
@pytest.mark.skipif(len(placement.usable()) < 2, reason="placing the loop's ends needs two usable CPUs")
def test_a_placed_run_pins_each_end_and_gives_the_tap_its_cpus_back(tmp_path):
    """`hil run --cpus A,B` (what `auto` picks on a free pair): the run's four processes read from
    /proc while it runs, the simulator and the tap (this process) on A, the vessel computer and its
    planner worker on B; afterwards this process has its CPUs back, and the run is the run the
    scheduler's own placement gives (`--cpus off`)."""
    cpus = placement.usable()
    before = _cpus_of(0)
    seen: dict[str, set[int]] = {}
    policies: dict[str, int] = {}

    def policy(tap, run):
        workers = placement.children(run.ap.pid)
        if "free" not in policies and tap.truth and workers:
            policies["free"] = os.getpriority(os.PRIO_PROCESS, workers[0])

    def look(tap, run):
        if seen or not tap.truth:
            return
        seen["simulator"] = _cpus_of(run.sim.pid)
        seen["computer"] = _cpus_of(run.ap.pid)
        seen["tap"] = _cpus_of(0)
        workers = placement.children(run.ap.pid)
        assert workers, "the vessel computer has a planner worker"
        seen["planner_worker"] = _cpus_of(workers[0])
        policies["placed"] = os.getpriority(os.PRIO_PROCESS, workers[0])

    def run(name: str, cpus_opt, hooks=()) -> Any:
        opts = RunOptions(scenario="harbour", lockstep=True, duration=300.0, seed=3, out=tmp_path / name,
                          plot=False, cpus=cpus_opt,
                          hooks=list(hooks), wall_timeout=300.0)
        return run_loop(opts, settings.load(None, opts.overrides))

    a, b = cpus[-1], cpus[0]
    placed = run("placed", placement.Placement(a, b), [look])
    assert placed.outcome == "goal", placed.events
    assert gc.get_freeze_count() == 0   # the tap froze its heap for the loop only: a campaign's runs share it
    assert seen == {"simulator": {a}, "computer": {b}, "tap": {a}, "planner_worker": {b}}
    assert placed.simulator["cpus"] == {"simulator": a, "tap": a, "computer": b, "planner_worker": b}
    assert _cpus_of(0) == before
    free = run("free", "off", [policy])
    assert free.simulator["cpus"] is None
    # Placed, the worker yields to the vessel computer it shares a CPU with; left to the scheduler, as any process.
    assert policies == {"placed": min(19, os.getpriority(os.PRIO_PROCESS, 0) + placement.WORKER_NICE),
                        "free": os.getpriority(os.PRIO_PROCESS, 0)}
    # The vessel computer slept on its socket, not polling, while the worker had a request out (at
    # most the frames of a planning deadline, 30, each cycle).
    held = placed.simulator["busy_poll"]["autopilot"]["held"]
    assert 0 < held <= 31 * placed.planning_cycles, (held, placed.planning_cycles)

    def strip(s: Any) -> dict:
        return {k: v for k, v in to_table(s).items() if k not in WALL_CLOCK_KEYS}
    assert strip(placed) == strip(free)


def test_tlog_is_readable_by_pymavlink(hil, tmp_path):
    from pymavlink import mavutil

    code, s = _run(hil, tmp_path, "--scenario", "harbour", "--duration", "5")
    assert s["outcome"] == "timeout" and code == 1  # 5 s is not enough to reach the goal: a failed run
    log = mavutil.mavlink_connection(s["tlog"])
    kinds = set()
    for _ in range(5000):
        m = log.recv_match()
        if m is None:
            break
        kinds.add(m.get_type())
    assert {"HIL_SENSOR", "HIL_GPS", "HIL_STATE_QUATERNION", "HIL_ACTUATOR_CONTROLS", "LOCAL_POSITION_NED",
            "HEARTBEAT"} <= kinds


def test_a_reused_run_folder_holds_only_the_new_runs_logs(hil, tmp_path):
    """`hil run --out DIR` twice: each process log holds one run (they used to be appended to), and
    an earlier run's simulator-restart log, which the new run did not have, is gone."""
    _run(hil, tmp_path, "--scenario", "harbour", "--duration", "2")
    (tmp_path / "run" / "sim-restart1.log").write_text("sim: an earlier run's restart\n")
    _run(hil, tmp_path, "--scenario", "harbour", "--duration", "2")
    sim_log = (tmp_path / "run" / "sim.log").read_text()
    ap_log = (tmp_path / "run" / "autopilot.log").read_text()
    assert sim_log.count("sim: commands on") == 1, sim_log
    assert ap_log.count("autopilot: listening on") == 1, ap_log
    assert not (tmp_path / "run" / "sim-restart1.log").exists()


def test_unknown_scenario_is_one_line_exit_2(hil):
    r = hil("run", "--scenario", "atlantis", timeout=60)
    assert r.returncode == 2
    assert len(r.stderr.strip().splitlines()) == 1 and "atlantis" in r.stderr


def test_wall_timeout_ends_the_run_with_its_folder_written(hil, tmp_path):
    # The wall timeout covers the autopilot's start-up too (issue 14): 4 s may end the run before
    # any traffic, with an empty run.tlog.
    code, s = _run(hil, tmp_path, "--wall-timeout", "4", traffic=False)
    assert s["outcome"] == "wall_timeout" and code == 1
    assert 4.0 <= s["wall_time_s"] < 60.0


@pytest.mark.slow
def test_bench_loop_measures_plain_and_pipelined_lockstep_against_the_simulator_alone(hil):
    # `auto` places a run on the first pair of CPUs no other run holds: free now, unless another
    # suite runs beside this one.
    probe = placement.claim("auto", lockstep=True)
    free = probe is not None
    if probe is not None:
        probe.release()
    r = hil("bench", "loop", "--duration", "4", "--realtime-duration", "0", "--sim-steps", "300", "--json",
            timeout=600)
    assert r.returncode == 0, r.stderr
    res = json.loads(r.stdout.strip().splitlines()[-1])
    assert res["simulator_alone_steps_per_s"] > 0 and "realtime" not in res
    for name in ("lockstep", "pipelined"):
        leg = res[name]
        assert leg["simulator_steps"] >= 400 and leg["steps_per_wall_s"] > 0, leg
        ratio = leg["steps_per_wall_s"] / res["simulator_alone_steps_per_s"]   # the reference is rounded to 0.1
        assert leg["ratio_to_simulator"] == pytest.approx(ratio, abs=2e-3)
    assert res["pipelined"]["pipeline_skips"] == 0 and "pipeline_skips" not in res["lockstep"]
    # Each leg placed as `hil run` places it (hil.placement) where a pair of CPUs was free.
    for name in ("lockstep", "pipelined"):
        assert (res[name]["cpus"] is not None) == free, res[name]["cpus"]
        assert res[name]["cpus"] is None or set(res[name]["cpus"]) == {"simulator", "tap", "computer",
                                                                       "planner_worker"}
    assert isinstance(res["speed_goal_met"], bool) and isinstance(res["pipelined_speed_goal_met"], bool)
    assert "bench loop: pipelined, 4 s simulated" in r.stderr
