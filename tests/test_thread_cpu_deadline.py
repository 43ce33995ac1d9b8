"""A planning budget on the thread's CPU clock (issue 34: the equal CPU-time cell).

No timing-fragile asserts: a CPU deadline of S must let the search use at least S of thread CPU,
whatever the wall clock did meanwhile, and it must be checked inside the compiled search.
"""

from __future__ import annotations

import time

import numpy as np
import pytest

from hil import scenario as scenarios
from hil.errors import ConfigError
from planner import PlannerParams
from planner.gridmap import OccupancyGrid
from planner.online import OnlineParams, VesselState, make_context, plan_cycle, run_online
from planner.problem import PlanningProblem
from planner.registry import make_planner
from planner.termination import Termination

BUDGET = 0.03  # s of thread CPU


def _problem() -> PlanningProblem:
    occ = np.zeros((120, 120), bool)
    occ[20:100, 60] = True  # a wall between start and goal: the search keeps rewiring
    return PlanningProblem(OccupancyGrid(occ, 0.5), (10.0, 30.0), (50.0, 30.0))


@pytest.mark.parametrize("alg", ["rrt-star", "ddrrt-star"])
def test_thread_cpu_deadline_stops_the_compiled_search_after_its_cpu_budget(alg):
    planner = make_planner(alg, PlannerParams(seed=2))
    problem = _problem()
    planner.solve(problem, Termination.iterations(10))  # compiled code loaded before the budget starts
    c0 = time.thread_time()  # before the condition: its budget starts when it is made
    cond = Termination.thread_cpu_deadline(BUDGET)
    b = cond.bounds()
    assert b.thread_cpu_deadline is not None and b.monotonic_deadline is None and not b.poll_python
    res = planner.solve(problem, cond)
    used = time.thread_time() - c0
    # stopped by the compiled core's deadline check (DONE_DEADLINE), not by the tree filling up
    assert "deadline reached" in res.reason, res.reason
    assert used >= BUDGET
    assert res.diagnostics["thread_cpu_s"] >= BUDGET * 0.9   # measured from inside solve, after the set-up
    assert res.iterations > 0


def _sleep_once(seconds: float):
    slept = [0.0]

    def predicate() -> bool:
        if slept[0] == 0.0:
            t = time.monotonic()
            time.sleep(seconds)
            slept[0] = time.monotonic() - t
        return False

    return predicate, slept


def test_time_the_thread_sleeps_does_not_consume_a_cpu_budget():
    """The thread sleeps 3 S of wall clock at the start of the search: a wall deadline of S is
    then spent before the first iteration, a CPU deadline of S still lets the search use S of CPU."""
    problem = _problem()
    planner = make_planner("rrt-star", PlannerParams(seed=2))
    planner.solve(problem, Termination.iterations(10))

    sleeper, slept = _sleep_once(3 * BUDGET)
    wall = planner.solve(problem, Termination.any_of(Termination.deadline(BUDGET), Termination.custom(sleeper)))
    assert slept[0] >= 3 * BUDGET
    assert wall.iterations == 0, wall.reason  # the wall budget went by while the thread slept

    sleeper, slept = _sleep_once(3 * BUDGET)
    c0 = time.thread_time()
    cpu = planner.solve(problem, Termination.any_of(Termination.thread_cpu_deadline(BUDGET),
                                                    Termination.custom(sleeper)))
    used = time.thread_time() - c0
    assert slept[0] >= 3 * BUDGET
    assert used >= BUDGET and cpu.iterations > 0
    assert "deadline reached" in cpu.reason or "termination condition met" in cpu.reason


def test_the_thread_cpu_deadline_refuses_a_bad_budget():
    for bad in (-1.0, float("inf"), float("nan")):
        with pytest.raises(ValueError, match="thread_cpu_deadline"):
            Termination.thread_cpu_deadline(bad)


def test_online_local_clock_is_checked():
    with pytest.raises(ValueError, match="local_clock"):
        OnlineParams(local_clock="cpu")  # type: ignore[arg-type]
    with pytest.raises(ConfigError, match="local_time"):
        scenarios.online_params({"local_time": 601.0}, "test")
    assert OnlineParams().local_clock == "wall"


def _ctx(**online):
    sc = scenarios.load("labyrinth")
    params = scenarios.planner_params(PlannerParams(), sc.planner_overrides)
    op = scenarios.online_params({**sc.online_overrides, **online})
    return sc, make_context(OccupancyGrid(sc.occ, sc.resolution), sc.goal, sc.reference_path, params, op,
                            "ddrrt-star", sc.planning_field())


def test_an_iteration_budget_gives_bit_identical_runs_whatever_the_clock_field():
    """With an iteration budget the clock field changes nothing: the default, and a thread-CPU
    deadline that never fires beside the iterations, give the same runs bit for bit."""
    sc, base = _ctx(local_iterations=300)
    _, cpu = _ctx(local_iterations=300, local_time=600.0, local_clock="thread-cpu")
    start = VesselState(*sc.start, sc.start_heading)
    a, b = run_online(base, start, seed=3), run_online(cpu, start, seed=3)
    assert np.array_equal(a.executed, b.executed)
    assert a.metrics == b.metrics
    assert [c.iterations for c in a.cycles] == [c.iterations for c in b.cycles]
    for ca, cb in zip(a.cycles, b.cycles, strict=True):
        assert np.array_equal(ca.tree_nodes, cb.tree_nodes)


def test_online_cycle_on_a_cpu_budget_stops_after_it():
    sc, ctx = _ctx(local_iterations=0, local_time=BUDGET, local_clock="thread-cpu")
    start = VesselState(*sc.start, sc.start_heading)
    plan_cycle(ctx, start, 0, seed=1)  # loads the compiled code
    c0 = time.thread_time()
    rec = plan_cycle(ctx, start, 0, seed=1, clock=lambda: 0.0)  # the wall clock is not read
    assert time.thread_time() - c0 >= BUDGET
    assert rec.iterations > 0 and "deadline reached" in rec.reason
