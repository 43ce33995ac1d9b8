"""The collision cone of eqs. (9)-(10) (Wen et al. 2019, section 3.3; Chakravarthy & Ghose 1998).

O is the USV, F the dynamic obstacle, r = |OF| and theta the direction of OF. With the USV's
velocity V_O along alpha and the obstacle's V_F along beta, eq. (9) splits the obstacle's velocity
relative to the USV into the component along OF (V_r, negative while closing) and across it
(V_theta)::

    V_theta = V_F sin(beta - theta) - V_O sin(alpha - theta)
    V_r     = V_F cos(beta - theta) - V_O cos(alpha - theta)

and eq. (10) says the two may collide (the relative velocity points into the cone of the
tangents from O to the disc of radius R about F, R = the sum of the influence radii) if

    V_theta = 0 and V_r < 0,   or
    V_theta != 0 and V_r < 0 and r^2 V_theta^2 <= R^2 (V_r^2 + V_theta^2).

The paper's text calls alpha and beta "the angles of V_F and V_r"; the formula (and Chakravarthy
& Ghose's, from which it is taken) needs alpha = direction of V_O and beta = direction of V_F,
which is what is used here. Angles only need one consistent convention: with positions and
velocities given as vectors, theta, alpha and beta are ``atan2(second, first)`` of them, so the
functions work in NED (north, east) and in the planner's map frame (east, north) alike.

Under constant velocities the closest point of approach follows from the same components: the
time to it is TCPA = -r V_r / (V_r^2 + V_theta^2) and the distance DCPA = r |V_theta| / |V_rel|,
so eq. (10)'s second condition is DCPA <= R while closing. Pure numpy/math, no state.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np


def cone_components(r: float, theta: float, v_o: float, alpha: float, v_f: float, beta: float) -> tuple[float, float]:
    """Eq. (9): (V_theta, V_r) in m/s from speeds (m/s) and directions (rad)."""
    v_theta = v_f * math.sin(beta - theta) - v_o * math.sin(alpha - theta)
    v_r = v_f * math.cos(beta - theta) - v_o * math.cos(alpha - theta)
    return v_theta, v_r


def on_collision_course(r: float, v_theta: float, v_r: float, radius: float, tol: float = 1e-9) -> bool:
    """Eq. (10) for range ``r`` (m), components (m/s) and combined radius R (m).

    ``tol`` (m/s) is the magnitude below which V_theta counts as zero (floating point)."""
    if not v_r < 0.0:
        return False
    if abs(v_theta) <= tol:
        return True
    return r * r * v_theta * v_theta <= radius * radius * (v_r * v_r + v_theta * v_theta)


@dataclass(frozen=True)
class ConeAssessment:
    """Eqs. (9)-(10) for one own-ship/obstacle pair, with the closest point of approach."""

    r: float               # m, current range |OF|
    theta: float           # rad, direction of OF
    v_theta: float         # m/s, eq. (9)
    v_r: float             # m/s, eq. (9)
    collision: bool        # eq. (10)
    tcpa: float            # s until the closest approach (0 if opening or no relative motion)
    dcpa: float            # m, distance at the closest approach (r if opening)
    inside: bool           # r <= R now: already within the combined radius


def assess(own_pos: tuple[float, float], own_vel: tuple[float, float], obs_pos: tuple[float, float],
           obs_vel: tuple[float, float], radius: float) -> ConeAssessment:
    """Eqs. (9)-(10) from positions (m) and velocity vectors (m/s) in one frame; R = ``radius``."""
    ox, oy = float(own_pos[0]), float(own_pos[1])
    fx, fy = float(obs_pos[0]), float(obs_pos[1])
    dx, dy = fx - ox, fy - oy
    r = math.hypot(dx, dy)
    theta = math.atan2(dy, dx)
    v_o, alpha = math.hypot(own_vel[0], own_vel[1]), math.atan2(own_vel[1], own_vel[0])
    v_f, beta = math.hypot(obs_vel[0], obs_vel[1]), math.atan2(obs_vel[1], obs_vel[0])
    v_theta, v_r = cone_components(r, theta, v_o, alpha, v_f, beta)
    v2 = v_r * v_r + v_theta * v_theta
    if v_r < 0.0 and v2 > 0.0:
        tcpa = -r * v_r / v2
        dcpa = r * abs(v_theta) / math.sqrt(v2)
    else:
        tcpa, dcpa = 0.0, r
    return ConeAssessment(r, theta, v_theta, v_r, on_collision_course(r, v_theta, v_r, radius), tcpa, dcpa,
                          r <= radius)


def cone_half_angle(r: float, radius: float) -> float:
    """Half-angle (rad) of the cone of tangents from O to the disc of ``radius`` at range ``r``
    (pi/2 when O is inside the disc)."""
    return math.pi / 2.0 if r <= radius else math.asin(radius / r)


def cpa_series(rel_pos: np.ndarray, rel_vel: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Vectorised TCPA (s, clipped at 0) and DCPA (m) for (N, 2) relative positions/velocities."""
    rel_pos = np.asarray(rel_pos, dtype=float).reshape(-1, 2)
    rel_vel = np.asarray(rel_vel, dtype=float).reshape(-1, 2)
    v2 = np.sum(rel_vel * rel_vel, axis=1)
    t = np.where(v2 > 1e-12, -np.sum(rel_pos * rel_vel, axis=1) / np.maximum(v2, 1e-12), 0.0)
    t = np.maximum(t, 0.0)
    d = np.hypot(*(rel_pos + rel_vel * t[:, None]).T)
    return t, d
