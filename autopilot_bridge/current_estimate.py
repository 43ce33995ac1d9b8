"""The current, as the vessel computer can know it: ground velocity minus velocity through the water.

The navigation filter gives the velocity over ground (GPS, bottom-tracking DVL). The velocity through
the water is not measured on this boat (no water-track log), so it is predicted from what the computer
does know, its thrust and its nominal hull model (eq. (4), :class:`autopilot_bridge.control.SurgeModel`):

* surge through the water ``u_w``: integrated from ``m11 du_w/dt = tau_u - D(u_w)`` with the thrust sent;
* sway through the water: 0 - twin thrusters make no sway force, and the hull's cross-flow drag
  (d_v = 300 kg/s, a time constant m22/d_v of about a quarter of a second) stops any sway through the
  water within a second of a turn.

Their difference, rotated to NED, is low-pass filtered (time constant ``tau``, 10 s by default: waves of
a few seconds' period average out, a current that changes over the run's minutes is followed). Where the
planner's current field (the chart's forecast, ``prior``) is known, the estimate starts from it. Chosen
over the filter's own drift state because the filter has none: its state is position, heading, ground
velocity, yaw rate and gyro bias (:mod:`autopilot_bridge.navigation`).
"""

from __future__ import annotations

import math
from collections.abc import Callable

from autopilot_bridge.control import SurgeModel
from autopilot_bridge.navigation import NavState

Prior = Callable[[float, float], tuple[float, float]]   # (north, east) m -> current (north, east) m/s


class CurrentObserver:
    def __init__(self, model: SurgeModel, tau: float = 10.0, prior: Prior | None = None) -> None:
        self.model, self.tau, self.prior = model, tau, prior
        self.north = self.east = 0.0          # m/s, the estimate
        self.u_water: float | None = None     # m/s, predicted surge through the water
        self.samples = 0

    def reset(self) -> None:
        self.north = self.east = 0.0
        self.u_water = None
        self.samples = 0

    @property
    def velocity(self) -> tuple[float, float]:
        """The current (north, east), m/s."""
        return self.north, self.east

    def along(self, psi: float) -> float:
        """The current's component along a heading ``psi`` (rad), m/s."""
        return self.north * math.cos(psi) + self.east * math.sin(psi)

    def update(self, s: NavState, tau_u: float, dt: float) -> None:
        """One frame: the estimate ``s`` (ground velocity u, v in the body frame) after ``dt`` s under the
        surge force ``tau_u`` (N, the two thrusters' sum) that was applied over it."""
        c, sn = math.cos(s.psi), math.sin(s.psi)
        if self.u_water is None:
            if self.prior is not None:
                self.north, self.east = self.prior(s.x, s.y)
            self.u_water = s.u - self.along(s.psi)
            return
        m = self.model
        if dt > 0.0:
            self.u_water += dt * (tau_u - m.damping(self.u_water)) / m.m11
            cu, cv = s.u - self.u_water, s.v          # the current in the body frame
            k = min(1.0, dt / self.tau)
            self.north += k * (cu * c - cv * sn - self.north)
            self.east += k * (cu * sn + cv * c - self.east)
            self.samples += 1
