"""The time-varying meandering-jet sea current of eq. (13) (Wen et al. 2019, section 4.1).

Stream function, with non-dimensional coordinates X = sc (x - origin_x), Y = sc (y - origin_y)
(x north, y east, metres) and time T = time_scale * t (seconds)::

    psi(X, Y, T) = 1 - tanh( (Y - B(T) cos(k (X - c T))) / sqrt(1 + k^2 B(T)^2 sin^2(k (X - c T))) )
    B(T) = b + e cos(omega T + theta_u)

The paper prints "tan"; the meandering-jet stream function (Bower 1991) uses the hyperbolic
tangent, which keeps the speed bounded. The paper also applies sc only inside the cosine; it is
applied to both coordinates here so that the field is a consistent function of (X, Y).
Velocity (m/s, NED) is derived from the stream function with the divergence-free convention

    v_north = -speed_scale * dpsi/dY,    v_east = +speed_scale * dpsi/dX

(the paper prints U = dpsi/dy, V = dpsi/dx, which is not divergence-free). The partial
derivatives are analytic. The jet flows north along its axis Y = B cos(k X).
"""

from __future__ import annotations

import math

import numpy as np
import numpy.typing as npt

from common.current_params import CurrentParams


class CurrentField:
    """Analytic current of eq. (13) with the constants of ``[current]``."""

    def __init__(self, params: CurrentParams) -> None:
        self.enabled = bool(params.enabled)
        self.b, self.c, self.k = params.b, params.c, params.k_u
        self.omega, self.e, self.theta_u = params.omega, params.e, params.theta_u
        self.sc, self.time_scale, self.speed_scale = params.sc, params.time_scale, params.speed_scale
        self.origin_x, self.origin_y = params.origin_x, params.origin_y

    def stream_function(self, x: npt.ArrayLike, y: npt.ArrayLike, t: npt.ArrayLike) -> np.ndarray:
        """Non-dimensional stream function psi of eq. (13) at NED metres x, y and time t (s)."""
        X = self.sc * (np.asarray(x, float) - self.origin_x)
        Y = self.sc * (np.asarray(y, float) - self.origin_y)
        T = self.time_scale * np.asarray(t, float)
        B = self.b + self.e * np.cos(self.omega * T + self.theta_u)
        theta = self.k * (X - self.c * T)
        phi = (Y - B * np.cos(theta)) / np.sqrt(1.0 + self.k ** 2 * B ** 2 * np.sin(theta) ** 2)
        return 1.0 - np.tanh(phi)

    def velocity_at(self, x: float, y: float, t: float) -> tuple[float, float]:
        """Current (north, east) in m/s at one point: the scalar hot path (plain floats)."""
        if not self.enabled:
            return 0.0, 0.0
        k = self.k
        X = self.sc * (x - self.origin_x)
        Y = self.sc * (y - self.origin_y)
        T = self.time_scale * t
        B = self.b + self.e * math.cos(self.omega * T + self.theta_u)
        theta = k * (X - self.c * T)
        s, co = math.sin(theta), math.cos(theta)
        den = math.sqrt(1.0 + k * k * B * B * s * s)
        num = Y - B * co
        phi = num / den
        if abs(phi) > 40.0:  # sech^2 underflows: far outside the jet
            return 0.0, 0.0
        sech2 = 1.0 / math.cosh(phi) ** 2
        dphi_dY = 1.0 / den
        dphi_dX = B * k * s / den - num * k ** 3 * B * B * s * co / den ** 3
        # dpsi/d. = -sech^2(phi) dphi/d.
        return self.speed_scale * sech2 * dphi_dY, -self.speed_scale * sech2 * dphi_dX

    def velocity(self, x: npt.ArrayLike, y: npt.ArrayLike, t: npt.ArrayLike) -> tuple[np.ndarray, np.ndarray]:
        """Vectorised current (north, east) in m/s for numpy arrays x, y (m) and t (s)."""
        x, y, t = np.broadcast_arrays(np.asarray(x, float), np.asarray(y, float), np.asarray(t, float))
        if not self.enabled:
            return np.zeros(x.shape), np.zeros(x.shape)
        k = self.k
        X = self.sc * (x - self.origin_x)
        Y = self.sc * (y - self.origin_y)
        T = self.time_scale * t
        B = self.b + self.e * np.cos(self.omega * T + self.theta_u)
        theta = k * (X - self.c * T)
        s, co = np.sin(theta), np.cos(theta)
        den = np.sqrt(1.0 + k * k * B * B * s * s)
        num = Y - B * co
        phi = np.clip(num / den, -40.0, 40.0)
        sech2 = 1.0 / np.cosh(phi) ** 2
        dphi_dY = 1.0 / den
        dphi_dX = B * k * s / den - num * k ** 3 * B * B * s * co / den ** 3
        return self.speed_scale * sech2 * dphi_dY, -self.speed_scale * sech2 * dphi_dX
