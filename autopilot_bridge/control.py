"""Control: heading PID, speed by pole placement, and thrust allocation to the two propellers.

As on the paper's platform (section 4.2): a PID controls the heading and pole placement the
linear speed. Their outputs are the surge force ``tau_u`` (N) and the yaw moment ``tau_r`` (N m);
the allocation inverts ``tau`` of eq. (3),

    tau_u = T_port + T_stdb,    tau_r = (T_port - T_stdb) * B_u / 2,

and saturates to [T_min, T_max] per propeller, keeping the yaw moment first (a boat that cannot
turn cannot avoid anything) and giving up surge force when both do not fit. Commands leave
normalised to the simulator's [-1, 1]: u >= 0 means u * T_max, u < 0 means |u| * T_min.

Frames: NED, heading clockwise from north, positive yaw moment turns to starboard.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from autopilot_bridge.angles import wrap_angle
from autopilot_bridge.parameters import Tunable
from common.params import param


@dataclass(frozen=True)
class ControlParams:
    """Gains of the heading and speed controllers (the [control] TOML section)."""

    heading_kp: float = param("heading PID proportional gain (HDG_KP: at least 20, else the boat cannot steer)",
                              "N m/rad", ge=20, le=1000)
    heading_ki: float = param("heading PID integral gain (HDG_KI)", "N m/(rad s)", ge=0, le=200)
    heading_kd: float = param("heading PID derivative gain (on the measured yaw rate; HDG_KD)", "N m s/rad", ge=0,
                              le=500)
    heading_integral_limit: float = param("anti-windup bound on the integral's yaw moment", "N m", ge=0)
    heading_rate_feedforward: float = param(
        "yaw moment per rad/s of the path's turn rate (u times its curvature) added to the PID: the yaw damping a "
        "steady turn must overcome (d_r); 0 = none", "N m s/rad", ge=0)
    speed_bandwidth: float = param("speed loop natural frequency omega_n (closed-loop poles; SPD_BANDWIDTH)", "rad/s",
                                   ge=0.05, le=5)
    speed_damping: float = param("speed loop damping ratio zeta", gt=0)
    speed_integral_limit: float = param("anti-windup bound on the speed integral's force", "N", ge=0)
    speed_reference_time_constant: float = param("first-order reference model of the speed set-point", "s", gt=0)
    max_acceleration: float = param("acceleration limit of the speed reference model", "m/s^2", gt=0)


@dataclass(frozen=True)
class SurgeModel:
    """The nominal surge dynamics of eq. (4) used by the speed controller (vessel computer's model)."""

    m11: float      # kg, surge inertia incl. added mass, eq. (5)
    m22: float      # kg, sway inertia, eq. (5)
    d_u: float      # kg/s, linear surge damping; d_u2 = 0.2 d_u, d_u3 = 0.1 d_u

    @classmethod
    def from_hull(cls, m: float, rho: float, D: float, L: float, d_u: float) -> SurgeModel:
        """The nominal model from the hull's configured numbers ([vessel]: mass m (kg), water
        density rho (kg/m^3), draught D (m), length L (m), damping d_u (kg/s)), by eq. (5)'s first
        two rows: m11 = 1.05 m, m22 = m + 0.5 rho pi D^2 L. The vessel computer's own reading of
        the paper; the simulator keeps its truth model to itself."""
        return cls(m11=1.05 * m, m22=m + 0.5 * rho * math.pi * D * D * L, d_u=d_u)

    def damping(self, u: float) -> float:
        """Surge damping force of eq. (4) at speed ``u`` (N)."""
        return self.d_u * (u + 0.2 * abs(u) * u + 0.1 * u * u * u)


class HeadingPID:
    """PID on the wrapped heading error; derivative on the measured yaw rate (no set-point kick).

    Its gains are its own parameters (initial values from [control]; a ground station tunes them)."""

    # At least 20 N m/rad: with none the boat cannot steer (a chaos GCS set 0 and the boat hit a quay).
    kp = Tunable("HDG_KP", 20.0, 1000.0, "N m/rad", "heading PID proportional gain")
    ki = Tunable("HDG_KI", 0.0, 200.0, "N m/(rad s)", "heading PID integral gain")
    kd = Tunable("HDG_KD", 0.0, 500.0, "N m s/rad", "heading PID derivative gain (on the measured yaw rate)")

    def __init__(self, p: ControlParams) -> None:
        self.p = p
        self.kp, self.ki, self.kd = p.heading_kp, p.heading_ki, p.heading_kd
        self.integral = 0.0

    def reset(self) -> None:
        self.integral = 0.0

    def update(self, psi_ref: float, psi: float, r: float, dt: float, r_ref: float = 0.0) -> float:
        """Yaw moment (N m) to steer heading ``psi`` (rad) to ``psi_ref`` given yaw rate ``r`` (rad/s).

        ``r_ref`` is the turn rate the reference itself moves at (u times the path's curvature):
        without its feed-forward ``heading_rate_feedforward * r_ref`` (and with the derivative on
        ``r`` alone) a steady turn at r costs a heading error of (d_r + Kd) r / Kp, 0.4 rad at
        0.3 rad/s, and the vessel swings wide of every bend of the path."""
        e = wrap_angle(psi_ref - psi)
        if self.ki > 0.0 and dt > 0.0:
            self.integral += self.ki * e * dt
            lim = self.p.heading_integral_limit
            self.integral = min(max(self.integral, -lim), lim)
        return self.kp * e + self.integral + self.kd * (r_ref - r) \
            + self.p.heading_rate_feedforward * r_ref


class SpeedController:
    """Surge speed by feedback linearisation and pole placement, behind a reference model.

    A first-order, acceleration-limited reference model turns the set-point ``u_ref`` into a smooth
    desired speed ``u_d`` with derivative ``du_d`` (Fossen's reference models: a step set-point would
    otherwise excite the zero of the integral action and overshoot). With ``e = u - u_d`` and

        tau_u = D(u) - m22 v r + m11 (du_d - 2 zeta omega e - omega^2 I),   I = integral of e,

    the surge row of eq. (4) closes to ``e'' + 2 zeta omega e' + omega^2 e = 0`` (disturbances
    aside, which the integral removes): poles at ``-zeta omega +- omega sqrt(zeta^2 - 1)``.
    """

    bandwidth = Tunable("SPD_BANDWIDTH", 0.05, 5.0, "rad/s", "speed loop natural frequency (closed-loop poles)")

    def __init__(self, p: ControlParams, model: SurgeModel) -> None:
        self.p, self.model = p, model
        self.bandwidth = p.speed_bandwidth
        self.integral = 0.0
        self.u_d: float | None = None

    def reset(self, u: float | None = None) -> None:
        self.integral = 0.0
        self.u_d = u

    def limit_reference(self, bound: float) -> None:
        """Bring the reference model's speed within +-``bound`` (m/s) now, not at its acceleration limit: the
        speed error then brakes at once (simple avoidance: an obstacle within the stopping distance)."""
        if self.u_d is not None:
            self.u_d = min(max(self.u_d, -bound), bound)

    def update(self, u_ref: float, u: float, v: float, r: float, dt: float, u_current: float = 0.0) -> float:
        """Surge force (N) to bring surge speed over ground ``u`` (m/s) to the set-point ``u_ref``.

        ``u_current`` (m/s): the current's component along the bow, when known
        (:mod:`autopilot_bridge.current_estimate`): the hull's drag is that of its speed through the
        water, ``u - u_current``, so the feed-forward holds a speed over ground against the stream
        instead of leaving it to the bounded integral."""
        m, w, z = self.model, self.bandwidth, self.p.speed_damping
        if self.u_d is None:
            self.u_d = u
        du_d = (u_ref - self.u_d) / self.p.speed_reference_time_constant
        du_d = min(max(du_d, -self.p.max_acceleration), self.p.max_acceleration)
        self.u_d += du_d * dt
        e = u - self.u_d
        if dt > 0.0:
            self.integral += e * dt
            lim = self.p.speed_integral_limit / max(m.m11 * w * w, 1e-9)
            self.integral = min(max(self.integral, -lim), lim)
        return m.damping(u - u_current) - m.m22 * v * r + m.m11 * (du_d - 2.0 * z * w * e - w * w * self.integral)


@dataclass(frozen=True)
class Thrust:
    """Allocated propeller thrusts (N) and the normalised commands sent to the simulator."""

    port: float
    stdb: float
    port_cmd: float
    stdb_cmd: float
    saturated: bool


def clearance_speed_cap(clearance: float, inner: float, outer: float, v_min: float, v_max: float) -> float:
    """Speed cap (m/s) at ``clearance`` m from the nearest obstacle: ``v_max`` from ``outer`` on,
    falling linearly to ``v_min`` at ``inner`` (and below); no cap when ``outer <= inner``."""
    if outer <= inner:
        return math.inf
    f = min(max((clearance - inner) / (outer - inner), 0.0), 1.0)
    return v_min + f * (v_max - v_min)


def stopping_speed_cap(distance: float, speed: float, arrival: float, deceleration: float, lag: float) -> float:
    """Speed cap (m/s) ``distance`` m before the point where the boat must be down to ``arrival`` m/s,
    braking at ``deceleration`` m/s^2: ``sqrt(arrival^2 + 2 a d)``, with ``d`` the distance less what the
    present ``speed`` covers in the speed loop's ``lag`` s (its reference model follows a set-point that late)."""
    d = max(distance - max(speed, 0.0) * lag, 0.0)
    return math.sqrt(arrival * arrival + 2.0 * deceleration * d)


def heading_error_speed_cap(error: float, angle: float, v_min: float, v_max: float) -> float:
    """Speed cap (m/s) for a heading error of ``error`` rad (any multiple of 2 pi): ``v_max`` within
    ``angle`` rad, ``v_min`` beyond it, where the boat must turn sharply and the turning circle
    shrinks with the speed (u / r at the yaw rate the thrusters give)."""
    return v_max if abs(wrap_angle(error)) <= angle else v_min


def normalise(thrust: float, t_max: float, t_min: float) -> float:
    """Thrust (N) to the simulator's command in [-1, 1] (u >= 0: u T_max; u < 0: |u| T_min)."""
    if thrust >= 0.0:
        return min(thrust / t_max, 1.0)
    return -min(thrust / t_min, 1.0)


def allocate(tau_u: float, tau_r: float, b_u: float, t_max: float, t_min: float) -> Thrust:
    """Invert tau of eq. (3) and saturate, keeping the yaw moment before the surge force.

    The differential ``delta = T_port - T_stdb = 2 tau_r / B_u`` is limited first to what the
    propellers can produce at all (``T_max - T_min``); the common part ``tau_u / 2`` is then
    clipped to the interval that keeps both propellers inside [T_min, T_max].
    """
    delta = 2.0 * tau_r / b_u
    span = t_max - t_min
    saturated = False
    if abs(delta) > span:
        delta = math.copysign(span, delta)
        saturated = True
    mean = tau_u / 2.0
    lo = t_min + abs(delta) / 2.0
    hi = t_max - abs(delta) / 2.0
    if mean < lo or mean > hi:
        mean = min(max(mean, lo), hi)
        saturated = True
    port, stdb = mean + delta / 2.0, mean - delta / 2.0
    return Thrust(port, stdb, normalise(port, t_max, t_min), normalise(stdb, t_max, t_min), saturated)
