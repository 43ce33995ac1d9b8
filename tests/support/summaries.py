"""Complete sample summaries (every required field set), for tests of their readers and writers."""

from __future__ import annotations

from dataclasses import replace
from typing import Any

from autopilot_bridge.ais_tracking import AisSummary
from autopilot_bridge.can_actuators import CanPathSummary
from autopilot_bridge.gcs.link import GcsSummary, ServiceTimes
from autopilot_bridge.hil_link import LinkSummary, StallEvent, StallSummary
from autopilot_bridge.plan_acceptance import AcceptedPath
from autopilot_bridge.summary import AutopilotSummary, ControlLatency, NavigationCounts, WorkerStartup
from autopilot_bridge.tracking_stats import TrackingSummary
from autopilot_bridge.traffic_awareness import EncounterRecord, TrafficSummary
from common.udp import BusyPollSummary
from hil.ardupilot import ArduPilotSimulatorSection, ArduRoverSetup, FenceUpload
from hil.encounter_report import EncounterVerdict
from hil.run_summary import (
    BusyPollEnds,
    HilSimulatorSection,
    RunCan,
    RunSecurity,
    RunSummary,
    RunTraffic,
    SimulatorSecurity,
    TapCounters,
)
from simulator.core import BatterySummary
from simulator.esc import EscBankSummary
from simulator.server import SimulatorCanSummary, Stalls, Stepping

LATENCY = ControlLatency(p50=0.4, p99=6.0, max=80.0, frames=100)
NAVIGATION = NavigationCounts(updates={"gps_pos": 450}, rejected={"gps_pos": 4, "numeric_gps": 1}, position_resets=0)
TRACKING = TrackingSummary(frames=100, cross_track_rms_m=0.2, cross_track_p95_m=0.5, cross_track_max_m=0.9,
                           heading_error_rms_rad=0.05, heading_error_p95_rad=0.1)
LINK = LinkSummary(rejects={"wrong_system": 2}, frames=1903, truth_ignored=0, timeline_switches=0, late_frames=1,
                   stalls=StallSummary(count=1, stale_frames_skipped=3,
                                       events=[StallEvent(t_s=12.5, length_s=0.75)]),
                   sensors_from="127.0.0.1:40001", wrong_source=0, budget_stops=0, kernel_drops=None)
GCS = GcsSummary(endpoints=["127.0.0.1:14551"], datagrams_in=20, datagrams_out=400, frames_in=20, frames_sent=380,
                 received={"HEARTBEAT": 20}, rejects={}, security_rejects={}, signing=False, signature_failures={},
                 missions_accepted=1, missions_rejected=0, mission_acks={"MAV_MISSION_ACCEPTED": 1},
                 mission={"uploads_accepted": 1}, command_acks={"MAV_RESULT_ACCEPTED": 2},
                 commands={"MAV_CMD_COMPONENT_ARM_DISARM:MAV_RESULT_ACCEPTED": 1}, param_rejects=0, encode_errors={},
                 failsafe_events=0, failsafe_active=False,
                 service_ms=ServiceTimes(p50=0.02, p99=0.4, max=1.5, calls=1903))
CAN = CanPathSummary(interface="virtual", channel="vcan0", node_id=10, raw_commands_sent=3,
                     transfers_sent={"RawCommand": 3}, send_errors=0, frames_received=6, own_frames_ignored=0,
                     impostor_frames=0, node_id_conflicts=0,
                     transfers_received={"Status@20": 2}, transfers_lost={}, transfers_duplicated={}, rejects={},
                     esc_status={"port": {"node_id": 20.0, "rpm": 900.0, "voltage": 24.1}}, esc_health={"20": 0})
TRAFFIC = TrafficSummary(ais=AisSummary(tracked=1, accepted=40, new_tracks=1, forgotten=0, rejected={}),
                         forwarded_to_gcs=40,
                         encounters=[EncounterRecord(mmsi=412000103, type="crossing-give-way", role="give-way",
                                                     start_s=30.5, bearing_deg=45.0, rule17_act_s=None, end_s=80.25)])
TAP = TapCounters(refused={"wrong_source": 1}, wrong_source=1, budget_stops=0, kernel_drops=0)
ENCOUNTER = EncounterVerdict(mmsi=412000103, name="FERRY", type="crossing-give-way", compliant=True, cpa_m=10.5,
                             cpa_time_s=55.0, safety_radius_m=4.0, collision=False, action="starboard turn",
                             role="give-way", required="starboard turn", risk_time_s=31.0, bearing_deg=40.0,
                             action_time_s=33.5, max_starboard_deg=35.0, max_port_deg=0.0, min_speed_ratio=0.9,
                             rule17_time_s=None, note="passed astern of her")
RUN_TRAFFIC = RunTraffic(ships=1, encounters=1, collisions=0, mean_cpa_m=10.5, compliance_rate=1.0,
                         ship_collision=None, ais=None, ais_forwarded_to_gcs=0)
BUSY = BusyPollSummary(max_us=950.0, caught=1800, missed=100, pauses=2, held=0)
SIMULATOR = HilSimulatorSection(
    steps=4530, commands_received=4529, malformed_dropped=0, stale_command_events=0, lockstep_resends=1,
    jitter_ms=None, stepping=Stepping(steps=4529, wall_s=30.5, steps_per_s=148.5),
    stalls=Stalls(count=0, total_s=0.0, events=[]),
    battery=BatterySummary(state_of_charge=0.98, voltage_v=24.9, consumed_mah=120.5, energy_wh=3.0, depleted=False),
    busy_poll=BusyPollEnds(simulator=None, autopilot=BUSY), stale_command_events_after_end=0, cpus=None)
SIM_SECURITY = SimulatorSecurity(rejects={"out_of_step_command": 1}, source="127.0.0.1:40002", wrong_source_address=0,
                                 wrong_source_id=0, budget_stops=0, kernel_drops=0)
ARDUPILOT = ArduPilotSimulatorSection(
    packets=40000, repeats=2, malformed=0, steps=39998, frame_rate_hz=400, wrong_peer=0,
    ardupilot=ArduRoverSetup(binary="/opt/ardurover", instance=11, params={"CRUISE_SPEED": 1.5}, auto_at_s=41.5,
                             mission_items=5, fence=FenceUpload(polygons=2, vertices=12, requests=12),
                             mission_time_s=150.0, setup_failure=None, statustext=["41.0 s: Mission: 1 WP"]))
ESC_BANK = EscBankSummary(node_ids=[20, 21], raw_commands_applied=3, last_raw_command=[4000, 4000], frames_received=6,
                          transfers_received={"RawCommand@10": 3}, transfers_lost={}, transfers_duplicated={},
                          transfers_sent={"Status@20": 2}, send_errors=0, rejects={}, autopilot_health=0,
                          budget_stops={}, node_id_conflicts=0)
RUN_CAN = RunCan(autopilot=CAN, simulator=SimulatorCanSummary(**ESC_BANK, lockstep_commands_missing=0,
                                                              mavlink_commands_ignored=0),
                 can_log="/tmp/run/can.log", can_log_frames=12)


def autopilot_summary(**changes: Any) -> AutopilotSummary:
    """An autopilot summary as `hil autopilot` writes it after a short run, with ``changes``."""
    base = AutopilotSummary(
        mode="planned", vehicle_mode="AUTO", mission_complete=True, complete_time_s=190.25, frames=1903,
        duplicate_frames=0, commands_sent=1903, planning_cycles=45, plans_accepted=40,
        plans_rejected={"collision": 5}, deadline_overruns=0, worker_kills=0, worker_restarts=0,
        worker_startup_s=WorkerStartup(count=1, max=0.412), plans_skipped_worker_starting=0,
        fallback_activations=2, tracking=TRACKING,
        simulator_restarts=0, navigation=NAVIGATION,
        sensed_obstacles={"scans": 10, "returns": 3, "cells": 2, "replans": 1}, link_rejects={},
        truth_messages_ignored=0, control_latency_ms=LATENCY, lockstep_planner_waits=3,
        lockstep_planner_wait_ms_max=12.5, lockstep_planner_wait_ms_total=40.0,
        events=("12.00s fallback: reactive avoidance", "190.25s mission complete"),
        traffic=None, link=LINK, busy_poll=BUSY,
        local_paths=(AcceptedPath(t=1.0, cycle=1, status="exact", path_ned=[[0.0, 0.0], [5.0, 1.0]]),),
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
        fallback_activations=2, tracking=TRACKING,
        navigation_rmse_m=0.1, control_latency_ms=LATENCY, simulator_restarts=0, navigation=NAVIGATION,
        sensed_obstacles={"cells": 0}, simulator=SIMULATOR,
        security=RunSecurity(simulator=SIM_SECURITY, autopilot=LINK, autopilot_navigation_numeric={}, tap=TAP),
        tlog="/tmp/run/run.tlog", tlog_messages=9000, events=("190.25s mission complete",), actuators="mavlink",
        run_folder="/tmp/run", plot="/tmp/run/plot.png",
    )
    return replace(base, **changes)
