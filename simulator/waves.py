"""Wave forces of eq. (6) with a slowly varying, seeded amplitude and direction.

The mean wave amplitude alpha and the direction beta the waves travel towards (clockwise from
north) each follow an Ornstein-Uhlenbeck process around the configured mean, with the
configured standard deviation and correlation time, advanced with its exact discretisation.
The encounter angle is chi = beta - psi (0: following seas, pi/2: waves pushing to starboard).
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

import numpy as np

from simulator.sensors import Normals

if TYPE_CHECKING:
    from simulator.config import VesselParams, WaveParams


def wave_forces(rho: float, L: float, alpha: float, chi: float,
                C_X: float, C_Y: float, C_N: float) -> tuple[float, float, float]:
    """Eq. (6): body-frame surge force, sway force (N) and yaw moment (N m)."""
    q = 0.5 * rho * alpha * alpha
    return q * L * math.cos(chi) * C_X, q * L * math.sin(chi) * C_Y, q * L * L * math.sin(chi) * C_N


class OrnsteinUhlenbeck:
    """Scalar OU process x' = -(x - mean)/tau + noise, stationary std ``std`` (exact steps)."""

    def __init__(self, mean: float, std: float, tau: float, rng: np.random.Generator | Normals) -> None:
        """``rng``: a :class:`~simulator.sensors.Normals` (the Generator's draws, in order, fetched in
        blocks), or a Generator, which gets a Normals of its own. Processes that draw from one stream
        in turn must share one Normals: two Normals on one Generator would each fetch a block ahead,
        and the draws would no longer alternate between them (:class:`WaveModel` shares one)."""
        self.mean, self.std, self.tau = mean, std, tau
        self.normal = rng if isinstance(rng, Normals) else Normals(rng)
        self.value = mean + std * self.normal() if std > 0 else mean

    def step(self, dt: float) -> float:
        if self.std > 0:
            a = math.exp(-dt / self.tau)
            self.value = self.mean + (self.value - self.mean) * a \
                + self.std * math.sqrt(1.0 - a * a) * self.normal()
        return self.value


class WaveModel:
    """Slowly varying sea state; :meth:`forces` gives eq. (6) for a heading."""

    def __init__(self, waves: WaveParams, vessel: VesselParams, rng: np.random.Generator) -> None:
        self.p, self.rho, self.L = waves, vessel.rho, vessel.L
        self.enabled = bool(waves.enabled)
        normal = Normals(rng)   # one stream, drawn in turn by both processes as before
        self.amplitude = OrnsteinUhlenbeck(waves.amplitude, waves.amplitude_std, waves.correlation_time, normal)
        self.direction = OrnsteinUhlenbeck(waves.direction, waves.direction_std, waves.correlation_time, normal)

    def advance(self, dt: float) -> None:
        if self.enabled:
            self.amplitude.step(dt)
            self.direction.step(dt)

    def forces(self, psi: float) -> tuple[float, float, float]:
        if not self.enabled:
            return 0.0, 0.0, 0.0
        alpha = max(0.0, self.amplitude.value)
        p = self.p
        return wave_forces(self.rho, self.L, alpha, self.direction.value - psi, p.C_X, p.C_Y, p.C_N)
