"""Judging a run from the tap's records (no processes, no sockets): collisions, clearance and goal
against the chart (:class:`Judge`), the thrust energy, the navigation error of the vessel computer's
own estimate, and the simulator's counters as the run summary shows them. :class:`hil.hilrun.HilRun`
supervises the processes and hands their records here."""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Protocol

import numpy as np
from scipy import ndimage

from hil.run_summary import (
    BusyPollEnds,
    HilSimulatorSection,
    RunCan,
    RunCurrent,
    RunSecurity,
    RunSummary,
    RunTraffic,
    ShipCollision,
    SimulatorSecurity,
    TapCounters,
    read_autopilot_summary,
    read_simulator_summary,
)

if TYPE_CHECKING:
    from common.udp import BusyPollSummary
    from hil.can_log import CanLogSummary
    from hil.encounter_report import EncounterJudge
    from hil.settings import HilConfig
    from simulator.config import VesselParams
    from simulator.server import SimulatorSummary


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


def simulator_part(sim: SimulatorSummary, end_s: float, ap_busy_poll: BusyPollSummary | None = None,
                   cpus: dict[str, int] | None = None) -> HilSimulatorSection:
    """The simulator's counters for the run summary. Stale-command failsafes are those up to the
    run's judged end (s of simulated time); those after it, while the processes were being
    stopped, are counted apart (the simulator runs on in real time while the autopilot exits).
    ``busy_poll``: how each end's lockstep waits went (common.udp.BusyPoll; None where off);
    ``cpus``: where each end was pinned (None: not placed)."""
    after = sum(1 for t in sim["stale_command_times_s"] if t > end_s + 1e-9)
    out = HilSimulatorSection(
        steps=sim["steps"], commands_received=sim["commands_received"], malformed_dropped=sim["malformed_dropped"],
        stale_command_events=sim["stale_command_events"] - after, lockstep_resends=sim["lockstep_resends"],
        jitter_ms=sim["jitter_ms"], stepping=sim["stepping"], stalls=sim["stalls"], battery=sim["battery"],
        busy_poll=BusyPollEnds(simulator=sim["busy_poll"], autopilot=ap_busy_poll),
        stale_command_events_after_end=after, cpus=cpus)
    if "pipeline_skips" in sim:   # the pipelined lockstep (sim.lockstep_pipeline)
        out["pipeline_skips"] = sim["pipeline_skips"]
    return out


class TapRecords(Protocol):
    """What the tap (:class:`hil.tap.Tap`) recorded of a run, as the judge reads it."""

    truth: dict[int, tuple[float, float, float, float]]           # time_usec -> (north m, east m, vn, ve m/s)
    truth_raw: dict[tuple[int, int], tuple[float, float, int]]    # (segment, time_usec) -> (n, e, run time usec)
    estimate: dict[tuple[int, int], tuple[float, float]]          # (segment, ms) -> (north, east) m
    commands: list[tuple[int, float, float]]                      # (time_usec, port, stdb) in [-1, 1]
    ais_forwarded: int
    counters_at_close: TapCounters | None
    frames: int


@dataclass(frozen=True)
class RunRecord:
    """What supervision (:class:`hil.hilrun.HilRun`) knows of a run at its end, besides the tap's
    records: how it ended (``outcome``; ``decided``: the truth time in us of the deciding sample),
    and the processes' own summaries as they printed them."""

    scenario: str
    seed: int
    lockstep: bool
    speedup: float
    outcome: str
    collision_at: float | None        # s of simulated time
    min_clearance: float              # m
    wall_s: float
    decided: int | None
    autopilot: object | None      # the processes' summaries as parsed JSON, read strictly here
    simulator: object | None
    simulator_restarts: int
    pinned: dict[str, int]
    warnings: tuple[str, ...]
    can_log: CanLogSummary | None
    tlog: Path


def summarise(run: RunRecord, tap: TapRecords, cfg: HilConfig,
              encounter_judge: EncounterJudge | None = None) -> RunSummary:
    """The run's summary, judged up to the deciding sample (what arrived while the processes were
    being stopped depends on the wall clock): path length, energy, navigation error, encounters, and
    the processes' counters."""
    decided = run.decided
    times = [t for t in sorted(tap.truth) if decided is None or t <= decided]
    track = np.array([tap.truth[t][:2] for t in times]) if times else np.zeros((0, 2))
    speeds = np.array([math.hypot(*tap.truth[t][2:]) for t in times]) if times else np.zeros(0)
    length = float(np.sum(np.hypot(*np.diff(track, axis=0).T))) if len(track) > 1 else 0.0
    energy = thrust_energy(times, speeds, tap.commands, cfg.vessel)
    rmse = nav_rmse(tap.estimate, tap.truth_raw, decided)
    ap = None if run.autopilot is None else read_autopilot_summary(run.autopilot)
    sim = None if run.simulator is None else read_simulator_summary(run.simulator)
    reached = run.outcome == "goal" and run.collision_at is None
    encounters = traffic = None
    if encounter_judge is not None:
        from hil.encounter_report import totals

        enc = encounter_judge.report({t: tap.truth[t] for t in times})   # up to the deciding sample
        encounters = tuple(enc)
        traffic = RunTraffic(**totals(enc), ship_collision=ship_collision(encounter_judge),
                             ais=ap.traffic["ais"] if ap is not None and ap.traffic is not None else None,
                             ais_forwarded_to_gcs=tap.ais_forwarded)
    can = None
    if cfg.can.actuators == "can":
        # The CAN path's counters: transport, ESC status, rejects (wall-clock dependent).
        can = RunCan(autopilot=None if ap is None else ap.can, simulator=None if sim is None else sim.get("can"))
        if run.can_log is not None:
            can["can_log"], can["can_log_frames"] = run.can_log["can_log"], run.can_log["can_log_frames"]
    end_s = times[-1] * 1e-6 if times else 0.0
    return RunSummary(
        scenario=run.scenario,
        seed=run.seed,
        mode="lockstep" if run.lockstep else f"realtime x{run.speedup:g}",
        outcome=run.outcome,
        reached_goal=reached,
        collisions=0 if run.collision_at is None else 1,
        collision_time_s=run.collision_at,
        min_clearance_m=None if not math.isfinite(run.min_clearance) else round(run.min_clearance, 3),
        sim_time_s=round(end_s, 3),
        wall_time_s=round(run.wall_s, 2),
        path_length_m=round(length, 2),
        # With CAN in real time the commands travel only on CAN: the tap cannot see them.
        energy_J=None if can is not None and not run.lockstep else round(energy, 1),
        planning_cycles=None if ap is None else ap.planning_cycles,
        plans_accepted=None if ap is None else ap.plans_accepted,
        deadline_overruns=None if ap is None else ap.deadline_overruns,
        worker_restarts=None if ap is None else ap.worker_restarts,
        fallback_activations=None if ap is None else ap.fallback_activations,
        tracking=None if ap is None else ap.tracking,     # cross-track and heading errors on local paths
        navigation_rmse_m=None if rmse is None else round(rmse, 3),
        control_latency_ms=None if ap is None else ap.control_latency_ms,
        simulator_restarts=run.simulator_restarts,
        navigation=None if ap is None else ap.navigation,
        sensed_obstacles=None if ap is None else ap.sensed_obstacles,
        simulator=None if sim is None else simulator_part(sim, end_s, None if ap is None else ap.busy_poll,
                                                          run.pinned or None),
        security=RunSecurity(
            simulator=None if sim is None else SimulatorSecurity(rejects=sim["rejects"], **sim["command_port"]),
            autopilot=None if ap is None else ap.link,
            autopilot_navigation_numeric={} if ap is None else
            {k: v for k, v in ap.navigation.rejected.items() if k.startswith("numeric_")},
            tap=tap.counters_at_close,
        ),
        tlog=str(run.tlog),
        tlog_messages=tap.frames,
        events=() if ap is None else ap.events,
        actuators=cfg.can.actuators,
        warnings=run.warnings or None,
        # The ground-station link's counters (datagrams, rejects, missions, command acks, signing,
        # failsafe): what a GCS did during the run. Wall-clock dependent (heartbeats per wall second).
        gcs=None if ap is None else ap.gcs,
        encounters=encounters,
        traffic=traffic,
        can=can,
        current=None if sim is None else RunCurrent(
            source=sim["current"]["source"], felt=sim["current"]["felt"],
            planner_field=None if ap is None or ap.current is None else ap.current["planner_field"],
            estimate=None if ap is None or ap.current is None else ap.current["estimate"]),
    )


def ship_collision(judge: EncounterJudge) -> ShipCollision | None:
    """The ship the vessel collided with, and when (None: none)."""
    return None if judge.collision is None else ShipCollision(time_s=judge.collision[0], mmsi=judge.collision[1])
