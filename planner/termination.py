"""When to stop an anytime planner (in the spirit of OMPL's PlannerTerminationCondition).

A :class:`Termination` is a callable returning True when the planner must stop. The planner
tells it how far it has got (:meth:`Termination.notify`) so iteration counts and "stop at the
first exact solution" can be evaluated; deadlines read a clock. Planners also inspect the
conditions (:meth:`bounds`) so the compiled tree core can check the iteration budget, a
``time.monotonic`` deadline and a deadline on the calling thread's CPU clock
(``time.thread_time``, :meth:`Termination.thread_cpu_deadline`) itself, every iteration,
without returning to Python.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable
from dataclasses import dataclass


@dataclass(frozen=True)
class Bounds:
    """What a planner needs to honour a termination condition inside compiled code."""

    max_iterations: int | None      # stop after this many iterations (samples drawn)
    monotonic_deadline: float | None  # time.monotonic() value at which to stop
    poll_python: bool               # some condition needs a Python call after every iteration
    stop_on_exact: bool             # stop at the first exact solution
    thread_cpu_deadline: float | None = None  # time.thread_time() value (this thread's CPU, s) at which to stop


class Termination:
    """A stop condition. Build with :meth:`iterations`, :meth:`deadline`,
    :meth:`thread_cpu_deadline`, :meth:`exact_solution` and combine with :meth:`any_of`."""

    def __init__(self, check: Callable[[Termination], bool], *, max_iterations: int | None = None,
                 deadline: float | None = None, clock: Callable[[], float] | None = None,
                 stop_on_exact: bool = False, children: tuple[Termination, ...] = ()) -> None:
        self._check = check
        self.max_iterations = max_iterations
        self.deadline_at = deadline
        self.clock = clock
        self.stop_on_exact = stop_on_exact
        self.children = children
        self.iterations_done = 0
        self.solved = False

    def __call__(self) -> bool:
        return bool(self._check(self))

    def notify(self, iterations: int, solved: bool) -> None:
        """Called by the planner: iterations done so far in this solve, exact solution found?"""
        self.iterations_done = iterations
        self.solved = solved
        for c in self.children:
            c.notify(iterations, solved)

    def reset(self) -> None:
        self.notify(0, False)

    def bounds(self) -> Bounds:
        """The tightest iteration, monotonic-clock and thread-CPU bounds of this condition and its
        children; a deadline on any other (injected) clock is polled from Python."""
        leaves = self._leaves()
        iters = [t.max_iterations for t in leaves if t.max_iterations is not None]
        real = [t.deadline_at for t in leaves if t.deadline_at is not None and t.clock is time.monotonic]
        cpu = [t.deadline_at for t in leaves if t.deadline_at is not None and t.clock is time.thread_time]
        poll = any(
            (t.deadline_at is not None and t.clock not in (time.monotonic, time.thread_time)) or t._custom
            for t in leaves
        )
        return Bounds(
            max_iterations=min(iters) if iters else None,
            monotonic_deadline=min(real) if real else None,
            poll_python=poll,
            stop_on_exact=any(t.stop_on_exact for t in leaves),
            thread_cpu_deadline=min(cpu) if cpu else None,
        )

    def is_bounded(self) -> bool:
        """True when the condition is guaranteed to fire (an iteration count or a deadline)."""
        return any(t.max_iterations is not None or t.deadline_at is not None for t in self._leaves())

    _custom = False

    def _leaves(self) -> list[Termination]:
        if not self.children:
            return [self]
        out: list[Termination] = []
        for c in self.children:
            out.extend(c._leaves())
        return out

    @staticmethod
    def iterations(n: int) -> Termination:
        """Stop after ``n`` iterations (one iteration = one sample drawn)."""
        if n < 0:
            raise ValueError("iterations: must be >= 0")
        return Termination(lambda t: t.iterations_done >= n, max_iterations=int(n))

    @staticmethod
    def deadline(seconds: float, clock: Callable[[], float] = time.monotonic) -> Termination:
        """Stop once ``clock()`` has advanced ``seconds`` from now (seconds >= 0)."""
        if not (seconds >= 0) or math.isinf(seconds):
            raise ValueError("deadline: seconds must be finite and >= 0")
        at = clock() + seconds
        return Termination(lambda t: clock() >= at, deadline=at, clock=clock)

    @staticmethod
    def thread_cpu_deadline(seconds: float) -> Termination:
        """Stop once the calling thread has used ``seconds`` of CPU time from now (its
        CLOCK_THREAD_CPUTIME_ID, ``time.thread_time``): time the thread sleeps, waits or is
        preempted by other processes does not count, so the budget is the same on a loaded
        machine. Evaluate it on the thread that runs the search (the compiled core checks it
        before every iteration on its own thread)."""
        if not (seconds >= 0) or math.isinf(seconds):
            raise ValueError("thread_cpu_deadline: seconds must be finite and >= 0")
        at = time.thread_time() + seconds
        return Termination(lambda t: time.thread_time() >= at, deadline=at, clock=time.thread_time)

    @staticmethod
    def exact_solution() -> Termination:
        """Stop at the first exact solution. Unbounded on its own: combine it with an iteration
        count or a deadline (``solve`` refuses an unbounded condition)."""
        return Termination(lambda t: t.solved, stop_on_exact=True)

    @staticmethod
    def custom(fn: Callable[[], bool]) -> Termination:
        """Any Python predicate, polled after every iteration (unbounded on its own)."""
        t = Termination(lambda _t: fn())
        t._custom = True
        return t

    @staticmethod
    def any_of(*conds: Termination) -> Termination:
        """Stop as soon as any of ``conds`` says stop."""
        if not conds:
            raise ValueError("any_of: needs at least one condition")
        return Termination(lambda t: any(c() for c in t.children), children=tuple(conds))
