"""What the vessel computer (autopilot_bridge/autopilot.py) is built from and counts: its tuning
(:class:`ComputerConfig`), the devices it talks to (:class:`Devices`), how a run drives it
(:class:`RunOptions`), and its counters (:class:`AutopilotStats`)."""

from __future__ import annotations

from collections import Counter
from dataclasses import dataclass, field
from typing import TYPE_CHECKING

from autopilot_bridge.battery_monitor import BatteryMonitorParams
from autopilot_bridge.config import AutopilotParams
from autopilot_bridge.control import ControlParams, SurgeModel
from autopilot_bridge.hil_link import SensorLink
from autopilot_bridge.local_planning import CycleInput, LocalPlan
from autopilot_bridge.navigation import NavigationParams
from autopilot_bridge.planning_worker import PlannerWorker
from autopilot_bridge.telemetry import Telemetry
from common.percentiles import StreamingPercentiles

if TYPE_CHECKING:
    from autopilot_bridge.can_actuators import CanActuators
    from autopilot_bridge.traffic_awareness import TrafficAwareness


@dataclass(frozen=True)
class Hull:
    """What the vessel computer is told of its hull and thrusters: the [vessel] figures of eq. (5)."""

    m: float         # kg, rigid-body mass
    rho: float       # kg/m^3, water density
    D: float         # m, average draught
    L: float         # m, hull length
    d_u: float       # kg/s, linear surge damping
    B_u: float       # m, distance between the port and starboard propellers
    T_max: float     # N, largest forward thrust of one propeller
    T_min: float     # N (<= 0), largest reverse thrust of one propeller


@dataclass(frozen=True)
class Propulsion:
    """What the controller knows of the vessel: nominal surge model and the thrusters."""

    surge: SurgeModel
    B_u: float       # m
    T_max: float     # N
    T_min: float     # N (<= 0)

    @classmethod
    def from_hull(cls, hull: Hull) -> Propulsion:
        """The computer's own nominal model of ``hull`` (eq. (5), :meth:`SurgeModel.from_hull`)."""
        return cls(SurgeModel.from_hull(hull.m, hull.rho, hull.D, hull.L, hull.d_u), hull.B_u, hull.T_max, hull.T_min)


@dataclass(frozen=True)
class ComputerConfig:
    """How the vessel computer is tuned: its own parameters, the filter's and the controllers',
    and what it is told of its hull (its nominal propulsion model is its own: :meth:`Propulsion.from_hull`)."""

    params: AutopilotParams
    nav: NavigationParams
    control: ControlParams
    hull: Hull
    battery: BatteryMonitorParams = field(default_factory=BatteryMonitorParams)


@dataclass(frozen=True)
class RunOptions:
    """How this run drives the computer: lockstep (answer every frame, wait for the planner in
    simulated time) or real time, the seed of its planning cycles, int14 thruster commands
    (DroneCAN resolution), whether it waits disarmed in HOLD for a ground station, and the pace
    (x wall time) of lockstep with a ground station attached (None: 1x while disarmed only);
    ``home_item``: mission item 0 is home (the boat identifies as ArduPilot, whose convention it is)."""

    lockstep: bool
    seed: int
    int14_commands: bool = False
    wait_for_arm: bool = False
    pace_speedup: float | None = None
    home_item: bool = False


@dataclass(frozen=True)
class Devices:
    """What the computer talks to: the simulator's HIL link, the planner worker process, the
    ground-station link (or None), AIS traffic awareness (or None) and the thruster back-end
    (None: HIL_ACTUATOR_CONTROLS on the HIL link; else e.g. CanActuators)."""

    link: SensorLink
    worker: PlannerWorker[CycleInput, LocalPlan]
    telemetry: Telemetry | None = None
    traffic: TrafficAwareness | None = None
    actuators: CanActuators | None = None


@dataclass
class AutopilotStats:
    frames: int = 0
    duplicate_frames: int = 0
    commands: int = 0
    planning_cycles: int = 0
    plans_accepted: int = 0
    plans_rejected: Counter = field(default_factory=Counter)
    fallback_activations: int = 0
    simulator_restarts: int = 0
    latency_ms: StreamingPercentiles = field(default_factory=StreamingPercentiles)
    planner_waits: int = 0          # lockstep frames that waited for the planner (by design)
    planner_wait_ms: list[float] = field(default_factory=list)
    sensed_replans: int = 0         # local paths found blocked by newly sensed obstacles
    events: list[tuple[float, str]] = field(default_factory=list)
