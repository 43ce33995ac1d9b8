"""The vessel computer built in-process from its typed parts, without sockets or processes.

:func:`build_computer` makes an :class:`autopilot_bridge.autopilot.Autopilot` from the configuration and a
scenario exactly as ``hil.assembly.build`` does (the same :func:`hil.assembly.planning_world`,
:func:`hil.assembly.computer_config`, :func:`hil.assembly.run_options`), with three devices of its own that
implement the same interfaces:

* :class:`ScriptedLink` (``autopilot_bridge.hil_link.SensorLink``): the test hands frames to ``on_frame``
  itself; the thruster commands are recorded;
* :class:`InlineWorker` (the planner worker's interface): the real online planning handler, run in this
  process when a cycle is submitted; every request is kept;
* no ground-station link: a test drives the parameter service and the command API directly.
"""

from __future__ import annotations

import math
from collections import Counter
from dataclasses import dataclass, field
from typing import Any

from autopilot_bridge.autopilot import Autopilot
from autopilot_bridge.computer_setup import Devices
from autopilot_bridge.hil_link import GpsFix, SensorFrame
from autopilot_bridge.local_planning import CycleInput, LocalPlan, online_cycle_handler
from autopilot_bridge.planning_worker import PlanReply, PlanRequest, WorkerStats
from hil import scenario as scenarios
from hil import settings
from hil.assembly import computer_config, planning_world, run_options
from planner.gridmap import OccupancyGrid


@dataclass
class ScriptedLink:
    rejects: Counter[str] = field(default_factory=Counter)
    truth_ignored: int = 0
    busy: Any = None
    commands: list[tuple[int, float, float]] = field(default_factory=list)

    def receive(self, timeout: float) -> list[SensorFrame]:
        return []

    def take_ais(self) -> list[Any]:
        return []

    def send_controls(self, time_usec: int, port: float, stdb: float, armed: bool = True) -> None:
        self.commands.append((time_usec, port, stdb))


class InlineWorker:
    """The planner worker's interface with the handler run at submit (lockstep: the answer is due at once)."""

    def __init__(self, handler: Any) -> None:
        self.handler = handler
        self.stats = WorkerStats()
        self.requests: list[PlanRequest[CycleInput]] = []
        self._reply: PlanReply[LocalPlan] | None = None
        self.busy = False

    def wait_ready(self, timeout: float) -> bool:
        return True

    def submit(self, request: PlanRequest[CycleInput], now: float | None = None) -> bool:
        self.requests.append(request)
        self._reply = PlanReply(request.cycle, self.handler(request))
        self.stats.submitted += 1
        return True

    def poll(self, now: float | None = None) -> PlanReply[LocalPlan] | None:
        reply, self._reply = self._reply, None
        return reply

    def wait(self, timeout: float) -> PlanReply[LocalPlan] | None:
        return self.poll()

    def cancel(self, why: str) -> bool:
        self._reply = None
        return True

    def watchdog(self, now: float | None = None) -> bool:
        return False

    def close(self) -> None:
        pass


def build_computer(scenario: str = "harbour", overrides: tuple[str, ...] = (), wait_for_arm: bool = True
                   ) -> tuple[Autopilot, ScriptedLink, InlineWorker]:
    cfg = settings.load(None, [*overrides, f"gcs.wait_for_arm={'true' if wait_for_arm else 'false'}"])
    scen = scenarios.load(scenario, cfg.current, cfg.planner.safety_radius, cfg.geodesy)
    world = planning_world(cfg, scen)
    link, worker = ScriptedLink(), InlineWorker(online_cycle_handler(world))
    ap = Autopilot(computer_config(cfg), world, Devices(link, worker), run_options(cfg, lockstep=True),
                   grid=OccupancyGrid(world.occ.copy(), world.resolution))
    return ap, link, worker


def frame(t: float, north: float, east: float, heading: float = 0.0, speed: float = 0.0) -> SensorFrame:
    """A sensor frame at time ``t`` (s) of a boat at (north, east) m heading ``heading`` rad at ``speed`` m/s,
    with every sensor reporting the truth (GPS every frame)."""
    vn, ve = speed * math.cos(heading), speed * math.sin(heading)
    return SensorFrame(time_usec=int(round(t * 1e6)), yaw_rate=0.0, heading=heading,
                       gps=GpsFix(north, east, vn, ve), gps_dropout=False, dvl=(speed, 0.0))
