"""The run's summary: what `hil run` returns, prints with ``--json`` and writes to ``summary.json``.

Frozen dataclasses serialised with :func:`common.tables.to_table`; :func:`read_summary` and
:func:`read_autopilot_summary` read them back strictly, an unknown or missing key being one line that
names it. Sections owned by other components (path tracking, the ground-station link, the CAN path,
COLREGs encounters) keep those components' own tables.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING, Any, NotRequired, TypedDict, TypeVar

from autopilot_bridge.ais_tracking import AisSummary
from autopilot_bridge.gcs.link import GcsSummary
from autopilot_bridge.hil_link import LinkSummary
from autopilot_bridge.summary import AutopilotSummary, ControlLatency, NavigationCounts
from autopilot_bridge.tracking_stats import TrackingSummary
from common.tables import absent_when_none
from hil.config import from_table
from hil.encounter_report import EncounterTotals, EncounterVerdict
from hil.errors import ConfigError, RunFailed

if TYPE_CHECKING:
    from _typeshed import DataclassInstance

T = TypeVar("T", bound="DataclassInstance")


class ShipCollision(TypedDict):
    time_s: float      # s of simulated time
    mmsi: int


class RunTraffic(EncounterTotals):
    """The ``traffic`` section: the encounters' totals, the ship we collided with (None: none), and
    what the vessel computer made of the AIS reports (absent where ArduRover flew)."""

    ship_collision: ShipCollision | None
    ais: NotRequired[AisSummary | None]
    ais_forwarded_to_gcs: NotRequired[int]


class TapCounters(TypedDict):
    """What the run's tap refused, by reason, and its socket's counters."""

    refused: dict[str, int]
    wrong_source: int
    budget_stops: int
    kernel_drops: int | None


@dataclass(frozen=True)
class RunSecurity:
    """Every refused frame by reason, per endpoint, with the kernel's drops (docs/security.md)."""

    simulator: dict[str, Any] | None
    autopilot: LinkSummary | None                    # the autopilot's HIL link (AutopilotSummary.link)
    autopilot_navigation_numeric: dict[str, int]
    tap: TapCounters | None


@dataclass(frozen=True)
class RunSummary:
    """One HIL run (times in s, distances in m, energy in J). The autopilot's counters are None when
    it printed no summary (killed); the sections after ``actuators`` exist only where they apply."""

    scenario: str
    seed: int
    mode: str                                        # "lockstep" or "realtime xS"
    outcome: str                                     # goal, timeout, collision, wall_timeout, ...
    reached_goal: bool
    collisions: int
    collision_time_s: float | None
    min_clearance_m: float | None
    sim_time_s: float
    wall_time_s: float
    path_length_m: float
    energy_J: float | None                           # None where the tap cannot see the commands (CAN)
    planning_cycles: int | None
    plans_accepted: int | None
    deadline_overruns: int | None
    worker_restarts: int | None
    fallback_activations: int | None
    tracking: TrackingSummary | None                 # cross-track and heading errors on local paths
    navigation_rmse_m: float | None
    control_latency_ms: ControlLatency | None
    simulator_restarts: int
    navigation: NavigationCounts | None
    sensed_obstacles: dict[str, int] | None
    simulator: dict[str, Any] | None
    security: RunSecurity
    tlog: str
    tlog_messages: int
    events: tuple[str, ...]
    actuators: str                                   # "mavlink" or "can"
    warnings: tuple[str, ...] | None = absent_when_none()
    gcs: GcsSummary | None = absent_when_none()                  # the ground-station link's counters
    encounters: tuple[EncounterVerdict, ...] | None = absent_when_none()   # scenarios with traffic
    traffic: RunTraffic | None = absent_when_none()
    can: dict[str, Any] | None = absent_when_none()              # --actuators can
    run_folder: str | None = absent_when_none()
    plot: str | None = absent_when_none()
    plot_error: str | None = absent_when_none()


def _read(cls: type[T], table: Any, source: str) -> T:
    if not isinstance(table, dict):
        raise ConfigError(f"{source}: expected a JSON object, got {type(table).__name__}")
    return from_table(cls, table, source)


def read_summary(table: Any, source: str = "summary.json") -> RunSummary:
    """A run summary from its table (parsed JSON); ConfigError names the key that does not fit."""
    return _read(RunSummary, table, source)


def read_autopilot_summary(table: Any, source: str = "the autopilot's summary") -> AutopilotSummary:
    """The autopilot's summary from its table; RunFailed names the key that does not fit (the two
    processes disagree on the contract: a bug, not a user mistake)."""
    try:
        return _read(AutopilotSummary, table, source)
    except ConfigError as exc:
        raise RunFailed(str(exc)) from None

