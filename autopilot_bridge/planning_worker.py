"""The local planner in a separate process, under a watchdog (section 2.2: "a watching dog timer
which stops the current local planning by an interruption style").

The control loop hands a :class:`PlanRequest` to :meth:`PlannerWorker.submit` and goes on; it
collects the answer later with :meth:`PlannerWorker.poll`, which never blocks. Each request
carries its own termination budget, so a healthy planner stops itself at the deadline with its
best-so-far (OMPL-style anytime planning). If the worker has not answered ``grace`` seconds after
the deadline, :meth:`PlannerWorker.watchdog` kills the process, starts a fresh one and counts the
event: a hung planner costs the control loop nothing but the plan it did not deliver.

A worker takes requests only once it has said it is ready (:class:`WorkerReady`, sent after its
handler is built). Its start-up (a fork's copy-on-write faults, building the planning context) is
not charged to a planning deadline: otherwise a start-up slower than deadline + grace, as inside
User-Mode Linux, makes every restarted worker overrun its first request and be restarted again.

Two budgets:

* ``deadline_s`` (real time): the planner's termination is a wall-clock deadline;
* ``iterations`` (lockstep): the planner's termination is an iteration count, so the same seed
  gives the same plan whatever the machine's speed, and a lockstep run is repeatable.
"""

from __future__ import annotations

import importlib
import multiprocessing as mp
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from multiprocessing.connection import Connection
from multiprocessing.process import BaseProcess
from typing import TYPE_CHECKING, Generic, TypeVar, cast

if TYPE_CHECKING:
    from multiprocessing.context import ForkContext, ForkServerContext, SpawnContext

    from planner.params import PlannerParams
    from planner.problem import PlanningProblem
    from planner.result import PlannerResult
    from planner.termination import Termination

P = TypeVar("P")   # the problem a request carries (the vessel computer's: local_planning.CycleInput)
R = TypeVar("R")   # what the handler answers with (the vessel computer's: local_planning.LocalPlan)


@dataclass(frozen=True)
class PlanRequest(Generic[P]):
    """One local planning cycle's problem and budget."""

    cycle: int
    problem: P                       # whatever the worker's handler takes (picklable)
    deadline_s: float                # wall-clock budget of the planner itself
    iterations: int | None = None    # if set, an iteration budget replaces the deadline (lockstep)

    def termination(self) -> Termination:
        """The planner's termination condition for this budget."""
        from planner.termination import Termination

        if self.iterations is not None:
            return Termination.iterations(self.iterations)
        return Termination.deadline(self.deadline_s)


@dataclass(frozen=True)
class PlanReply(Generic[R]):
    cycle: int
    result: R | None                 # what the handler returned, or None if it raised
    error: str = ""
    compute_time_s: float = 0.0


@dataclass(frozen=True)
class WorkerReady:
    """The worker's first message: its handler is built (start-up time in s, worker clock)."""

    pid: int
    startup_s: float


@dataclass
class WorkerStats:
    submitted: int = 0
    answered: int = 0
    overruns: int = 0                # answers that came after deadline (but before the kill)
    killed: int = 0                  # watchdog kills (the worker hung past deadline + grace)
    restarts: int = 0
    errors: int = 0                  # the handler raised
    busy_rejections: int = 0         # submit() while a request was still running
    not_ready_rejections: int = 0    # submit() while a (re)started worker was still starting up
    startup_s: list[float] = field(default_factory=list)   # each worker's start-up (s)
    events: list[str] = field(default_factory=list)


def planning_problem_handler(algorithm: str, params: PlannerParams
                             ) -> Callable[[PlanRequest[PlanningProblem]], PlannerResult]:
    """Handler that solves a ``planner.problem.PlanningProblem`` with one planner, under the budget."""
    from planner import make_planner

    planner = make_planner(algorithm, params)
    return lambda request: planner.solve(request.problem, request.termination())


def _resolve(factory_path: str) -> Callable[..., Callable[[PlanRequest[object]], object]]:
    """The handler factory named ``module:function``: called with the factory's arguments, it returns
    the handler of one :class:`PlanRequest` (a plan, or a test double's reply)."""
    module, _, name = factory_path.partition(":")
    return getattr(importlib.import_module(module), name)


def _owned_by_parent() -> None:
    """The worker's life belongs to its parent: a SIGTERM/SIGINT to the process group (the way
    runs are stopped) must not kill it under a parent that is still serving frames; it ends on
    the pipe's EOF or the parent's SIGKILL, and (Linux) with its parent."""
    import signal

    for sig in (signal.SIGINT, signal.SIGTERM):
        signal.signal(sig, signal.SIG_IGN)
    try:
        import ctypes

        ctypes.CDLL("libc.so.6", use_errno=True).prctl(1, signal.SIGKILL)  # 1 = PR_SET_PDEATHSIG
    except (OSError, AttributeError):
        pass


def _worker_main(conn: Connection, factory_path: str, factory_args: tuple) -> None:
    import os

    _owned_by_parent()
    t0 = time.perf_counter()
    handler = _resolve(factory_path)(*factory_args)
    try:
        conn.send(WorkerReady(os.getpid(), time.perf_counter() - t0))
    except (BrokenPipeError, OSError):
        return
    while True:
        try:
            request = conn.recv()
        except (EOFError, OSError, KeyboardInterrupt):
            return
        if request is None:
            return
        t0 = time.perf_counter()
        try:
            reply = PlanReply(request.cycle, handler(request), compute_time_s=time.perf_counter() - t0)
        except Exception as exc:  # a planner bug must not take the worker down silently
            reply = PlanReply(request.cycle, None, error=f"{type(exc).__name__}: {exc}",
                              compute_time_s=time.perf_counter() - t0)
        try:
            conn.send(reply)
        except (BrokenPipeError, OSError):
            return


class PlannerWorker(Generic[P, R]):
    """A planner process with a non-blocking request/answer interface and a watchdog.

    ``factory`` is ``"module:function"``, called once in the worker process (and again after a
    restart) with ``factory_args`` (pickled once); it returns the handler, a callable that takes a
    :class:`PlanRequest` and returns the plan. Tests put a hanging double behind it.
    """

    def __init__(self, factory: str, factory_args: tuple = (), grace_s: float = 0.5,
                 start_method: str = "spawn", startup_timeout_s: float = 60.0, *, start: bool = True) -> None:
        """``start``: start the process now (False: at :meth:`start`, e.g. once the parent has warmed
        up what a forked worker inherits)."""
        self.factory = factory
        self.factory_args = factory_args
        self.grace_s = grace_s
        self.startup_timeout_s = startup_timeout_s
        # typeshed's BaseContext has no Process (each concrete context has its own)
        self.ctx = cast("SpawnContext | ForkContext | ForkServerContext", mp.get_context(start_method))
        self.stats = WorkerStats()
        self._proc: BaseProcess | None = None
        self._conn: Connection | None = None
        self._pending: PlanRequest[P] | None = None
        self._pending_since = 0.0
        self._ready = False
        self._started_at = 0.0
        if start:
            self._start()

    def start(self) -> None:
        """Start the process of a worker made with ``start=False`` (nothing if it runs)."""
        if self._proc is None:
            self._start()

    # -- process management ---------------------------------------------------------------
    def _start(self) -> None:
        parent, child = self.ctx.Pipe(duplex=True)
        self._proc = self.ctx.Process(target=_worker_main, args=(child, self.factory, self.factory_args),
                                      name="planner-worker", daemon=True)
        self._proc.start()
        child.close()
        self._conn = parent
        self._ready = False
        self._started_at = time.monotonic()

    def _kill(self) -> None:
        if self._conn is not None:
            self._conn.close()
            self._conn = None
        if self._proc is not None:
            self._proc.kill()
            self._proc.join(timeout=5.0)
            self._proc = None

    def close(self) -> None:
        """Stop the worker (politely, then by force)."""
        if self._proc is None:
            return
        try:
            if self._conn is not None and self._pending is None:
                self._conn.send(None)
                self._proc.join(timeout=2.0)
        except (BrokenPipeError, OSError):
            pass
        if self._proc is not None and self._proc.is_alive():
            self._proc.kill()
        self._kill()

    def __enter__(self) -> PlannerWorker:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    @property
    def pid(self) -> int | None:
        return self._proc.pid if self._proc is not None else None

    @property
    def busy(self) -> bool:
        return self._pending is not None

    @property
    def ready(self) -> bool:
        """The worker has started and takes requests (never blocks)."""
        return self.wait_ready(0.0)

    def wait_ready(self, timeout: float) -> bool:
        """Block up to ``timeout`` s for the worker's :class:`WorkerReady`; True once it came."""
        if self._ready:
            return True
        if self._conn is None:
            return False
        try:
            if not self._conn.poll(timeout):
                return False
            msg = self._conn.recv()
        except (EOFError, OSError):
            self._restart("worker died while starting")
            return False
        if not isinstance(msg, WorkerReady):
            self._restart(f"worker sent {type(msg).__name__} before it was ready")
            return False
        self._ready = True
        self.stats.startup_s.append(msg.startup_s)
        return True

    # -- requests -----------------------------------------------------------------------------
    def submit(self, request: PlanRequest[P], now: float | None = None) -> bool:
        """Start planning ``request``; False (and counted) if the previous one is still running or
        the worker is still starting up. The deadline runs from here."""
        if self._pending is not None:
            self.stats.busy_rejections += 1
            return False
        if not self.ready:
            self.stats.not_ready_rejections += 1
            return False
        assert self._conn is not None
        try:
            self._conn.send(request)
        except (BrokenPipeError, OSError):
            self._restart(f"cycle {request.cycle}: worker died")
            return False
        self._pending = request
        self._pending_since = time.monotonic() if now is None else now
        self.stats.submitted += 1
        return True

    def poll(self, now: float | None = None) -> PlanReply[R] | None:
        """The answer to the pending request if it has arrived; never blocks."""
        if self._pending is None or self._conn is None:
            return None
        try:
            if not self._conn.poll(0):
                return None
            reply: PlanReply[R] = self._conn.recv()
        except (EOFError, OSError):
            self._restart("worker died")
            return None
        now = time.monotonic() if now is None else now
        if now - self._pending_since > self._pending.deadline_s and self._pending.iterations is None:
            self.stats.overruns += 1
            self.stats.events.append(f"cycle {reply.cycle}: planner answered after its deadline")
        if reply.error:
            self.stats.errors += 1
            self.stats.events.append(f"cycle {reply.cycle}: planner error {reply.error}")
        self.stats.answered += 1
        self._pending = None
        return reply

    def wait(self, timeout: float) -> PlanReply[R] | None:
        """Block up to ``timeout`` s for the pending answer (lockstep only: simulated time stands still)."""
        if self._pending is None or self._conn is None:
            return None
        try:
            self._conn.poll(timeout)
        except (EOFError, OSError):
            pass
        return self.poll()

    def cancel(self, why: str) -> bool:
        """Abandon the pending request (a planner cannot be interrupted mid-solve: the worker is
        restarted). True if there was one."""
        if self._pending is None:
            return False
        self._restart(f"cycle {self._pending.cycle}: cancelled ({why})")
        return True

    def watchdog(self, now: float | None = None) -> bool:
        """Kill and restart a worker that is ``grace_s`` past its request's deadline, or that has
        not started within ``startup_timeout_s``. True if it did."""
        if self._pending is None:
            if self._ready or self.ready:
                return False
            now = time.monotonic() if now is None else now
            if now - self._started_at <= self.startup_timeout_s:
                return False
            self.stats.killed += 1
            self._restart(f"planner worker not started after {now - self._started_at:.1f} s, killed")
            return True
        now = time.monotonic() if now is None else now
        limit = self._pending.deadline_s + self.grace_s
        if now - self._pending_since <= limit:
            return False
        self.stats.killed += 1
        self._restart(f"cycle {self._pending.cycle}: planner hung {now - self._pending_since:.2f} s, killed")
        return True

    def _restart(self, why: str) -> None:
        self.stats.events.append(why)
        self._pending = None
        self._kill()
        self._start()
        self.stats.restarts += 1
