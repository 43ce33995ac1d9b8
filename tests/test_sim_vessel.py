"""The 3-DOF model of eqs. (2)-(5): inertia, steady state, integration accuracy, turning, Coriolis."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.integrate import solve_ivp
from scipy.optimize import brentq

from hil.assembly.simulator import simulator_settings
from hil.settings import load
from simulator.core import Command, SimulatorCore
from simulator.integrator import rk4_step
from simulator.vessel import Vessel, hull_dynamics, hull_rk4_step

CALM = ["waves.enabled=false", "current.enabled=false"]


@pytest.fixture(scope="module")
def cfg():
    return load(None, CALM)


def test_inertia_follows_eq5(cfg):
    p = cfg.vessel
    v = Vessel(p)
    assert v.m11 == pytest.approx(1.05 * p.m)
    assert v.m22 == pytest.approx(p.m + 0.5 * p.rho * np.pi * p.D ** 2 * p.L)
    # the figures quoted in configs/default.toml for the Otter
    assert v.m22 == pytest.approx(112.82, abs=0.01)
    assert v.m33 == pytest.approx(43.16, abs=0.01)


def test_thrust_mapping_and_saturation(cfg):
    v = Vessel(cfg.vessel)
    assert v.thrust(1.0) == pytest.approx(cfg.vessel.T_max)
    assert v.thrust(0.5) == pytest.approx(0.5 * cfg.vessel.T_max)
    assert v.thrust(-1.0) == pytest.approx(cfg.vessel.T_min)
    assert v.thrust(-0.5) == pytest.approx(0.5 * cfg.vessel.T_min)
    assert v.thrust(3.0) == pytest.approx(cfg.vessel.T_max)
    assert v.thrust(-3.0) == pytest.approx(cfg.vessel.T_min)


@pytest.mark.parametrize("command", [0.3, 0.7, 1.0, -0.6])
def test_steady_surge_speed_solves_surge_equation(cfg, command):
    core = SimulatorCore(simulator_settings(cfg))
    for _ in range(int(60 / core.frame_dt)):
        core.apply(Command(core.time_usec, command, command))
        core.step()
    p = cfg.vessel
    tau_u = 2 * (command * p.T_max if command >= 0 else -command * p.T_min)
    # eq. (4), u_dot = 0 with v = r = 0: d_u u + 0.2 d_u |u| u + 0.1 d_u |u|^2 u = tau_u
    root = brentq(lambda u: p.d_u * u + 0.2 * p.d_u * abs(u) * u + 0.1 * p.d_u * abs(u) ** 2 * u - tau_u, -50, 50)
    u = core.state[3]
    assert u == pytest.approx(root, rel=0.01)
    assert abs(core.state[4]) < 1e-9 and abs(core.state[5]) < 1e-9


def test_full_thrust_top_speed_is_3_m_s(cfg):
    v = Vessel(cfg.vessel)
    assert v.surge_speed_for(2 * cfg.vessel.T_max) == pytest.approx(3.0, rel=1e-3)


def _thrust_schedule(vessel: Vessel, t: float) -> tuple[float, float, float]:
    """A 60 s manoeuvre: accelerate, turn to starboard, reverse-differential turn to port, slow."""
    seg = int(t // 10)
    port, stdb = [(1.0, 1.0), (1.0, 0.4), (0.5, 0.5), (0.2, 0.8), (-0.5, 0.5), (0.3, 0.3)][min(seg, 5)]
    return vessel.propulsion(vessel.thrust(port), vessel.thrust(stdb))


def test_rk4_matches_solve_ivp_over_60s_manoeuvre(cfg):
    v = Vessel(cfg.vessel)
    tau_w, cur = (1.0, 2.0, 0.2), (0.3, -0.2)  # constant waves and current, to exercise every term
    dt = cfg.sim.dt
    s = (0.0, 0.0, 0.3, 0.0, 0.0, 0.0)
    ref = np.array(s)
    for seg in range(6):
        tau = _thrust_schedule(v, seg * 10.0)
        def f(s_, tau=tau):
            return v.dynamics(s_, tau, tau_w, cur)
        for _ in range(int(round(10.0 / dt))):
            s = rk4_step(f, s, dt)
        sol = solve_ivp(lambda t, y: f(tuple(y)), (0.0, 10.0), ref, method="DOP853", rtol=1e-11, atol=1e-11)
        ref = sol.y[:, -1]
    assert np.max(np.abs(np.array(s) - ref)) < 1e-3
    assert np.hypot(ref[0], ref[1]) > 20  # it really went somewhere


@pytest.mark.parametrize("port,stdb,sign", [(0.8, 0.4, 1), (0.4, 0.8, -1)])
def test_more_port_thrust_turns_to_starboard(cfg, port, stdb, sign):
    core = SimulatorCore(simulator_settings(cfg))
    for _ in range(300):
        core.apply(Command(core.time_usec, port, stdb))
        core.step()
    x, y, psi, u, v, r = core.state
    assert sign * r > 0.05
    assert sign * psi > 0.1  # heading clockwise from north grows: a starboard turn
    # heading north, a starboard turn moves the boat east
    assert sign * y > 0


def test_coriolis_does_no_work(cfg):
    v = Vessel(cfg.vessel)
    rng = np.random.default_rng(3)
    m11, m22, m33 = v.m11, v.m22, v.m33
    for u, vv, r in rng.normal(0, 2, (100, 3)):
        # the Coriolis terms of eq. (4) with the corrected sway sign, as forces/moments
        power = u * (m22 * vv * r) + vv * (-m11 * u * r) + r * ((m11 - m22) * u * vv)
        assert abs(power) < 1e-9
        # and they are what dynamics() uses: zero damping, zero inputs -> only Coriolis remains
    zero = Vessel(type("P", (), dict(vars(cfg.vessel), d_u=0.0, d_v=0.0, d_r=0.0))())
    s = (0.0, 0.0, 0.0, 1.5, -0.7, 0.4)
    d = zero.dynamics(s, (0, 0, 0), (0, 0, 0), (0, 0))
    kinetic_rate = m11 * s[3] * d[3] + m22 * s[4] * d[4] + m33 * s[5] * d[5]
    assert abs(kinetic_rate) < 1e-9


def test_current_moves_the_vessel_over_ground(cfg):
    """A hull drifting with a uniform current feels no water-relative force (water-relative dynamics)."""
    v = Vessel(cfg.vessel)
    cn, ce, psi = 0.4, -0.3, 1.1
    u = math.cos(psi) * cn + math.sin(psi) * ce
    vv = -math.sin(psi) * cn + math.cos(psi) * ce
    d = v.dynamics((5.0, 6.0, psi, u, vv, 0.0), (0, 0, 0), (0, 0, 0), (cn, ce))
    assert d[0] == pytest.approx(cn) and d[1] == pytest.approx(ce)
    assert d[3] == pytest.approx(0.0, abs=1e-12) and d[4] == pytest.approx(0.0, abs=1e-12)
    assert d[5] == pytest.approx(0.0, abs=1e-12)


def test_vessel_at_rest_in_current_picks_up_the_current(cfg):
    v = Vessel(cfg.vessel)
    cur = (0.5, 0.2)
    s = (0.0, 0.0, 0.7, 0.0, 0.0, 0.0)
    def f(s_):
        return v.dynamics(s_, (0, 0, 0), (0, 0, 0), cur)
    for _ in range(6000):
        s = rk4_step(f, s, 0.01)
    d = f(s)
    assert d[0] == pytest.approx(cur[0], abs=0.02) and d[1] == pytest.approx(cur[1], abs=0.02)


def test_compiled_hull_step_is_the_generic_rk4_of_the_printed_equations(cfg):
    """The simulator integrates with ``hull_rk4_step`` (compiled); it must compute, bit for bit, what
    the generic Python ``rk4_step`` computes over the equations run as Python (``py_func``)."""
    k = Vessel(cfg.vessel).coefficients
    rng = np.random.default_rng(11)
    for i in range(3000):
        s = tuple(float(a) for a in rng.normal(0.0, [200.0, 200.0, 4.0, 3.0, 1.0, 0.6]))
        tau = (float(rng.normal(0, 80)), 0.0, float(rng.normal(0, 20)))
        tau_w = tuple(float(a) for a in rng.normal(0, 5, 3))
        cur = tuple(float(a) for a in rng.normal(0, 0.5, 2))
        dt = (0.01, 0.005, 0.1)[i % 3]
        assert hull_dynamics(s, tau, tau_w, cur, k) == hull_dynamics.py_func(s, tau, tau_w, cur, k)
        python = rk4_step(lambda x, tau=tau, tau_w=tau_w, cur=cur: hull_dynamics.py_func(x, tau, tau_w, cur, k), s, dt)
        assert hull_rk4_step(s, dt, tau, tau_w, cur, k) == python


def test_simulator_steps_with_the_compiled_hull(cfg):
    """SimulatorCore.step is the generic RK4 (simulator.integrator) over Vessel.dynamics, as the
    simulator integrated before the step was compiled."""
    core = SimulatorCore(simulator_settings(load(None, [])))   # waves and current on
    v = core.vessel
    assert core.substeps == 1   # the default layout: one RK4 step a frame
    for n in range(200):
        core.apply(Command(core.time_usec, 0.8, 0.3 if n < 100 else -0.4))
        s0, env = core.state, core._env
        (sp, ss), (tp, ts), a = core.thrusts(), core.thrust, core._lag
        tau = v.propulsion(sp + (tp - sp) * a, ss + (ts - ss) * a)
        core.step()
        assert core.state == rk4_step(lambda x, tau=tau, env=env: v.dynamics(x, tau, *env), s0, core.dt)
