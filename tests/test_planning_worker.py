"""The planner worker process and its watchdog, with scripted planner doubles in a real process."""

from __future__ import annotations

import os
import time

import pytest

from autopilot_bridge.planning_worker import PlannerWorker, PlanRequest

FACTORY = "planner_doubles:scripted_factory"


def request(cycle: int, behaviour: str, deadline: float = 0.2, iterations: int | None = None) -> PlanRequest:
    return PlanRequest(cycle=cycle, problem=behaviour, deadline_s=deadline, iterations=iterations)


def wait_for_reply(worker: PlannerWorker, timeout: float = 30.0):
    reply = worker.wait(timeout)
    assert reply is not None, "worker did not answer"
    return reply


def test_answers_requests_in_a_separate_process():
    with PlannerWorker(FACTORY) as w:
        assert w.submit(request(1, "echo"))
        reply = wait_for_reply(w)
        assert reply.cycle == 1 and reply.result.status == "exact"
        assert reply.result.pid == w.pid != os.getpid()
        assert w.stats.answered == 1 and w.stats.killed == 0


def test_a_busy_worker_refuses_a_second_request_and_counts_it():
    with PlannerWorker(FACTORY) as w:
        assert w.submit(request(1, "slow", deadline=0.3))
        assert not w.submit(request(2, "echo"))
        assert w.stats.busy_rejections == 1
        assert wait_for_reply(w).cycle == 1


def test_iteration_budget_is_passed_to_the_planner():
    with PlannerWorker(FACTORY) as w:
        w.submit(request(1, "slow", deadline=60.0, iterations=1234))
        reply = wait_for_reply(w)
        assert reply.result.iterations == 1234


def test_hanging_planner_is_killed_restarted_and_never_blocks_poll():
    with PlannerWorker(FACTORY, grace_s=0.1) as w:
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
        w.submit(request(8, "echo"))
        assert wait_for_reply(w).cycle == 8


def test_planner_exception_is_reported_not_fatal():
    with PlannerWorker(FACTORY) as w:
        w.submit(request(1, "raise"))
        reply = wait_for_reply(w)
        assert reply.result is None and "planner bug" in reply.error
        assert w.stats.errors == 1
        w.submit(request(2, "echo"))
        assert wait_for_reply(w).result.status == "exact"
