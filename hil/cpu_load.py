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

Inside User-Mode Linux (``hil vcan -- hil soak``) the guest's /proc shows only the guest: the host's
other processes, which slow the whole guest down, are invisible there (a busy host failed guest
soaks with "planner deadline overruns 6 > 0 allowed"). So ``hil vcan`` runs a :class:`HostLoadFeed`:
it writes the host's busy and steal ticks and the UML process tree's ticks to a file on the shared
file system every half second, named to the guest by ``HIL_HOST_LOAD``; a :class:`LoadWatch` in the
guest reads it at each sample and judges by the host's foreign load (everything on the host but the
guest: the guest's own load is the run itself), keeping the guest's own figures under ``guest``.
"""

from __future__ import annotations

import json
import os
import threading
import time
from dataclasses import dataclass
from pathlib import Path

TICK_S = 1.0 / os.sysconf("SC_CLK_TCK") if hasattr(os, "sysconf") else 0.01
HOST_LOAD_ENV = "HIL_HOST_LOAD"  # the host feed's file, for a watch inside User-Mode Linux


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


class HostLoadFeed:
    """On the host: write ``{"wall", "busy", "steal", "ours", "cpus"}`` (host monotonic seconds,
    cumulative ticks, ``ours`` those of ``root`` (the UML process) and its descendants) to ``path``
    every ``every_s`` seconds, replacing the file atomically, until :meth:`stop`."""

    def __init__(self, path: Path, root: int, every_s: float = 0.5) -> None:
        self.path, self.root, self.every_s = Path(path), root, every_s
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, name="host-load-feed", daemon=True)

    def write(self) -> bool:
        ticks = system_ticks()
        if ticks is None:
            return False
        record = {"wall": time.monotonic(), "busy": ticks[0], "steal": ticks[1], "ours": tree_ticks([self.root]),
                  "cpus": os.cpu_count() or 1}
        tmp = self.path.with_name(self.path.name + ".tmp")
        tmp.write_text(json.dumps(record))
        os.replace(tmp, self.path)
        return True

    def _run(self) -> None:
        while self.write() and not self._stop.wait(self.every_s):
            pass

    def start(self) -> HostLoadFeed:
        self._thread.start()
        return self

    def stop(self) -> None:
        self._stop.set()
        self._thread.join(timeout=5.0)


def read_host_load(path: str | Path) -> dict[str, float] | None:
    """The host feed's latest record, or None (no file yet, a partial or foreign file)."""
    try:
        record = json.loads(Path(path).read_text())
        return {k: float(record[k]) for k in ("wall", "busy", "steal", "ours", "cpus")}
    except (OSError, ValueError, KeyError, TypeError):
        return None


class LoadWatch:
    """Samples the machine's and our processes' CPU time (at most once per ``every_s``); :meth:`report`
    gives the load over the window between the first and the last sample. With a host feed
    (``host_load``, default the ``HIL_HOST_LOAD`` file: inside User-Mode Linux) the report is the
    host's load over the same window, the guest's own under ``guest``."""

    def __init__(self, every_s: float = 1.0, host_load: str | Path | None = None) -> None:
        self.every_s = every_s
        self.first: Sample | None = None
        self.last: Sample | None = None
        self.available = system_ticks() is not None
        feed = host_load if host_load is not None else os.environ.get(HOST_LOAD_ENV)
        self.host_load = Path(feed) if feed else None
        self.host_first: dict[str, float] | None = None
        self.host_last: dict[str, float] | None = None

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
        if self.host_load is not None:
            host = read_host_load(self.host_load)
            if host is not None:
                if self.host_first is None:
                    self.host_first = host
                self.host_last = host

    def report(self) -> dict | None:
        guest = self._own_report()
        host = self._host_report()
        if host is None:
            return guest
        return {**host, "source": "host", "guest": guest}

    def _host_report(self) -> dict[str, float] | None:
        a, b = self.host_first, self.host_last
        if a is None or b is None or b["wall"] <= a["wall"]:
            return None
        busy = (b["busy"] - a["busy"]) * TICK_S
        ours = max(0.0, b["ours"] - a["ours"]) * TICK_S   # the whole guest: the run and its kernel
        wall, cpus = b["wall"] - a["wall"], int(b["cpus"])
        foreign = max(0.0, busy - ours)
        return {"wall_s": round(wall, 2), "cpus": cpus, "busy_cpu_s": round(busy, 2), "ours_cpu_s": round(ours, 2),
                "foreign_cpu_s": round(foreign, 2), "steal_cpu_s": round((b["steal"] - a["steal"]) * TICK_S, 2),
                "foreign_fraction": round(foreign / (wall * cpus), 4)}

    def _own_report(self) -> dict[str, float] | None:
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
