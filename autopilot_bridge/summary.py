"""The vessel computer's summary: what `hil autopilot` prints as its last stdout line and writes with
``--summary-out`` (``autopilot.json`` of a run folder), read back by `hil run`.

A frozen dataclass, serialised with :func:`common.tables.to_table` and read strictly with
``hil.config.from_table`` (an unknown or missing key is a one-line error naming it). Sections owned by
other components (path tracking, the CAN path, traffic, the HIL and ground-station links, the busy
poll, the accepted paths) have the types those components declare (TypedDicts beside the code that
fills them, read back as strictly as the dataclasses).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TypedDict

from autopilot_bridge.can_actuators import CanPathSummary
from autopilot_bridge.gcs.link import GcsSummary
from autopilot_bridge.hil_link import LinkSummary
from autopilot_bridge.plan_acceptance import AcceptedPath
from autopilot_bridge.tracking_stats import TrackingSummary
from autopilot_bridge.traffic_awareness import TrafficSummary
from common.current_tally import CurrentStats
from common.tables import absent_when_none
from common.udp import BusyPollSummary


@dataclass(frozen=True)
class ControlLatency:
    """Sensor frame received to actuator command sent, over the run (ms)."""

    p50: float
    p99: float
    max: float
    frames: int


@dataclass(frozen=True)
class WorkerStartup:
    """Start-ups of the planning worker process: how many, and the longest (s; None before any)."""

    count: int
    max: float | None


@dataclass(frozen=True)
class NavigationCounts:
    """The navigation filter's measurement updates and rejections by sensor or reason."""

    updates: dict[str, int]
    rejected: dict[str, int]
    position_resets: int


class ComputerCurrent(TypedDict):
    """The current as the vessel computer met it, sampled at 10 Hz where its estimate put the boat (m/s,
    NED): the planner's field (eq. (12)'s, frozen at ``field_time``; None without a current) and the
    computer's own estimate (:class:`autopilot_bridge.current_estimate.CurrentObserver`)."""

    planner_field: CurrentStats | None
    estimate: CurrentStats | None


@dataclass(frozen=True)
class AutopilotSummary:
    """Counters and outcome of one `hil autopilot` process (times in s of simulated time, latencies in ms).

    ``Autopilot.summary()`` fills everything up to ``traffic``; the command adds what its links and
    the run folder's plot need (``link`` ... ``sensed_cells``)."""

    mode: str                            # the planned/fallback behaviour's state
    vehicle_mode: str                    # the Rover mode (MANUAL, HOLD, AUTO ...)
    mission_complete: bool
    complete_time_s: float | None
    frames: int
    duplicate_frames: int
    commands_sent: int
    planning_cycles: int
    plans_accepted: int
    plans_rejected: dict[str, int]
    deadline_overruns: int
    worker_kills: int
    worker_restarts: int
    worker_startup_s: WorkerStartup
    plans_skipped_worker_starting: int
    fallback_activations: int
    tracking: TrackingSummary
    simulator_restarts: int
    navigation: NavigationCounts
    sensed_obstacles: dict[str, int]     # autopilot_bridge.obstacle_map, plus "replans"
    link_rejects: dict[str, int]
    truth_messages_ignored: int
    control_latency_ms: ControlLatency
    lockstep_planner_waits: int
    lockstep_planner_wait_ms_max: float
    lockstep_planner_wait_ms_total: float   # wall time the loop stood still for the planner
    events: tuple[str, ...]              # "12.34s what happened"
    can: CanPathSummary | None = absent_when_none()       # CAN actuators only
    traffic: TrafficSummary | None = None                 # None without traffic
    current: ComputerCurrent | None = absent_when_none()  # the planner's field and the estimate along the way
    link: LinkSummary | None = absent_when_none()         # the HIL link's refusals
    busy_poll: BusyPollSummary | None = absent_when_none()  # lockstep waits for frames
    gcs: GcsSummary | None = absent_when_none()           # the ground-station link's counters
    local_paths: tuple[AcceptedPath, ...] | None = absent_when_none()
    estimated_track: tuple[tuple[float, ...], ...] | None = absent_when_none()   # (t s, north m, east m, psi rad)
    sensed_cells: tuple[tuple[int, ...], ...] | None = absent_when_none()        # map grid [row, col]

    # What the human summary (no --json) leaves out: long arrays for the run folder's plot.
    BULKY = ("local_paths", "estimated_track", "sensed_cells")
