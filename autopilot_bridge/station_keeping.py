"""Keeping station at the end of a route (AUTO's mission end, LOITER, RTL and GUIDED arrival).

``loiter`` (ArduPilot's LOITER for boats): drift while within LOIT_RADIUS of the point; beyond it,
steer straight back at ``return_speed`` until within half the radius. The way back is the water the boat
has just drifted across, so it needs no planning. Not looping: thrusters off (HOLD at the end).
"""

from __future__ import annotations

import math
from collections.abc import Callable

from autopilot_bridge.behaviour import Behaviour, BehaviourMachine
from autopilot_bridge.control import Thrust
from autopilot_bridge.navigation import NavState
from autopilot_bridge.parameters import Tunable

# drive(state, dt, heading ref rad, speed ref m/s) -> Thrust
Drive = Callable[[NavState, float, float, float], Thrust]


class StationKeeper:
    radius = Tunable("LOIT_RADIUS", 0.5, 100.0, "m",
                     "loiter: drifting this far from the point starts the way back (ArduRover: LOIT_RADIUS)")

    def __init__(self, radius: float, return_speed: float, zero_thrust: Thrust) -> None:
        self.radius = radius
        self.return_speed = return_speed    # m/s
        self.zero_thrust = zero_thrust

    def command(self, s: NavState, dt: float, point: tuple[float, float], loiter: bool, behaviour: BehaviourMachine,
                drive: Drive, on_return: Callable[[], None]) -> Thrust:
        """This frame's thrust at ``point`` (NED m); ``on_return()`` when the way back begins."""
        d = math.hypot(point[0] - s.x, point[1] - s.y)
        if not loiter or d <= 0.5 * self.radius or (behaviour.state is Behaviour.COMPLETE and d <= self.radius):
            behaviour.to(Behaviour.COMPLETE)
            return self.zero_thrust
        if behaviour.to(Behaviour.RETURNING):
            on_return()
        psi_ref = math.atan2(point[1] - s.y, point[0] - s.x)
        return drive(s, dt, psi_ref, min(self.return_speed, max(0.3, 0.5 * d)))
