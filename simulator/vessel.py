"""The 3-DOF twin-propeller USV of Wen et al. (2019), eqs. (2)-(5), as a plain-float model.

State s = (x, y, psi, u, v, r): x north, y east (m), heading psi clockwise from north (rad),
surge u, sway v (m/s, body axes, over ground) and yaw rate r (rad/s).

Water-relative formulation (Fossen 2011, ch. 10.3): eq. (4)'s Coriolis and damping terms act on
the velocity relative to the water nu_r = nu - nu_c, where nu_c is the current (north, east)
rotated into the body frame; the kinematics (2) move the vessel with nu over ground. For a
current that is constant in NED over a step, d(nu_c)/dt = (r v_c, -r u_c, 0), so
nu_dot = nu_r_dot + (r v_c, -r u_c, 0). With no current this is eq. (4) exactly.

Correction of a sign typo: the paper prints v_dot = +(m11/m22) u r. With u_dot = +(m22/m11) v r
and r_dot = ((m11 - m22)/m33) u v as printed, the Coriolis forces do work unless the sway term is
-(m11/m22) u r (Fossen's standard form, used here): u m22 v r - v m11 u r + r (m11 - m22) u v = 0.

Plain floats and ``math`` on tuples, compiled by numba: numpy's per-call overhead dominates on
6-element states (see ``hil bench sim``), and the simulator's step is on the lockstep loop's
critical path. :func:`hull_dynamics` is the equations; :func:`hull_rk4_step` one RK4 step of them,
the same operations in the same order as ``simulator.integrator.rk4_step`` (bit for bit,
tests/test_sim_vessel.py). Both live in this file so that numba's cache, which follows a function's
own file, never pairs a changed equation with a stale integrator.
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

from numba import njit

if TYPE_CHECKING:
    from simulator.config import VesselParams

State = tuple[float, float, float, float, float, float]
Coefficients = tuple[float, float, float, float, float, float, float, float, float, float, float, float]


@njit(cache=True)
def hull_dynamics(s: State, tau: tuple[float, float, float], tau_w: tuple[float, float, float],
                  current: tuple[float, float], k: Coefficients) -> State:
    """Time derivative of the state, eqs. (2) and (4).

    ``tau`` propulsion (N, N, N m, body), ``tau_w`` wave forces of eq. (6) (body), ``current``
    (north, east) velocity of the water in m/s; ``k`` = (m11, m22, m33, d_u, d_u2, d_u3, d_v, d_v2,
    d_v3, d_r, d_r2, d_r3) (:attr:`Vessel.coefficients`).
    """
    x, y, psi, u, v, r = s
    m11, m22, m33, d_u, d_u2, d_u3, d_v, d_v2, d_v3, d_r, d_r2, d_r3 = k
    c, sn = math.cos(psi), math.sin(psi)
    uc = c * current[0] + sn * current[1]
    vc = -sn * current[0] + c * current[1]
    ur, vr = u - uc, v - vc
    # eq. (2) / first three rows of eq. (4): kinematics over ground
    x_dot = u * c - v * sn
    y_dot = u * sn + v * c
    psi_dot = r
    # eq. (4), rows 4-6, on the water-relative velocity (sway Coriolis sign corrected)
    ur_dot = (m22 / m11) * vr * r - (d_u / m11) * ur \
        - (d_u2 / m11) * abs(ur) * ur - (d_u3 / m11) * ur * ur * ur \
        + tau[0] / m11 + tau_w[0] / m11
    vr_dot = -(m11 / m22) * ur * r - (d_v / m22) * vr \
        - (d_v2 / m22) * abs(vr) * vr - (d_v3 / m22) * vr * vr * vr \
        + tau[1] / m22 + tau_w[1] / m22
    r_dot = ((m11 - m22) / m33) * ur * vr - (d_r / m33) * r \
        - (d_r2 / m33) * abs(r) * r - (d_r3 / m33) * r * r * r \
        + tau[2] / m33 + tau_w[2] / m33
    # nu = nu_r + nu_c, with nu_c rotating with the hull
    return (x_dot, y_dot, psi_dot, ur_dot + r * vc, vr_dot - r * uc, r_dot)


@njit(cache=True)
def _stage(s: State, h: float, d: State) -> State:
    return (s[0] + h * d[0], s[1] + h * d[1], s[2] + h * d[2], s[3] + h * d[3], s[4] + h * d[4], s[5] + h * d[5])


@njit(cache=True)
def hull_rk4_step(s: State, dt: float, tau: tuple[float, float, float], tau_w: tuple[float, float, float],
                  current: tuple[float, float], k: Coefficients) -> State:
    """One classic RK4 step of :func:`hull_dynamics` with the inputs held over ``dt`` (s)."""
    k1 = hull_dynamics(s, tau, tau_w, current, k)
    k2 = hull_dynamics(_stage(s, 0.5 * dt, k1), tau, tau_w, current, k)
    k3 = hull_dynamics(_stage(s, 0.5 * dt, k2), tau, tau_w, current, k)
    k4 = hull_dynamics(_stage(s, dt, k3), tau, tau_w, current, k)
    w = dt / 6.0
    return (s[0] + w * (k1[0] + 2.0 * k2[0] + 2.0 * k3[0] + k4[0]),
            s[1] + w * (k1[1] + 2.0 * k2[1] + 2.0 * k3[1] + k4[1]),
            s[2] + w * (k1[2] + 2.0 * k2[2] + 2.0 * k3[2] + k4[2]),
            s[3] + w * (k1[3] + 2.0 * k2[3] + 2.0 * k3[3] + k4[3]),
            s[4] + w * (k1[4] + 2.0 * k2[4] + 2.0 * k3[4] + k4[4]),
            s[5] + w * (k1[5] + 2.0 * k2[5] + 2.0 * k3[5] + k4[5]))


class Vessel:
    """Parameters of eqs. (4)-(5) and the dynamics; ``params`` has the fields of ``[vessel]``."""

    def __init__(self, params: VesselParams) -> None:
        p = params
        self.params = p
        # eq. (5): inertia including added mass
        self.m11 = p.m + 0.05 * p.m
        self.m22 = p.m + 0.5 * (p.rho * math.pi * p.D ** 2 * p.L)
        self.m33 = (0.083 * p.m * (p.L ** 2 + p.W ** 2)
                    + 0.042 * (0.1 * p.m * p.B_u ** 2 + p.rho * math.pi * p.D ** 2 * p.L ** 3))
        # damping: d_x2 = 0.2 d_x, d_x3 = 0.1 d_x (section 2.3, after eq. (5))
        self.d_u, self.d_v, self.d_r = p.d_u, p.d_v, p.d_r
        self.d_u2, self.d_v2, self.d_r2 = 0.2 * p.d_u, 0.2 * p.d_v, 0.2 * p.d_r
        self.d_u3, self.d_v3, self.d_r3 = 0.1 * p.d_u, 0.1 * p.d_v, 0.1 * p.d_r
        self.B_u, self.T_max, self.T_min = p.B_u, p.T_max, p.T_min
        self.coefficients: Coefficients = _floats((self.m11, self.m22, self.m33, self.d_u, self.d_u2, self.d_u3,
                                                   self.d_v, self.d_v2, self.d_v3, self.d_r, self.d_r2, self.d_r3))

    # -- actuators -------------------------------------------------------------------------
    def thrust(self, control: float) -> float:
        """Thrust (N) of one propeller for a normalised command in [-1, 1].

        u >= 0 maps to u * T_max, u < 0 to |u| * T_min (T_min <= 0 is the largest reverse
        thrust); the result is saturated to [T_min, T_max].
        """
        t = control * self.T_max if control >= 0.0 else -control * self.T_min
        return min(self.T_max, max(self.T_min, t))

    def propulsion(self, T_port: float, T_stdb: float) -> tuple[float, float, float]:
        """tau = [T_port + T_stdb, 0, (T_port - T_stdb) B_u / 2] (section 2.3, after eq. (3)).

        More port thrust gives a positive (clockwise, starboard) yaw moment in NED.
        """
        return T_port + T_stdb, 0.0, (T_port - T_stdb) * self.B_u / 2.0

    # -- eqs. (2) and (4) ------------------------------------------------------------------
    def dynamics(self, s: State, tau: tuple[float, float, float], tau_w: tuple[float, float, float],
                 current: tuple[float, float]) -> State:
        """Time derivative of the state (:func:`hull_dynamics` with this hull's coefficients)."""
        return hull_dynamics(_floats(s), _floats(tau), _floats(tau_w), _floats(current), self.coefficients)

    def surge_speed_for(self, tau_u: float) -> float:
        """Steady surge speed (m/s) of eq. (4) for a constant surge force (no current, v = r = 0)."""
        lo, hi = -100.0, 100.0
        for _ in range(200):
            mid = 0.5 * (lo + hi)
            f = self.d_u * mid + self.d_u2 * abs(mid) * mid + self.d_u3 * mid ** 3 - tau_u
            lo, hi = (mid, hi) if f < 0 else (lo, mid)
        return 0.5 * (lo + hi)


def _floats(t: tuple) -> tuple:
    """The tuple as floats: one compiled signature, whatever numbers a caller passed."""
    return tuple(float(a) for a in t)
