"""The planner worker process and its watchdog, with scripted planner doubles in a real process."""

from __future__ import annotations

import os
import time

import pytest

from autopilot_bridge.planning_worker import PlannerWorker, PlanRequest

FACTORY = "support.planner_doubles:scripted_factory"


def request(cycle: int, behaviour: str, deadline: float = 0.2, iterations: int | None = None) -> PlanRequest:
    return PlanRequest(cycle=cycle, problem=behaviour, deadline_s=deadline, iterations=iterations)


def started(worker: PlannerWorker) -> PlannerWorker:
    assert worker.wait_ready(30.0), "worker did not start"
    return worker


def wait_for_reply(worker: PlannerWorker, timeout: float = 30.0):
    reply = worker.wait(timeout)
    assert reply is not None, "worker did not answer"
    return reply


def test_answers_requests_in_a_separate_process():
    with PlannerWorker(FACTORY) as w:
        started(w)
        assert w.submit(request(1, "echo"))
        reply = wait_for_reply(w)
        assert reply.cycle == 1 and reply.result.status == "exact"
        assert reply.result.pid == w.pid != os.getpid()
        assert w.stats.answered == 1 and w.stats.killed == 0


def test_a_busy_worker_refuses_a_second_request_and_counts_it():
    with PlannerWorker(FACTORY) as w:
        started(w)
        assert w.submit(request(1, "slow", deadline=0.3))
        assert not w.submit(request(2, "echo"))
        assert w.stats.busy_rejections == 1
        assert wait_for_reply(w).cycle == 1


def test_iteration_budget_is_passed_to_the_planner():
    with PlannerWorker(FACTORY) as w:
        started(w)
        w.submit(request(1, "slow", deadline=60.0, iterations=1234))
        reply = wait_for_reply(w)
        assert reply.result.iterations == 1234


def test_hanging_planner_is_killed_restarted_and_never_blocks_poll():
    with PlannerWorker(FACTORY, grace_s=0.1) as w:
        started(w)
        t0 = time.monotonic()
        w.submit(request(7, "hang", deadline=0.2), now=t0)
        old_pid = w.pid
        # Polling a hung planner returns at once with nothing, however often it is asked.
        assert all(w.poll(now=t0) is None for _ in range(100))
        assert not w.watchdog(now=t0 + 0.25)          # within deadline + grace: left alone
        assert w.watchdog(now=t0 + 0.35)              # past it: killed and restarted
        assert w.stats.killed == 1 and w.stats.restarts == 1
        assert w.pid != old_pid and not w.busy
        assert any("cycle 7" in e and "killed" in e for e in w.stats.events)
        # The old process is gone and the new one works.
        with pytest.raises(ProcessLookupError):
            for _ in range(100):
                os.kill(old_pid, 0)
                time.sleep(0.05)
        started(w)
        w.submit(request(8, "echo"))
        assert wait_for_reply(w).cycle == 8


def test_planner_exception_is_reported_not_fatal():
    with PlannerWorker(FACTORY) as w:
        started(w)
        w.submit(request(1, "raise"))
        reply = wait_for_reply(w)
        assert reply.result is None and "planner bug" in reply.error
        assert w.stats.errors == 1
        w.submit(request(2, "echo"))
        assert wait_for_reply(w).result.status == "exact"


def test_a_starting_worker_takes_no_request_so_its_start_up_is_never_an_overrun():
    """A start-up longer than deadline + grace must not be charged to the first request: else each
    restarted worker overruns, is killed, and the next one too (the cascade seen in User-Mode Linux)."""
    with PlannerWorker("support.planner_doubles:slow_start_factory", (1.0,), grace_s=0.1) as w:
        assert not w.submit(request(1, "echo", deadline=0.2))
        assert w.stats.not_ready_rejections == 1 and w.stats.submitted == 0
        assert not w.watchdog()                       # starting up is not hanging
        started(w)
        assert w.stats.startup_s and w.stats.startup_s[0] >= 1.0
        t0 = time.monotonic()
        assert w.submit(request(2, "echo", deadline=0.2), now=t0)
        reply = wait_for_reply(w)
        assert reply.cycle == 2 and w.stats.overruns == 0 and w.stats.killed == 0
        # After a restart the new worker starts up again before it takes a request.
        w.submit(request(3, "hang", deadline=0.2), now=time.monotonic())
        assert w.watchdog(now=time.monotonic() + 1.0) and w.stats.killed == 1
        assert not w.ready and not w.submit(request(4, "echo"))
        started(w)
        assert w.submit(request(5, "echo"))
        assert wait_for_reply(w).cycle == 5 and w.stats.overruns == 0 and w.stats.restarts == 1


def test_a_worker_that_never_starts_is_killed_after_its_start_up_limit():
    with PlannerWorker("support.planner_doubles:slow_start_factory", (3600.0,), startup_timeout_s=0.5) as w:
        t0 = time.monotonic()
        old = w.pid
        assert not w.watchdog(now=t0)
        assert w.watchdog(now=t0 + 1.0)
        assert w.stats.killed == 1 and w.pid != old
        assert any("not started" in e for e in w.stats.events)


def test_a_stop_signal_to_the_process_group_leaves_the_worker_to_its_parent():
    """Runs are stopped with SIGTERM to the process group; the parent may still serve a frame and
    submit, so the worker must not die first (that was a BrokenPipeError crash at the end of a soak)."""
    import signal

    with PlannerWorker(FACTORY) as w:
        started(w)
        os.kill(w.pid, signal.SIGTERM)
        os.kill(w.pid, signal.SIGINT)
        assert w.submit(request(1, "echo"))
        assert wait_for_reply(w).cycle == 1 and w.stats.restarts == 0


def test_submit_to_a_dead_worker_restarts_it_instead_of_raising():
    import signal

    with PlannerWorker(FACTORY) as w:
        started(w)
        dead = w.pid
        os.kill(dead, signal.SIGKILL)
        for _ in range(200):                          # until the kernel has closed its pipe end
            if not w.submit(request(1, "echo")):
                break
            w.wait(5.0)
        assert w.stats.restarts == 1 and w.pid != dead
        started(w)
        assert w.submit(request(2, "echo")) and wait_for_reply(w).cycle == 2


@pytest.mark.parametrize("run_seed", [0, 1, 10**15, 2**64 + 5])
def test_every_run_seed_gives_planning_cycles_a_seed_the_planner_takes(run_seed):
    """`hil run --seed 1000000000000000` planned nothing (every cycle 'planner error: OverflowError'): a
    cycle's seed is the run's seed mixed with the cycle number, kept within the planner's signed 64 bits
    (unchanged for the seeds that already fitted, so their runs stay as they were)."""
    import numpy as np

    from autopilot_bridge.plan_handoff import cycle_seed
    from planner import make_planner
    from planner.gridmap import OccupancyGrid
    from planner.params import SEED_MAX, PlannerParams
    from planner.problem import PlanningProblem
    from planner.termination import Termination

    seeds = [cycle_seed(run_seed, c) for c in (1, 2, 1000)]
    assert all(0 <= s <= SEED_MAX for s in seeds) and len(set(seeds)) == 3
    if run_seed * 100003 + 1000 <= SEED_MAX:
        assert seeds == [run_seed * 100003 + c for c in (1, 2, 1000)]
    grid = OccupancyGrid(np.zeros((20, 20), dtype=bool), 1.0)
    problem = PlanningProblem(grid=grid, start=(2.0, 2.0), goal=(15.0, 15.0), start_heading=None, field=None)
    result = make_planner("rrt-star", PlannerParams(seed=seeds[-1])).solve(problem, Termination.iterations(50))
    assert result.status != "none"
