"""The simulator assembled from its typed parts, in-process (issue 30 point 6), as
`hil sim` assembles it: a scenario's share of the world, the server, the sockets it owns."""

from __future__ import annotations

import socket

import numpy as np
import pytest

from hil import settings
from hil.assembly.simulator import build_simulator, scenario_world, simulator_settings
from hil.errors import UsageError
from simulator.core import SimulatorCore


def test_the_simulators_root_carries_the_sections_it_reads_and_the_computers_ids():
    cfg = settings.load(None, ["autopilot.system_id=7", "autopilot.component_id=3", "link.system_id=9",
                               "battery.rate_hz=4", "sim.seed=5"])
    root = simulator_settings(cfg)
    assert root.vessel is cfg.vessel and root.waves is cfg.waves and root.current is cfg.current
    assert root.sensors is cfg.sensors and root.sim is cfg.sim and root.link is cfg.link
    assert root.geodesy is cfg.geodesy and root.esc is cfg.esc and root.can is cfg.can
    assert root.traffic is cfg.traffic and root.battery is cfg.battery
    assert (root.computer.system_id, root.computer.component_id) == (7, 3)
    core = SimulatorCore(root)
    assert core.peer_ids == (7, 3) and core.codec.mav.srcSystem == 9
    assert core.battery_due.k == pytest.approx(4 * core.frame_dt)   # [battery] reached the pack


def test_the_harbour_gives_the_simulator_its_start_current_truth_and_ships():
    base = settings.load()
    given = scenario_world("harbour", base)
    from hil import scenario as scenarios

    scen = scenarios.load("harbour", base.current, geodesy=base.geodesy)
    assert np.array_equal(given.world.occ, scen.truth_occ())
    assert given.traffic == tuple(scen.traffic)
    assert any(o.startswith("sim.initial.x=") for o in given.overrides)
    cfg = settings.load(overrides=given.overrides + ["link.commands_on=\"127.0.0.1:0\"",
                                                      "link.state_to=[\"127.0.0.1:9\"]", "sim.duration=0.1"])
    parts = build_simulator(cfg, given.world, given.traffic)
    try:
        host, port = parts.endpoint.address
        assert host == "127.0.0.1" and port > 0 and parts.esc is None
        north, east = scen.start[1], scen.start[0]
        assert parts.server.core.state[:2] == pytest.approx([north, east])
    finally:
        parts.close()
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:   # the port was given back
        s.bind(("127.0.0.1", port))


def test_a_random_scenario_is_refused_in_one_line():
    with pytest.raises(UsageError, match="draws a new map per run"):
        scenario_world("random", settings.load())


def test_a_bus_that_cannot_open_is_a_usage_error_and_leaves_no_socket_open():
    cfg = settings.load(overrides=["can.actuators=\"can\"", "can.interface=\"no-such-interface\"",
                                   "link.commands_on=\"127.0.0.1:0\""])
    with pytest.raises(UsageError, match="cannot open CAN bus"):
        build_simulator(cfg, None, ())
