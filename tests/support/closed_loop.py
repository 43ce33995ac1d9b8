"""The simulator's truth and the vessel computer closed-loop in one process, no sockets (issue 31, point 7).

:class:`ClosedLoop` steps :class:`simulator.core.SimulatorCore` (the scenario's start and current, as
``hil run`` sets them) and feeds the vessel computer of :func:`support.vessel_harness.build_computer` a
frame of the truth each step (heading, yaw rate, GPS position and velocity, DVL: no sensor noise); the
thruster command it answers is applied by the core before the next step, as lockstep does. Used to
reproduce, small and deterministically, what the chaos ground station found near the quays.
Positions NED m; the chart's clearance is the cell-centre distance to the nearest obstacle cell.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
from scipy.ndimage import distance_transform_edt

from autopilot_bridge.hil_link import GpsFix, SensorFrame
from hil import scenario as scenarios
from hil import settings
from hil.assembly.simulator import simulator_settings
from simulator.core import Command, SimulatorCore
from support.vessel_harness import build_computer

REPO = Path(__file__).resolve().parents[2]
OCC = np.load(REPO / "configs" / "maps" / "harbour.npy")
CLEARANCE = distance_transform_edt(~OCC) * 0.5     # m, rows north, columns east, 0.5 m cells


# hil run's judge (hil.judging.Judge): a collision is a hull centre nearer than half the hull's length (1 m) to
# an obstacle cell's edge, that is nearer than 1.25 m to its centre in the measure of clearance() below.
COLLISION_CLEARANCE = 1.25


def clearance(north: float, east: float) -> float:
    """m from the harbour cell holding (north, east) to the nearest obstacle cell (cell centres)."""
    return float(CLEARANCE[min(max(int(north / 0.5), 0), OCC.shape[0] - 1),
                           min(max(int(east / 0.5), 0), OCC.shape[1] - 1)])


class ClosedLoop:
    """The harbour's truth at ``start`` (NED m, heading ``psi`` rad) and its vessel computer."""

    def __init__(self, start: tuple[float, float], psi: float = 0.0) -> None:
        base = settings.load(None, [])
        scen = scenarios.instance(scenarios.load_spec("harbour"), None, base.current)
        overrides = [o for o in scenarios.simulator_overrides(scen, base.current) if not o.startswith("sim.initial")]
        overrides += [f"sim.initial.x={start[0]!r}", f"sim.initial.y={start[1]!r}", f"sim.initial.psi={psi!r}"]
        self.core = SimulatorCore(simulator_settings(settings.load(None, overrides)))
        self.ap, self.link, self.worker = build_computer()

    def step(self) -> None:
        """One frame: the truth to the vessel computer, its command to the core, the core one step on."""
        core = self.core
        x, y, psi, u, v, r = core.state
        c, s = math.cos(psi), math.sin(psi)
        sent = len(self.link.commands)
        self.ap.on_frame(SensorFrame(core.time_usec, r, psi, GpsFix(x, y, u * c - v * s, u * s + v * c),
                                     False, (u, v)), 0.0)
        if len(self.link.commands) > sent:
            _, port, stdb = self.link.commands[-1]
            core.apply(Command(core.time_usec, port, stdb))
        core.step()

    def run(self, seconds: float) -> float:
        """Step ``seconds`` of simulated time; the least chart clearance (m) of the hull's centre on the way."""
        worst = math.inf
        for _ in range(int(round(seconds / self.core.frame_dt))):
            self.step()
            worst = min(worst, clearance(self.core.state[0], self.core.state[1]))
        return worst
