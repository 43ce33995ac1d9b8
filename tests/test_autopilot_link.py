"""The autopilot's HIL link and loop against the real simulator core's MAVLink bytes."""

from __future__ import annotations

import math

import pytest

from autopilot_bridge.hil_link import HilLink
from common.geodesy import LocalFrame
from common.udp import UdpEndpoint
from hil import settings
from hil.assembly.simulator import simulator_settings
from simulator.core import SimulatorCore


@pytest.fixture
def cfg():
    return settings.load(None, ["sensors.gps.glitch_probability=0.0", "sensors.dvl.enabled=true"])


def _link(cfg) -> HilLink:
    geo = LocalFrame(cfg.geodesy.lat0, cfg.geodesy.lon0, cfg.geodesy.alt0)
    return HilLink.open("127.0.0.1:0", ("127.0.0.1:9",), geo, declination=cfg.sensors.compass.declination)


def test_sensor_frames_decode_to_si_ned_and_truth_is_ignored(cfg):
    core = SimulatorCore(simulator_settings(cfg))
    link = _link(cfg)
    try:
        seen_gps = seen_dvl = 0
        for _ in range(60):
            frame = link.decode(core.frame())
            assert frame is not None and frame.time_usec == core.time_usec
            assert frame.heading == pytest.approx(core.state[2], abs=0.1)
            if frame.gps is not None:
                seen_gps += 1
                # GPS is `latency` old and noisy; the boat is near the origin at rest.
                assert math.hypot(frame.gps.north - core.state[0], frame.gps.east - core.state[1]) < 3.0
            if frame.dvl is not None:
                seen_dvl += 1
            core.step()
        assert seen_gps >= 5 and seen_dvl >= 2
        assert link.truth_ignored > 0
        assert not link.rejects
    finally:
        link.close()


def test_commands_round_trip_into_the_simulator(cfg):
    core = SimulatorCore(simulator_settings(cfg))
    link = _link(cfg)
    sink = UdpEndpoint("127.0.0.1:0")
    link.ep.destinations = [sink.address]
    try:
        link.send_controls(core.time_usec, 0.5, -0.25)
        data = sink.recv(timeout=5.0)
        cmds = core.receive(data)
        assert len(cmds) == 1
        assert (cmds[0].time_usec, cmds[0].port, cmds[0].stdb) == (core.time_usec, 0.5, -0.25)
    finally:
        link.close()
        sink.close()


def test_garbage_is_counted_not_fatal(cfg):
    link = _link(cfg)
    try:
        assert link.decode(b"\x00\x01garbage") is None
        assert sum(link.rejects.values()) >= 1
    finally:
        link.close()
