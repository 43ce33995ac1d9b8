"""Sensor models seen through their MAVLink messages: noise statistics, latency, dropouts, glitches."""

from __future__ import annotations

import math

import numpy as np
import pytest

from common.geodesy import LocalFrame
from common.mavlink import Codec
from hil.assembly.simulator import simulator_settings
from hil.settings import load
from simulator.core import Command, SimulatorCore, frame_layout
from simulator.sensors import G

QUIET = ["waves.enabled=false", "current.enabled=false", "sensors.gps.glitch_probability=0.0",
         "sensors.imu.gyro_bias_walk=0.0"]
DECODER = ("HIL_SENSOR", "HIL_GPS", "HIL_STATE_QUATERNION", "ODOMETRY", "BATTERY_STATUS")


def run_frames(overrides, n, controls=(0.0, 0.0)):
    """Run n frames of a SimulatorCore; yield (core state before step, decoded messages by type)."""
    core = SimulatorCore(simulator_settings(load(None, QUIET + list(overrides))))
    dec = Codec(255, 0, accept=DECODER)
    out = []
    for _ in range(n):
        msgs, rejects = dec.decode(core.frame())
        assert not rejects
        out.append((core.state, {m.get_type(): m for m in msgs}))
        core.apply(Command(core.time_usec, *controls))
        core.step()
    return core, out


def test_imu_and_compass_noise_match_configured_sigma():
    core, frames = run_frames([], 20000)
    p = core.cfg.sensors
    s = [m["HIL_SENSOR"] for _, m in frames]
    gz = np.array([m.zgyro for m in s])
    ax = np.array([m.xacc for m in s])
    az = np.array([m.zacc for m in s])
    # n = 20000: the sample std has relative standard error 1/sqrt(2n) = 0.5%; allow 4%
    assert gz.std() == pytest.approx(p.imu.gyro_std, rel=0.04)
    assert ax.std() == pytest.approx(p.imu.accel_std, rel=0.04)
    assert az.mean() == pytest.approx(-G, abs=5 * p.imu.accel_bias)  # specific force at rest, z down
    heading = np.array([math.atan2(-m.ymag, m.xmag) + p.compass.declination for m in s])
    assert heading.std() == pytest.approx(p.compass.heading_std, rel=0.04)
    assert np.hypot([m.xmag for m in s], [m.ymag for m in s]) == pytest.approx(p.compass.field_strength)
    assert all(m.fields_updated == 0x1FF for m in s[:10])


def test_gyro_bias_is_constant_per_run_and_seeded():
    _, a = run_frames(["sensors.imu.gyro_bias=0.01", "sensors.imu.gyro_std=0.0"], 50)
    _, b = run_frames(["sensors.imu.gyro_bias=0.01", "sensors.imu.gyro_std=0.0", "sim.seed=2"], 50)
    za = {m["HIL_SENSOR"].zgyro for _, m in a}
    zb = {m["HIL_SENSOR"].zgyro for _, m in b}
    assert len(za) == 1 and len(zb) == 1 and za != zb
    assert 0 < abs(za.pop()) < 0.05


def test_gps_position_and_velocity_noise_match_sigma():
    core, frames = run_frames([], 30000)  # 300 s at 10 Hz: 3000 fixes
    p = core.cfg.sensors.gps
    geo = LocalFrame(core.cfg.geodesy.lat0, core.cfg.geodesy.lon0, core.cfg.geodesy.alt0)
    fixes = [m["HIL_GPS"] for _, m in frames if "HIL_GPS" in m]
    assert len(fixes) == 3000 and all(f.fix_type == 3 for f in fixes)
    ne = np.array([geo.geodetic_to_sea_level(f.lat * 1e-7, f.lon * 1e-7) for f in fixes])
    # relative standard error of the std for n = 3000 is 1.3%; allow 6%
    assert ne[:, 0].std() == pytest.approx(p.pos_std, rel=0.06)
    assert ne[:, 1].std() == pytest.approx(p.pos_std, rel=0.06)
    assert abs(ne[:, 0].mean()) < 4 * p.pos_std / math.sqrt(3000)
    vn = np.array([f.vn for f in fixes]) / 100.0
    assert vn.std() == pytest.approx(p.vel_std, rel=0.1)  # cm/s quantisation adds a little
    assert fixes[0].eph == round(100 * p.pos_std)


def test_gps_rate_latency_and_truth():
    """Zero-noise GPS lags the truth by exactly the configured latency; 10 Hz of 100 Hz frames."""
    core, frames = run_frames(["sensors.gps.pos_std=0.0", "sensors.gps.vel_std=0.0", "sim.truth_rate_hz=100.0",
                               "sim.initial.u=2.5"], 300, controls=(1.0, 1.0))
    geo = core.geo
    truth = {m["HIL_STATE_QUATERNION"].time_usec: geo.geodetic_to_sea_level(
        m["HIL_STATE_QUATERNION"].lat * 1e-7, m["HIL_STATE_QUATERNION"].lon * 1e-7) for _, m in frames}
    gps = [m["HIL_GPS"] for _, m in frames if "HIL_GPS" in m]
    assert len(gps) == 30
    lag = int(round(core.cfg.sensors.gps.latency * 1e6))
    for g in gps[2:]:
        x, _ = geo.geodetic_to_sea_level(g.lat * 1e-7, g.lon * 1e-7)
        assert x == pytest.approx(truth[g.time_usec - lag][0], abs=0.02)  # degE7 quantisation ~1 cm
        assert x < truth[g.time_usec][0] - 0.1  # really behind


def test_gps_dropout_window_and_glitches():
    _, frames = run_frames(["sensors.gps.dropouts=[[1.0, 0.5]]"], 300)
    for _, m in frames:
        if "HIL_GPS" in m:
            t = m["HIL_GPS"].time_usec / 1e6
            in_window = 1.0 <= t < 1.5
            assert (m["HIL_GPS"].fix_type == 0) == in_window
            assert (m["HIL_GPS"].satellites_visible == 0) == in_window
    core, frames = run_frames(["sensors.gps.glitch_probability=1.0", "sensors.gps.pos_std=0.0"], 100)
    geo = core.geo
    for _, m in frames:
        if "HIL_GPS" in m:
            x, y = geo.geodetic_to_sea_level(m["HIL_GPS"].lat * 1e-7, m["HIL_GPS"].lon * 1e-7)
            assert math.hypot(x, y) == pytest.approx(core.cfg.sensors.gps.glitch_magnitude, abs=0.05)
    assert core.gps.glitches == 10


def test_random_dropouts_are_seeded():
    over = ["sensors.gps.dropout_rate=0.2", "sensors.gps.dropout_duration=1.0"]
    def fix(fr):
        return [m["HIL_GPS"].fix_type for _, m in fr if "HIL_GPS" in m]
    a, b = fix(run_frames(over, 3000)[1]), fix(run_frames(over, 3000)[1])
    assert a == b and 0 in a and 3 in a


def test_dvl_sends_body_velocity_when_enabled():
    _, frames = run_frames(["sensors.dvl.enabled=true", "sensors.dvl.vel_std=0.0", "sim.initial.u=1.5"], 100)
    odo = [(s, m["ODOMETRY"]) for s, m in frames if "ODOMETRY" in m]
    assert len(odo) == 5
    for s, o in odo:
        assert o.vx == pytest.approx(s[3], abs=1e-5) and o.vy == pytest.approx(s[4], abs=1e-5)
    _, frames = run_frames([], 100)
    assert not any("ODOMETRY" in m for _, m in frames)


def test_imu_period_must_be_whole_steps():
    with pytest.raises(ValueError, match="sensors.imu.rate_hz"):
        frame_layout(0.01, 30.0)
    assert frame_layout(0.01, 50.0) == (0.02, 2)


def test_stale_command_failsafe_zeroes_thrust_once_per_silence():
    core = SimulatorCore(simulator_settings(load(None, QUIET)))
    for _ in range(100):
        core.apply(Command(core.time_usec, 1.0, 1.0))
        core.step()
    assert core.thrusts() == (core.vessel.T_max, core.vessel.T_max)
    for _ in range(60):  # 0.6 s without a command > 0.5 s timeout
        core.step()
    assert core.thrusts() == (0.0, 0.0) and core.stale_command_events == 1
    for _ in range(100):
        core.step()
    assert core.stale_command_events == 1
    core.apply(Command(core.time_usec, 0.5, 0.5))
    assert core.thrusts() == (4096 / 8191 * core.vessel.T_max,) * 2   # int14 commands (esc default)
