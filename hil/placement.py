"""Where a lockstep run's processes run: the vessel computer on a CPU of its own.

A pipelined lockstep (``sim.lockstep_pipeline``) has the simulator and the vessel computer work at
once, each polling its socket while it waits (``common.udp.BusyPoll``). Left to the scheduler, the
two land on one core now and then: a datagram that wakes one of them there preempts the other,
and the preempted end's answer waits for the woken one's whole turn (in a harbour run the vessel
computer's ``sendto`` of its command took 12 µs at the median and 72 µs on average, 1.15 ms at
p99; docs/performance.md). Placed, the vessel computer has one CPU to itself and the simulator,
``hil run``'s tap and the planner worker share another: the simulator has slack in a step
(~140 µs of work against the vessel computer's ~200 µs), the tap and the worker fill it.

``--cpus auto`` places a pipelined lockstep run when this process may use two CPUs or more;
``off`` never places; ``A,B`` puts the simulator, tap and worker on CPU A and the vessel computer
on CPU B. Campaigns that run several loops at once do not place them (each would pin its ends to
the same two CPUs). Where a run ends, ``hil run`` gets back the CPUs it had."""

from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path

from hil.errors import UsageError

CHOICES = "auto, off, or two CPU numbers A,B"


@dataclass(frozen=True)
class Placement:
    """CPU numbers (as ``os.sched_setaffinity`` counts them)."""
    simulator: int   # the simulator, hil run's tap and the planner worker
    computer: int    # the vessel computer alone


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


def choose(spec: str | Placement, lockstep: bool, pipelined: bool) -> Placement | None:
    """The placement of a run: an explicit one as given (lockstep only), ``auto`` for a pipelined
    lockstep run on two usable CPUs or more, otherwise none."""
    if isinstance(spec, Placement):
        return spec if lockstep else None
    cpus = usable()
    if spec == "auto" and lockstep and pipelined and len(cpus) >= 2:
        return Placement(cpus[0], cpus[1])
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


def pin(pid: int, cpu: int) -> bool:
    """Every thread of process ``pid`` on ``cpu``; False where the process is gone or refused."""
    ok = False
    for tid in threads(pid):
        try:
            os.sched_setaffinity(tid, {cpu})
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
    return done
