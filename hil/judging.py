"""Judging a run from the tap's records (no processes, no sockets): collisions, clearance and goal
against the chart (:class:`Judge`), the thrust energy, the navigation error of the vessel computer's
own estimate, and the simulator's counters as the run summary shows them. :class:`hil.hilrun.HilRun`
supervises the processes and hands their records here."""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from typing import TYPE_CHECKING, Any

import numpy as np
from scipy import ndimage

if TYPE_CHECKING:
    from simulator.config import VesselParams


class Judge:
    """Collisions, clearance and goal from the truth against the chart (map frame: x east, y north)."""

    def __init__(self, occ: np.ndarray, resolution: float, hull_radius: float, goal_ned: tuple[float, float],
                 goal_tolerance: float) -> None:
        self.occ, self.res = occ, resolution
        # Distance (m) from each cell centre to the nearest obstacle cell's boundary (approximately).
        self.edt = ndimage.distance_transform_edt(~occ) * resolution - 0.5 * resolution
        self.hull_radius = hull_radius
        self.goal, self.tol = goal_ned, goal_tolerance

    def clearance(self, north: float, east: float) -> float:
        r, c = int(north / self.res), int(east / self.res)
        if not (0 <= r < self.occ.shape[0] and 0 <= c < self.occ.shape[1]):
            return 0.0
        return float(self.edt[r, c])

    def at_goal(self, north: float, east: float) -> bool:
        return math.hypot(north - self.goal[0], east - self.goal[1]) <= self.tol


def thrust_energy(times: Sequence[int], speeds: np.ndarray, commands: Sequence[tuple[int, float, float]],
                  vessel: VesselParams) -> float:
    """Integral of (|T_port| + |T_stdb|) * speed dt (J), the commands held between truth samples.

    ``times``: the truth's sample times (us), ``speeds``: the speed over ground at each (m/s),
    ``commands``: (time_usec, port, stdb) with the controls normalised to [-1, 1]."""
    if len(times) < 2 or not commands:
        return 0.0
    cmds = sorted(commands)
    cmd_t = np.array([c[0] for c in cmds])

    def thrust(u: float) -> float:
        return u * vessel.T_max if u >= 0 else -u * vessel.T_min

    total = 0.0
    for i in range(len(times) - 1):
        j = int(np.searchsorted(cmd_t, times[i], side="right")) - 1
        if j < 0:
            continue
        _, p, s = cmds[j]
        total += (abs(thrust(p)) + abs(thrust(s))) * speeds[i] * (times[i + 1] - times[i]) * 1e-6
    return total


def nav_rmse(estimate: Mapping[tuple[int, int], tuple[float, float]],
             truth_raw: Mapping[tuple[int, int], tuple[float, float, int]], decided: int | None = None) -> float | None:
    """RMS horizontal error (m) of the vessel computer's position estimates against the truth at the
    same time stamp, up to the deciding truth sample (us; None: all); None without any pair."""
    errs = []
    for (seg, ms), (n, e) in estimate.items():
        truth = truth_raw.get((seg, ms * 1000))
        if truth is not None and (decided is None or truth[2] <= decided):
            errs.append((n - truth[0]) ** 2 + (e - truth[1]) ** 2)
    return math.sqrt(float(np.mean(errs))) if errs else None


def simulator_part(sim: dict, end_s: float, ap_busy_poll: dict | None = None) -> dict[str, Any]:
    """The simulator's counters for the run summary. Stale-command failsafes are those up to the
    run's judged end (s of simulated time); those after it, while the processes were being
    stopped, are counted apart (the simulator runs on in real time while the autopilot exits).
    ``busy_poll``: how each end's lockstep waits went (common.udp.BusyPoll; None where off)."""
    out = {k: sim.get(k) for k in ("steps", "commands_received", "malformed_dropped", "stale_command_events",
                                   "lockstep_resends", "jitter_ms", "stepping", "stalls", "battery")}
    out["busy_poll"] = {"simulator": sim.get("busy_poll"), "autopilot": ap_busy_poll}
    if "pipeline_skips" in sim:   # the pipelined lockstep (sim.lockstep_pipeline)
        out["pipeline_skips"] = sim["pipeline_skips"]
    times = sim.get("stale_command_times_s")
    if times is not None:
        after = sum(1 for t in times if t > end_s + 1e-9)
        out["stale_command_events"] = (sim.get("stale_command_events") or 0) - after
        out["stale_command_events_after_end"] = after
    return out
