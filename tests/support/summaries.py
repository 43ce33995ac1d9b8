"""Complete sample summaries (every required field set), for tests of their readers and writers."""

from __future__ import annotations

from dataclasses import replace
from typing import Any

from autopilot_bridge.summary import AutopilotSummary, ControlLatency, NavigationCounts, WorkerStartup
from hil.run_summary import RunSecurity, RunSummary

LATENCY = ControlLatency(p50=0.4, p99=6.0, max=80.0, frames=100)
NAVIGATION = NavigationCounts(updates={"gps_pos": 450}, rejected={"gps_pos": 4, "numeric_gps": 1}, position_resets=0)


def autopilot_summary(**changes: Any) -> AutopilotSummary:
    """An autopilot summary as `hil autopilot` writes it after a short run, with ``changes``."""
    base = AutopilotSummary(
        mode="planned", vehicle_mode="AUTO", mission_complete=True, complete_time_s=190.25, frames=1903,
        duplicate_frames=0, commands_sent=1903, planning_cycles=45, plans_accepted=40,
        plans_rejected={"collision": 5}, deadline_overruns=0, worker_kills=0, worker_restarts=0,
        worker_startup_s=WorkerStartup(count=1, max=0.412), plans_skipped_worker_starting=0,
        fallback_activations=2, tracking={"frames": 100, "cross_track_rms_m": 0.2, "cross_track_max_m": 0.9},
        simulator_restarts=0, navigation=NAVIGATION,
        sensed_obstacles={"scans": 10, "returns": 3, "cells": 2, "replans": 1}, link_rejects={},
        truth_messages_ignored=0, control_latency_ms=LATENCY, lockstep_planner_waits=3,
        lockstep_planner_wait_ms_max=12.5, lockstep_planner_wait_ms_total=40.0,
        events=("12.00s fallback: reactive avoidance", "190.25s mission complete"),
        traffic=None, link={"rejects": {}, "frames": 1903},
        local_paths=({"t": 1.0, "status": "exact", "path_ned": [[0.0, 0.0], [5.0, 1.0]]},),
        estimated_track=((0.0, 60.0, 20.0, 1.571), (0.1, 60.0, 20.1, 1.571)),
        sensed_cells=((100, 200),),
    )
    return replace(base, **changes)


def run_summary(**changes: Any) -> RunSummary:
    """A run summary as `hil run` writes it to summary.json, with ``changes``."""
    base = RunSummary(
        scenario="harbour", seed=1, mode="lockstep", outcome="goal", reached_goal=True, collisions=0,
        collision_time_s=None, min_clearance_m=2.5, sim_time_s=190.3, wall_time_s=40.0, path_length_m=250.1,
        energy_J=40000.0, planning_cycles=45, plans_accepted=40, deadline_overruns=0, worker_restarts=0,
        fallback_activations=2, tracking={"frames": 100, "cross_track_rms_m": 0.2, "cross_track_max_m": 0.9},
        navigation_rmse_m=0.1, control_latency_ms=LATENCY, simulator_restarts=0, navigation=NAVIGATION,
        sensed_obstacles={"cells": 0}, simulator={"steps": 4530, "malformed_dropped": 0, "jitter_ms": None},
        security=RunSecurity(simulator={"rejects": {}}, autopilot={"rejects": {}}, autopilot_navigation_numeric={},
                             tap={"rejects": {}}),
        tlog="/tmp/run/run.tlog", tlog_messages=9000, events=("190.25s mission complete",), actuators="mavlink",
        run_folder="/tmp/run", plot="/tmp/run/plot.png",
    )
    return replace(base, **changes)
