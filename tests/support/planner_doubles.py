"""Planner test doubles that run inside the planner worker process (imported there by name)."""

from __future__ import annotations

import os
import time
from dataclasses import dataclass


@dataclass
class FakeResult:
    status: str
    pid: int
    iterations: int


class ScriptedPlanner:
    """Behaviour chosen by the request's problem: 'echo' answers at once, 'hang' never returns,
    'raise' raises, 'slow' runs its termination condition out (like a real anytime planner)."""

    def __call__(self, request):
        behaviour, termination = request.problem, request.termination()
        if behaviour == "hang":
            # A planner stuck in a loop that never looks at its termination condition.
            end = time.monotonic() + 3600.0
            while time.monotonic() < end:
                time.sleep(0.01)
        if behaviour == "raise":
            raise RuntimeError("planner bug")
        n = 0
        if behaviour == "slow":
            while not termination():
                n += 1
                termination.notify(n, False)  # as a real planner reports its progress
        return FakeResult("exact", os.getpid(), n)


def scripted_factory() -> ScriptedPlanner:
    return ScriptedPlanner()


def hanging_handler():
    """A local-planning handler that never answers (for the autopilot's worker)."""

    def handle(request):
        end = time.monotonic() + 3600.0
        while time.monotonic() < end:
            time.sleep(0.01)

    return handle


def slow_start_factory(startup_s: float) -> ScriptedPlanner:
    """A planner whose worker takes ``startup_s`` to build (as a fork's page faults and the
    planning context do inside User-Mode Linux)."""
    time.sleep(startup_s)
    return ScriptedPlanner()
