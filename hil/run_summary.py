"""The run's summary: what `hil run` returns, prints with ``--json`` and writes to ``summary.json``.

Frozen dataclasses serialised with :func:`common.tables.to_table`; :func:`read_summary` and
:func:`read_autopilot_summary` read them back strictly, an unknown or missing key being one line that
names it. Sections owned by other components (path tracking, the ground-station link, the CAN path,
COLREGs encounters) keep those components' own tables.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING, NotRequired, TypedDict, TypeVar, final

from autopilot_bridge.ais_tracking import AisSummary
from autopilot_bridge.can_actuators import CanPathSummary
from autopilot_bridge.gcs.link import GcsSummary
from autopilot_bridge.hil_link import LinkSummary
from autopilot_bridge.summary import AutopilotSummary, ControlLatency, NavigationCounts
from autopilot_bridge.tracking_stats import TrackingSummary
from common.current_tally import CurrentStats
from common.tables import absent_when_none
from common.udp import BusyPollSummary
from hil.ardupilot import ArduPilotSimulatorSection, ArduRoverSetup
from hil.config import from_table, from_typed_table
from hil.encounter_report import EncounterTotals, EncounterVerdict
from hil.errors import ConfigError, RunFailed
from simulator.core import BatterySummary
from simulator.server import CommandPort, JitterMs, SimulatorCanSummary, SimulatorSummary, Stalls, Stepping

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


class BusyPollEnds(TypedDict):
    """How each end's lockstep waits went (common.udp.BusyPoll; None where off)."""

    simulator: BusyPollSummary | None
    autopilot: BusyPollSummary | None


@final
class HilSimulatorSection(TypedDict):
    """The run summary's ``simulator`` section where the vessel computer flew: the simulator's counters
    (:class:`simulator.server.SimulatorSummary`) as the judge reads them. Stale-command failsafes are
    those up to the run's judged end; those after it, while the processes were being stopped, apart.
    ``cpus``: the CPUs each end was pinned on (None: not placed)."""

    steps: int
    commands_received: int
    malformed_dropped: int
    stale_command_events: int
    lockstep_resends: int
    jitter_ms: JitterMs | None
    stepping: Stepping | None
    stalls: Stalls
    battery: BatterySummary
    busy_poll: BusyPollEnds
    pipeline_skips: NotRequired[int]          # the pipelined lockstep only
    stale_command_events_after_end: int
    cpus: dict[str, int] | None


class RunCurrent(TypedDict):
    """The current three ways, each sampled along the boat's way (m/s, NED): the ``[current]`` source, the
    truth the simulator applied at the hull (once a frame), the planner's field where the vessel computer
    put the boat (10 Hz; None without a current) and the computer's own estimate from ground velocity and
    thrust (10 Hz). Where the three agree, the current given is the one the boat felt and planned with."""

    source: str
    felt: CurrentStats | None
    planner_field: CurrentStats | None
    estimate: CurrentStats | None


class SimulatorSecurity(CommandPort):
    """What the simulator refused, by reason, and its command port's counters."""

    rejects: dict[str, int]


class RunCan(TypedDict):
    """``--actuators can``: the CAN path's counters at both ends (transport, ESC status, rejects; wall-clock
    dependent) and the run folder's CAN log where one was recorded."""

    autopilot: CanPathSummary | None
    simulator: SimulatorCanSummary | None
    can_log: NotRequired[str]
    can_log_frames: NotRequired[int]


@dataclass(frozen=True)
class RunSecurity:
    """Every refused frame by reason, per endpoint, with the kernel's drops (docs/security.md)."""

    simulator: SimulatorSecurity | None
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
    simulator: HilSimulatorSection | ArduPilotSimulatorSection | None   # by back-end: `hil run --autopilot`
    security: RunSecurity
    tlog: str
    tlog_messages: int
    events: tuple[str, ...]
    actuators: str                                   # "mavlink" or "can"
    warnings: tuple[str, ...] | None = absent_when_none()
    gcs: GcsSummary | None = absent_when_none()                  # the ground-station link's counters
    encounters: tuple[EncounterVerdict, ...] | None = absent_when_none()   # scenarios with traffic
    traffic: RunTraffic | None = absent_when_none()
    can: RunCan | None = absent_when_none()                      # --actuators can
    current: RunCurrent | None = absent_when_none()              # where the vessel computer flew
    run_folder: str | None = absent_when_none()
    plot: str | None = absent_when_none()
    plot_error: str | None = absent_when_none()

    def simulator_counters(self) -> HilSimulatorSection | None:
        """The ``simulator`` section where the vessel computer flew (None: ArduRover flew, or no summary)."""
        sim = self.simulator
        return None if sim is None or "ardupilot" in sim else sim

    def ardurover(self) -> ArduRoverSetup | None:
        """ArduRover's setup where it flew (None: the vessel computer flew)."""
        sim = self.simulator
        return sim["ardupilot"] if sim is not None and "ardupilot" in sim else None


def _read(cls: type[T], table: object, source: str) -> T:
    if not isinstance(table, dict):
        raise ConfigError(f"{source}: expected a JSON object, got {type(table).__name__}")
    return from_table(cls, table, source)


def read_summary(table: object, source: str = "summary.json") -> RunSummary:
    """A run summary from its table (parsed JSON); ConfigError names the key that does not fit."""
    return _read(RunSummary, table, source)


def read_simulator_summary(table: object, source: str = "the simulator's summary") -> SimulatorSummary:
    """The simulator's summary (what `hil sim` prints) from its table; RunFailed names the key that does
    not fit (the two processes disagree on the contract: a bug, not a user mistake)."""
    try:
        return from_typed_table(SimulatorSummary, table, source)
    except ConfigError as exc:
        raise RunFailed(str(exc)) from None


def read_autopilot_summary(table: object, source: str = "the autopilot's summary") -> AutopilotSummary:
    """The autopilot's summary from its table; RunFailed names the key that does not fit (the two
    processes disagree on the contract: a bug, not a user mistake)."""
    try:
        return _read(AutopilotSummary, table, source)
    except ConfigError as exc:
        raise RunFailed(str(exc)) from None

