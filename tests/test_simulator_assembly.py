"""The simulator assembled from its typed parts, in-process (issue 30 point 6), as
`hil sim` assembles it: a scenario's share of the world, the server, the sockets it owns."""

from __future__ import annotations

import socket

import numpy as np
import pytest

from hil import settings
from hil.assembly.simulator import build_simulator, scenario_world
from hil.errors import UsageError


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
