"""The CPU load a run saw from outside itself, measured from /proc (Linux).

A soak judges planner deadline overruns against this: an overrun on a machine whose CPUs other
processes (or the hypervisor: *steal*) were using says nothing about our code. Over the watched
window:

* ``busy_cpu_s``: CPU-seconds all CPUs spent not idle (/proc/stat: user, nice, system, irq,
  softirq, steal), summed over CPUs;
* ``ours_cpu_s``: CPU-seconds of the watched processes and their descendants (/proc/PID/stat
  utime + stime, plus cutime + cstime of children they reaped, e.g. a restarted planner worker);
* ``foreign_cpu_s`` = busy - ours: what everything else took, steal included (``steal_cpu_s``).

The CPU time of a process that exited and was not reaped by a watched one between two samples is
missed, so it counts as foreign: the error goes towards excusing, never towards a false failure.
"""

from __future__ import annotations

import os
import time
from dataclasses import dataclass

TICK_S = 1.0 / os.sysconf("SC_CLK_TCK") if hasattr(os, "sysconf") else 0.01


def system_ticks() -> tuple[int, int] | None:
    """(busy ticks, steal ticks) summed over all CPUs since boot, or None without /proc/stat."""
    try:
        with open("/proc/stat") as fh:
            fields = fh.readline().split()
    except OSError:
        return None
    if not fields or fields[0] != "cpu":
        return None
    v = [int(x) for x in fields[1:]] + [0] * 10
    user, nice, system, _idle, _iowait, irq, softirq, steal = v[:8]
    return user + nice + system + irq + softirq + steal, steal


def _stat(pid: int) -> tuple[int, int] | None:
    """(parent pid, CPU ticks including reaped children) of one process, or None if it is gone."""
    try:
        with open(f"/proc/{pid}/stat") as fh:
            text = fh.read()
    except OSError:
        return None
    rest = text[text.rfind(")") + 2:].split()  # the command name may hold spaces and parentheses
    # rest[0] is field 3 (state): ppid is field 4, utime..cstime fields 14-17.
    return int(rest[1]), sum(int(x) for x in rest[11:15])


def tree_ticks(roots: list[int]) -> int:
    """CPU ticks of ``roots`` and all their living descendants."""
    stats = {}
    for name in os.listdir("/proc"):
        if name.isdigit():
            s = _stat(int(name))
            if s is not None:
                stats[int(name)] = s
    children: dict[int, list[int]] = {}
    for pid, (ppid, _) in stats.items():
        children.setdefault(ppid, []).append(pid)
    total, todo, seen = 0, [p for p in roots if p in stats], set()
    while todo:
        pid = todo.pop()
        if pid in seen:
            continue
        seen.add(pid)
        total += stats[pid][1]
        todo += children.get(pid, [])
    return total


@dataclass(frozen=True)
class Sample:
    wall: float   # s, monotonic
    busy: int     # ticks, all CPUs
    steal: int    # ticks, all CPUs
    ours: int     # ticks, the watched process trees


class LoadWatch:
    """Samples the machine's and our processes' CPU time (at most once per ``every_s``); :meth:`report`
    gives the load over the window between the first and the last sample."""

    def __init__(self, every_s: float = 1.0) -> None:
        self.every_s = every_s
        self.first: Sample | None = None
        self.last: Sample | None = None
        self.available = system_ticks() is not None

    def sample(self, roots: list[int], force: bool = False) -> None:
        now = time.monotonic()
        if not self.available or (not force and self.last is not None and now - self.last.wall < self.every_s):
            return
        sys_ticks = system_ticks()
        if sys_ticks is None:
            return
        s = Sample(now, sys_ticks[0], sys_ticks[1], tree_ticks(roots))
        if self.first is None:
            self.first = s
        self.last = s

    def report(self) -> dict[str, float] | None:
        if self.first is None or self.last is None or self.last.wall <= self.first.wall:
            return None
        a, b = self.first, self.last
        busy = (b.busy - a.busy) * TICK_S
        ours = max(0, b.ours - a.ours) * TICK_S
        wall = b.wall - a.wall
        cpus = os.cpu_count() or 1
        foreign = max(0.0, busy - ours)
        return {"wall_s": round(wall, 2), "cpus": cpus, "busy_cpu_s": round(busy, 2), "ours_cpu_s": round(ours, 2),
                "foreign_cpu_s": round(foreign, 2), "steal_cpu_s": round((b.steal - a.steal) * TICK_S, 2),
                "foreign_fraction": round(foreign / (wall * cpus), 4)}


# The rule of `hil soak` (its --help and docs/can.md say the same).
QUIET_FLOOR = 0.05  # of one CPU: what a quiet machine's daemons take; load below it excuses nothing


def overruns_allowed(max_overruns: int, load: dict[str, float] | None, load_per_overrun_s: float) -> int:
    """Planner deadline overruns a soak tolerates: ``max_overruns`` on a quiet machine, plus one per
    ``load_per_overrun_s`` CPU-seconds that other processes and steal took beyond the quiet floor
    (QUIET_FLOOR of one CPU over the window). Without /proc, only ``max_overruns``."""
    if load is None:
        return max_overruns
    excess = max(0.0, load["foreign_cpu_s"] - QUIET_FLOOR * load["wall_s"])
    return max_overruns + int(excess // load_per_overrun_s)
