"""Where a campaign's runs execute: local processes (the default), local threads, or a Dask cluster.

Every executor has one job: call ``fn(item)`` for each item, somewhere, and yield
``(index, result)`` as results arrive (completion order, each index exactly once). A campaign's
results depend only on its items, never on the executor, the number of workers or the order the
work finishes in; the caller sorts what it keeps.

* :class:`LocalProcesses` (default): ``jobs`` spawned processes on this machine (``jobs == 1``
  runs in-process), no extra dependency.
* :class:`LocalThreads`: for work that is itself made of subprocesses (whole HIL runs).
* :class:`DaskExecutor`: ``dask.distributed``; an existing cluster (``scheduler="tcp://HOST:8786"``)
  or, without an address, a ``LocalCluster`` of ``jobs`` worker processes with one thread each.
  Dask is optional (``pip install 'usv-hil[cluster]'``) and imported only here, only when used.
  When a worker dies, the scheduler runs its unfinished tasks again elsewhere: the client still
  receives exactly one result per task (no run lost, none duplicated).

``warm_up`` (a picklable, argument-free function) runs once in each worker process before its
first item, outside any item's timing (numba compilation or cache loading of the planners).
"""

from __future__ import annotations

import os
import signal
import threading
import uuid
from collections.abc import Callable, Iterator, Sequence
from concurrent.futures import FIRST_COMPLETED, ThreadPoolExecutor, wait
from dataclasses import dataclass
from types import FrameType, ModuleType, TracebackType
from typing import TYPE_CHECKING, Generic, NoReturn, TypeVar

from hil.errors import UsageError

if TYPE_CHECKING:
    import multiprocessing.pool


def default_jobs() -> int:
    """The CPUs this process may run on (at least 1): the default number of workers."""
    return max(1, len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else (os.cpu_count() or 1))

EXECUTORS = ("local", "dask")
DASK_HINT = "pip install 'usv-hil[cluster]' (or: pip install 'dask[distributed]')"

_WARMED: set[str] = set()   # per worker process: the warm-up functions already run here


def _warm_once(warm_up: Callable[[], None] | None) -> None:
    if warm_up is None:
        return
    name = f"{warm_up.__module__}.{warm_up.__qualname__}"
    if name not in _WARMED:
        warm_up()
        _WARMED.add(name)


def _pool_init(warm_up: Callable[[], None] | None) -> None:
    """Local worker processes ignore Ctrl-C (the parent decides and keeps the finished runs)."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    _warm_once(warm_up)


T = TypeVar("T")   # what one unit of work takes (a campaign's Task, say)
R = TypeVar("R")   # what it gives back (its result row)


@dataclass(frozen=True)
class _Call(Generic[T, R]):
    """``fn`` applied to an ``(index, item)`` pair, after the worker's one warm-up (picklable)."""

    fn: Callable[[T], R]
    warm_up: Callable[[], None] | None = None

    def __call__(self, pair: tuple[int, T]) -> tuple[int, R]:
        _warm_once(self.warm_up)
        i, item = pair
        return i, self.fn(item)


class Executor:
    """Base: a context manager with :meth:`map_unordered`; ``workers`` for the progress line."""

    workers: int = 1
    description: str = ""

    def map_unordered(self, fn: Callable[[T], R], items: Sequence[T],
                      warm_up: Callable[[], None] | None = None) -> Iterator[tuple[int, R]]:
        raise NotImplementedError

    def cancel(self) -> None:
        """Drop the work not yet finished (Ctrl-C); what was yielded stays valid."""

    def close(self) -> None:
        """Release the workers."""

    def __enter__(self) -> Executor:
        return self

    def __exit__(self, exc_type: type[BaseException] | None, exc: BaseException | None,
                 tb: TracebackType | None) -> None:
        if exc_type is not None:
            self.cancel()
        self.close()


def collect(executor: Executor, fn: Callable[[T], R], items: Sequence[T],
            take: Callable[[int, R], None]) -> bool:
    """Run ``fn`` over ``items`` on ``executor``, handing each ``(index, result)`` to ``take`` as it
    finishes. Ctrl-C (or SIGTERM, in the main thread) cancels the rest: returns True when interrupted,
    what ``take`` got so far being the finished work."""
    def on_term(signum: int, frame: FrameType | None) -> NoReturn:
        raise KeyboardInterrupt

    main = threading.current_thread() is threading.main_thread()
    previous = signal.signal(signal.SIGTERM, on_term) if main else None
    try:
        for i, result in executor.map_unordered(fn, items):
            take(i, result)
        return False
    except KeyboardInterrupt:
        executor.cancel()
        return True
    finally:
        if main:
            signal.signal(signal.SIGTERM, previous)


class LocalProcesses(Executor):
    """``jobs`` spawned worker processes (``jobs <= 1``: in this process)."""

    def __init__(self, jobs: int) -> None:
        self.workers = max(1, int(jobs))
        self.description = f"{self.workers} local process(es)" if self.workers > 1 else "this process"
        self._pool: multiprocessing.pool.Pool | None = None

    def map_unordered(self, fn: Callable[[T], R], items: Sequence[T],
                      warm_up: Callable[[], None] | None = None) -> Iterator[tuple[int, R]]:
        call = _Call(fn, warm_up)
        if self.workers <= 1:
            for pair in enumerate(items):
                yield call(pair)
            return
        import multiprocessing as mp
        self._pool = pool = mp.get_context("spawn").Pool(min(self.workers, max(1, len(items))),
                                                         initializer=_pool_init, initargs=(warm_up,))
        yield from pool.imap_unordered(call, list(enumerate(items)), chunksize=1)
        pool.close()

    def cancel(self) -> None:
        if self._pool is not None:
            self._pool.terminate()

    def close(self) -> None:
        if self._pool is not None:
            self._pool.join()
            self._pool = None


class LocalThreads(Executor):
    """``jobs`` threads of this process (for items that run their own subprocesses)."""

    def __init__(self, jobs: int) -> None:
        self.workers = max(1, int(jobs))
        self.description = f"{self.workers} local thread(s)"
        self._pool: ThreadPoolExecutor | None = None
        self._pending: set = set()

    def map_unordered(self, fn: Callable[[T], R], items: Sequence[T],
                      warm_up: Callable[[], None] | None = None) -> Iterator[tuple[int, R]]:
        _warm_once(warm_up)
        call = _Call(fn)
        self._pool = ThreadPoolExecutor(max_workers=self.workers)
        self._pending = {self._pool.submit(call, pair) for pair in enumerate(items)}
        while self._pending:
            done, self._pending = wait(self._pending, return_when=FIRST_COMPLETED)
            for f in done:
                yield f.result()

    def cancel(self) -> None:
        for f in self._pending:
            f.cancel()

    def close(self) -> None:
        if self._pool is not None:
            self._pool.shutdown(wait=True, cancel_futures=True)
            self._pool = None


def import_distributed() -> ModuleType:
    """``distributed``, or a one-line UsageError with the install hint."""
    try:
        import distributed
    except ImportError:
        raise UsageError(f"the Dask executor needs dask.distributed, which is not installed: {DASK_HINT}") from None
    return distributed


class DaskExecutor(Executor):
    """A Dask cluster: ``scheduler`` (e.g. ``tcp://10.0.0.5:8786``) or a LocalCluster of ``jobs``
    single-threaded worker processes on 127.0.0.1."""

    def __init__(self, jobs: int = 1, scheduler: str | None = None, connect_timeout_s: float = 30.0) -> None:
        distributed = import_distributed()
        import logging
        self.cluster = None
        try:
            if scheduler:
                self.client = distributed.Client(scheduler, timeout=f"{connect_timeout_s}s")
            else:
                # A terminal's Ctrl-C reaches the whole process group: the worker processes (and the
                # replacements their nannies start) inherit SIGINT ignored, so only this process
                # decides (cancel, keep the finished runs) and no worker dies mid-run with a traceback.
                main = threading.current_thread() is threading.main_thread()
                previous = signal.signal(signal.SIGINT, signal.SIG_IGN) if main else None
                try:
                    self.cluster = distributed.LocalCluster(
                        n_workers=max(1, int(jobs)), threads_per_worker=1, processes=True, host="127.0.0.1",
                        dashboard_address="127.0.0.1:0", silence_logs=logging.ERROR)
                finally:
                    if main:
                        signal.signal(signal.SIGINT, previous)
                self.client = distributed.Client(self.cluster)
        except (OSError, TimeoutError, ValueError) as exc:
            if self.cluster is not None:
                self.cluster.close()
            where = f"the Dask scheduler at {scheduler}" if scheduler else "a local Dask cluster"
            raise UsageError(f"cannot connect to {where}: {exc}") from None
        self.workers = max(1, len(self.client.scheduler_info().get("workers", {})))
        self.description = (f"Dask cluster {scheduler} ({self.workers} worker(s) now)" if scheduler
                            else f"Dask LocalCluster of {self.workers} worker process(es)")
        self._futures: list = []

    @property
    def address(self) -> str:
        return self.client.scheduler.address

    def map_unordered(self, fn: Callable[[T], R], items: Sequence[T],
                      warm_up: Callable[[], None] | None = None) -> Iterator[tuple[int, R]]:
        distributed = import_distributed()
        call = _Call(fn, warm_up)
        campaign = uuid.uuid4().hex[:12]   # keys unique per campaign: a shared cluster caches by key
        self._futures = [self.client.submit(call, pair, key=f"usv-hil-{campaign}-{pair[0]}", pure=False)
                         for pair in enumerate(items)]
        for _fut, result in distributed.as_completed(self._futures, with_results=True):
            yield result
        self._futures = []

    def cancel(self) -> None:
        pending = [f for f in self._futures if not f.done()]
        if pending:
            self.client.cancel(pending)
        self._futures = []

    def close(self) -> None:
        try:
            self.client.close()
        finally:
            if self.cluster is not None:
                self.cluster.close()


def make(executor: str = "local", jobs: int = 1, scheduler: str | None = None, threads: bool = False) -> Executor:
    """The executor a command line asks for (``--executor``, ``--jobs``, ``--scheduler``).

    ``threads``: the local executor runs threads instead of processes (work made of subprocesses).
    """
    if scheduler:
        executor = "dask"
    if executor not in EXECUTORS:
        raise UsageError(f"unknown executor {executor!r}; choose from {', '.join(EXECUTORS)}")
    if executor == "dask":
        return DaskExecutor(jobs, scheduler)
    return LocalThreads(jobs) if threads else LocalProcesses(jobs)


def worker_pids(ex: DaskExecutor) -> dict[str, int]:
    """Worker address -> OS process id (tests, diagnostics)."""
    return {addr: int(pid) for addr, pid in ex.client.run(os.getpid).items()}
