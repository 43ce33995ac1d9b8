"""Heading PID, pole-placement speed control, thrust allocation and LOS guidance."""

from __future__ import annotations

import math

import numpy as np
import pytest

from autopilot_bridge.control import (
    ControlParams,
    HeadingPID,
    SpeedController,
    SurgeModel,
    allocate,
    normalise,
)
from autopilot_bridge.guidance import LineOfSight

T_MAX, T_MIN, B_U = 119.68, -66.71, 0.79
MODEL = SurgeModel(m11=57.75, m22=112.82, d_u=31.915)


def params(**kw) -> ControlParams:
    base = dict(heading_kp=40.0, heading_ki=2.0, heading_kd=30.0, heading_integral_limit=10.0,
                heading_rate_feedforward=0.0,
                speed_bandwidth=1.0, speed_damping=1.0, speed_integral_limit=40.0,
                speed_reference_time_constant=2.0, max_acceleration=0.5)
    base.update(kw)
    return ControlParams(**base)


@pytest.mark.parametrize("tau_u, tau_r", [(100.0, 5.0), (-20.0, -3.0), (0.0, 10.0), (150.0, -20.0)])
def test_allocation_inverts_eq3_when_feasible(tau_u, tau_r):
    t = allocate(tau_u, tau_r, B_U, T_MAX, T_MIN)
    assert not t.saturated
    assert t.port + t.stdb == pytest.approx(tau_u)
    assert (t.port - t.stdb) * B_U / 2 == pytest.approx(tau_r)


def test_saturation_keeps_yaw_moment_before_surge_force():
    # Full ahead plus a hard turn: both cannot fit; the yaw moment must survive intact.
    t = allocate(2 * T_MAX, 30.0, B_U, T_MAX, T_MIN)
    assert t.saturated
    assert (t.port - t.stdb) * B_U / 2 == pytest.approx(30.0)
    assert T_MIN - 1e-9 <= t.stdb <= t.port <= T_MAX + 1e-9
    # An impossible yaw moment is limited to the largest the propellers can make.
    t = allocate(0.0, 1e4, B_U, T_MAX, T_MIN)
    assert t.port == pytest.approx(T_MAX) and t.stdb == pytest.approx(T_MIN)


def test_normalised_commands_follow_the_simulator_convention():
    assert normalise(T_MAX, T_MAX, T_MIN) == 1.0
    assert normalise(T_MAX / 2, T_MAX, T_MIN) == pytest.approx(0.5)
    assert normalise(T_MIN, T_MAX, T_MIN) == -1.0
    assert normalise(T_MIN / 4, T_MAX, T_MIN) == pytest.approx(-0.25)
    assert normalise(10 * T_MAX, T_MAX, T_MIN) == 1.0


def test_heading_pid_turns_the_short_way_across_north():
    pid = HeadingPID(params(heading_ki=0.0))
    # At 350 deg wanting 10 deg: turn to starboard (positive moment), not 340 deg the other way.
    assert pid.update(math.radians(10), math.radians(350), 0.0, 0.01) > 0
    assert pid.update(math.radians(350), math.radians(10), 0.0, 0.01) < 0


def _surge_sim(ctrl: SpeedController, u_ref: float, seconds: float, dt: float = 0.01, disturbance: float = 0.0):
    u, us = 0.0, []
    for _ in range(int(seconds / dt)):
        tau = allocate(ctrl.update(u_ref, u, 0.0, 0.0, dt), 0.0, B_U, T_MAX, T_MIN)
        force = tau.port + tau.stdb
        # Eq. (4), surge row, straight line (v = r = 0), integrated by explicit Euler at 100 Hz.
        u += dt * (-MODEL.damping(u) + force + disturbance) / MODEL.m11
        us.append(u)
    return np.array(us)


def test_speed_step_follows_the_reference_model_without_overshoot():
    ctrl = SpeedController(params(), MODEL)
    us = _surge_sim(ctrl, 1.5, 20.0)
    assert us[-1] == pytest.approx(1.5, abs=0.01)
    assert us.max() < 1.5 * 1.02
    # Reference model: 0.5 m/s^2 ramp, then a 2 s first-order approach: 90% after ~4 s.
    t90 = np.argmax(us >= 0.9 * 1.5) * 0.01
    assert 3.0 < t90 < 6.0, t90


def test_speed_tracking_error_decays_with_the_placed_poles():
    # With the reference already at the set-point (u_d = u_ref) and zero integral, the closed loop
    # e'' + 2 omega e' + omega^2 e = 0 starts at e(0) = e0, e'(0) = -2 omega e0, so
    # e(t) = e0 (1 - omega t) exp(-omega t).
    omega = 0.8
    ctrl = SpeedController(params(speed_bandwidth=omega), MODEL)
    ctrl.reset(u=1.5)
    dt, u = 0.001, 1.2
    for k in range(1, 3001):
        tau = ctrl.update(1.5, u, 0.0, 0.0, dt)  # unsaturated: stay in the model's linear regime
        u += dt * (-MODEL.damping(u) + tau) / MODEL.m11
        if k % 1000 == 0:
            t = k * dt
            expected = -0.3 * (1 - omega * t) * math.exp(-omega * t)
            assert u - 1.5 == pytest.approx(expected, abs=0.002), t


def test_speed_integral_removes_a_constant_disturbance():
    ctrl = SpeedController(params(), MODEL)
    us = _surge_sim(ctrl, 1.5, 40.0, disturbance=-15.0)  # a head current's drag, say
    assert us[-1] == pytest.approx(1.5, abs=0.01)


def test_los_cross_track_sign_and_convergence():
    path = np.array([[0.0, 0.0], [100.0, 0.0]])  # due north
    los = LineOfSight(path, lookahead=5.0, acceptance_radius=2.0)
    g = los.update(10.0, 3.0)  # 3 m east = starboard of a northbound path
    assert g.cross_track == pytest.approx(3.0)
    assert g.heading < 0  # steer to port, back towards the path
    # Kinematic vessel steering perfectly to the LOS heading converges on the path and finishes.
    x, y = 0.0, 8.0
    for _ in range(2000):
        g = los.update(x, y)
        if g.finished:
            break
        x += 0.1 * math.cos(g.heading)
        y += 0.1 * math.sin(g.heading)
    assert g.finished
    assert abs(y) < 0.5


def test_los_progress_never_skips_back():
    # A hairpin: the way back passes near the way out; progress must follow the path in order.
    path = np.array([[0.0, 0.0], [50.0, 0.0], [50.0, 4.0], [0.0, 4.0]])
    los = LineOfSight(path, lookahead=3.0, acceptance_radius=1.0)
    los.update(40.0, 0.5)
    assert los.index == 0
    los.update(49.0, 2.0)
    los.update(45.0, 3.9)
    assert los.index == 2
    los.update(20.0, 1.0)  # closer to the outbound leg now, but that leg is behind us
    assert los.index == 2


def test_los_rejects_degenerate_paths():
    with pytest.raises(ValueError):
        LineOfSight(np.array([[0.0, 0.0]]), 5.0, 1.0)
    with pytest.raises(ValueError):
        LineOfSight(np.array([[1.0, 1.0], [1.0, 1.0]]), 5.0, 1.0)


@pytest.mark.parametrize("turn", [+1.0, -1.0])
def test_guidance_reports_the_signed_curvature_of_a_bend(turn):
    """A 5 m radius arc to starboard (+1) or port (-1), sampled every 0.5 m as the Dubins paths are."""
    th = np.arange(0.0, np.pi / 2, 0.5 / 5.0)
    # heading north at the start; a starboard turn bends towards east
    path = np.column_stack([5.0 * np.sin(th), turn * 5.0 * (1.0 - np.cos(th))])
    los = LineOfSight(path, lookahead=3.0, acceptance_radius=1.0)
    g = los.update(*path[8])
    assert g.curvature == pytest.approx(turn / 5.0, rel=0.05)
    straight = LineOfSight(np.array([[0.0, 0.0], [10.0, 0.0], [20.0, 0.0]]), 3.0, 1.0)
    assert straight.update(5.0, 0.0).curvature == 0.0


def test_yaw_rate_feedforward_holds_a_steady_turn_without_heading_error():
    """On heading with the reference turning at r_ref and the vessel turning with it, the PID adds
    nothing; the feed-forward alone supplies the yaw damping d_r r_ref of the turn."""
    pid = HeadingPID(params(heading_ki=0.0, heading_rate_feedforward=100.0))
    assert pid.update(0.3, 0.3, 0.3, 0.01, r_ref=0.3) == pytest.approx(30.0)
    plain = HeadingPID(params(heading_ki=0.0))
    assert plain.update(0.3, 0.3, 0.3, 0.01, r_ref=0.3) == pytest.approx(0.0)


@pytest.mark.parametrize("clearance, cap", [(10.0, 1.5), (4.0, 1.5), (3.0, 1.05), (2.0, 0.6), (0.5, 0.6)])
def test_speed_falls_linearly_near_obstacles(clearance, cap):
    from autopilot_bridge.control import clearance_speed_cap

    assert clearance_speed_cap(clearance, 2.0, 4.0, 0.6, 1.5) == pytest.approx(cap)
    assert clearance_speed_cap(clearance, 2.0, 2.0, 0.6, 1.5) == float("inf")


def test_the_nominal_surge_model_from_the_configuration_is_the_simulators_hull():
    """The vessel computer builds its model of eq. (5) from [vessel] without the simulator's class;
    on the default hull both readings of eq. (5) agree."""
    from autopilot_bridge.control import SurgeModel
    from hil import settings
    from simulator.vessel import Vessel

    hull = settings.load(None, []).vessel
    nominal = SurgeModel.from_hull(hull.m, hull.rho, hull.D, hull.L, hull.d_u)
    truth = Vessel(hull)
    assert nominal.m11 == pytest.approx(truth.m11, rel=1e-12)
    assert nominal.m22 == pytest.approx(truth.m22, rel=1e-12)


@pytest.mark.parametrize("error, cap", [(0.0, 1.5), (0.78, 1.5), (-0.78, 1.5), (0.80, 0.6), (-2.5, 0.6), (3.1, 0.6),
                                        (2.0 * math.pi - 0.1, 1.5), (-2.0 * math.pi + 0.1, 1.5)])
def test_a_heading_error_beyond_the_angle_turns_at_steerage_way(error, cap):
    from autopilot_bridge.control import heading_error_speed_cap
    assert heading_error_speed_cap(error, 0.785, 0.6, 1.5) == cap
