"""What the vessel is following now: the state the frame pipeline, the helm and plan acceptance share.

One object, owned by :class:`autopilot_bridge.autopilot.Autopilot` and handed to the parts that read or
change it, so that none of them reaches into another. Positions NED m, times s of vehicle time.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from autopilot_bridge.behaviour import BehaviourMachine
from autopilot_bridge.guidance import LineOfSight


@dataclass
class Course:
    goal_ned: tuple[float, float]          # the end of the global reference path
    goal_radius: float                     # m: within it the route's end is reached
    reference_ned: np.ndarray              # (N, 2) the global reference path (routed on the chart)
    target: tuple[float, float] = (0.0, 0.0)   # the newest local plan's subgoal (the reactive behaviour's aim)
    behaviour: BehaviourMachine = field(default_factory=BehaviourMachine)
    los: LineOfSight | None = None         # the local path being followed
    speed_factor: float = 1.0              # the newest local plan's speed factor (traffic)
    path_invalid: bool = False             # the followed path is blocked (sensed) or traffic asks for a new one
    next_plan_t: float = 0.0               # when the next planning cycle is due
    complete_t: float | None = None        # when the route's end was reached

    def restart(self) -> None:
        """Navigation starts over (simulator restart): nothing followed, a cycle due at once."""
        self.behaviour = BehaviourMachine()
        self.los = None
        self.next_plan_t = 0.0
        self.complete_t = None
        self.target = self.goal_ned
        self.speed_factor = 1.0
        self.path_invalid = False
