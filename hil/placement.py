"""Where a lockstep run's processes run: each end of the loop on a CPU of its own.

In lockstep the simulator and the vessel computer wait for each other, each polling its socket
(``common.udp.BusyPoll``). Left to the scheduler, the two land on one core now and then: the
datagram that wakes one of them there preempts the other, and the preempted end's answer waits for
the woken one's turn. The vessel computer's ``sendto`` of its command, harbour, 150 s: p50 9.9 µs,
p99 1.14 ms, mean 57 µs left to the scheduler; placed, 6.1 µs, 53 µs and 10 µs
(docs/performance.md, "Placing the loop's processes").

A placement puts the simulator and ``hil run``'s tap (which reads the simulator's stream) on CPU
A, the vessel computer and its planner worker on CPU B. ``--cpus auto`` (the default) places a
lockstep run on the first pair of usable CPUs (1st and 2nd, 3rd and 4th, ...) that no other run on
this host holds: a ``flock`` per CPU, held for the run and dropped by the kernel if ``hil run``
dies. With every pair held, or one usable CPU, the run is left to the scheduler; ``off`` leaves
it there always; ``A,B`` places it on A and B whatever else runs. Real time is never placed.
Campaigns, which run several loops at once, do not place their runs. Where a run ends, ``hil run``
gets back the CPUs it had. What a run computes does not depend on where it runs (tested)."""

from __future__ import annotations

import fcntl
import os
import tempfile
from dataclasses import dataclass
from pathlib import Path
from typing import IO

from hil.errors import UsageError

CHOICES = "auto, off, or two CPU numbers A,B"


@dataclass(frozen=True)
class Placement:
    """CPU numbers (as ``os.sched_setaffinity`` counts them)."""
    simulator: int   # the simulator and hil run's tap
    computer: int    # the vessel computer and its planner worker (at WORKER_NICE)


def usable() -> list[int]:
    """The CPUs this process may run on, in order (none known: an empty list)."""
    try:
        return sorted(os.sched_getaffinity(0))
    except AttributeError:   # not Linux: nothing to place
        return []


def parse(spec: str) -> str | Placement:
    """``auto``, ``off`` or a Placement from ``A,B``; a bad spec is a UsageError of one line."""
    spec = spec.strip().lower()
    if spec in ("auto", "off"):
        return spec
    parts = spec.split(",")
    try:
        a, b = (int(x) for x in parts)
    except ValueError:
        raise UsageError(f"--cpus {spec!r}: expected {CHOICES}") from None
    cpus = usable()
    if a == b or a not in cpus or b not in cpus:
        raise UsageError(f"--cpus {spec}: two different CPUs this process may use ({cpus or 'none known'})")
    return Placement(a, b)


def _lock_dir() -> Path:
    return Path(tempfile.gettempdir())


class Claim:
    """A placement and the host-wide locks on its CPUs, held until :meth:`release` (or until the
    process ends: the kernel drops ``flock`` locks with their files)."""

    def __init__(self, placement: Placement, handles: list[IO[str]]) -> None:
        self.placement, self._handles = placement, handles

    def release(self) -> None:
        for fh in self._handles:
            fh.close()
        self._handles = []


def _lock(cpus: tuple[int, ...]) -> list[IO[str]] | None:
    """Exclusive locks on these CPUs' lock files, or None (and nothing held) where another run
    holds one of them."""
    handles: list[IO[str]] = []
    for cpu in cpus:
        try:
            fh = open(_lock_dir() / f"usv-hil-cpu-{os.getuid()}-{cpu}.lock", "a")
        except OSError:
            break
        try:
            fcntl.flock(fh, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except OSError:
            fh.close()
            break
        handles.append(fh)
    else:
        return handles
    for held in handles:
        held.close()
    return None


def claim(spec: str | Placement, lockstep: bool) -> Claim | None:
    """The placement of a lockstep run: an explicit one as given (its CPUs locked where free);
    ``auto``: the first pair of usable CPUs (1st and 2nd, 3rd and 4th, ...) that no other run on this
    host holds, none where every pair is held or fewer than two CPUs are usable; ``off``: none.
    Real time is never placed."""
    if isinstance(spec, str) and spec not in ("auto", "off"):
        spec = parse(spec)   # "A,B" given as text (a RunOptions built in code)
    if not lockstep or spec == "off":
        return None
    if isinstance(spec, Placement):
        return Claim(spec, _lock((spec.simulator, spec.computer)) or [])
    cpus = usable()
    for a, b in zip(cpus[0::2], cpus[1::2], strict=False):
        handles = _lock((a, b))
        if handles is not None:
            return Claim(Placement(a, b), handles)
    return None


def threads(pid: int) -> list[int]:
    try:
        return [int(t) for t in os.listdir(f"/proc/{pid}/task")]
    except OSError:
        return [pid]


def children(pid: int) -> list[int]:
    """The processes whose parent is ``pid`` (Linux /proc)."""
    out = []
    for d in Path("/proc").iterdir():
        if d.name.isdigit():
            try:
                if int((d / "stat").read_text().rsplit(")", 1)[1].split()[1]) == pid:
                    out.append(int(d.name))
            except (OSError, IndexError, ValueError):
                pass
    return out


def pin(pid: int, cpus: int | set[int]) -> bool:
    """Every thread of process ``pid`` on ``cpus`` (one CPU or a set); False where the process is
    gone or refused."""
    mask = {cpus} if isinstance(cpus, int) else cpus
    ok = False
    for tid in threads(pid):
        try:
            os.sched_setaffinity(tid, mask)
            ok = True
        except OSError:
            pass
    return ok


def apply(placement: Placement, simulator: int, computer: int, tap: bool = True) -> dict[str, int]:
    """Pin the simulator (and, with ``tap``, this process) on ``placement.simulator``, the computer
    and its children (its planner worker) on ``placement.computer``. Returns the CPU of each role
    that was pinned."""
    done: dict[str, int] = {}
    if pin(simulator, placement.simulator):
        done["simulator"] = placement.simulator
    if tap and pin(os.getpid(), placement.simulator):
        done["tap"] = placement.simulator
    if pin(computer, placement.computer):
        done["computer"] = placement.computer
    for child in children(computer):
        if pin(child, placement.computer):
            done["planner_worker"] = placement.computer
            lower_priority(child)
    return done


# How much lower the planner worker's priority is in a placed run. Its CPU is the vessel
# computer's, which sleeps while a request is out (it holds its polls) and so leaves it the CPU
# between frames; a worker of equal weight also took slices the loop waited for (4.3 ms a planning
# cycle at f5a0bc9), one of lower weight takes fewer. Not SCHED_IDLE nor nice 19: with another
# process busy on that CPU (no autogroup), those starved the worker at the planning deadline, and
# 3,000 steps took 73 s and 16 s against 1.8 s; 5 levels lower, 1.9 s (docs/performance.md). An
# unprivileged process cannot raise a priority back, so it is chosen once.
WORKER_NICE = 5   # added to the nice value the worker started with


def lower_priority(pid: int, by: int = WORKER_NICE) -> bool:
    """Every thread of ``pid`` (the planner worker) ``by`` nice levels lower (19 at most); False
    where refused or gone."""
    ok = False
    for tid in threads(pid):
        try:
            os.setpriority(os.PRIO_PROCESS, tid, min(19, os.getpriority(os.PRIO_PROCESS, tid) + by))
            ok = True
        except OSError:
            pass
    return ok
