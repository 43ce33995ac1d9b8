"""The vessel computer's assembly in-process: the root of its configuration made from the HIL one
(hil.assembly.computer.computer_settings), and a device that cannot be opened (SetupError) closes the
devices opened before it (autopilot_bridge.assembly.build_computer). No planner, no processes."""

from __future__ import annotations

import socket

import numpy as np
import pytest

from autopilot_bridge.assembly import SetupError, build_computer
from autopilot_bridge.local_planning import CycleInput, World
from hil import settings
from hil.assembly.computer import computer_settings, run_options
from hil.hilrun import free_udp_port
from planner.online import OnlineParams


def test_the_computers_root_carries_the_sections_it_reads():
    cfg = settings.load(None, ["sim.seed=11", "sensors.imu.rate_hz=50", "vessel.m=30"])
    root = computer_settings(cfg, lockstep=True)
    assert root.tuning.params is cfg.autopilot and root.tuning.nav is cfg.navigation
    assert root.gcs is cfg.gcs and root.can is cfg.can and root.tracking is cfg.tracking
    assert root.tuning.hull.m == 30.0 and root.tuning.hull.T_min == cfg.vessel.T_min
    assert root.origin == (cfg.geodesy.lat0, cfg.geodesy.lon0, cfg.geodesy.alt0)
    assert root.loss_seed == 18
    assert root.simulator.max_time_step == pytest.approx(1.5 / 50)   # lockstep: one IMU period and a half
    assert computer_settings(cfg, lockstep=False).simulator.max_time_step == pytest.approx(0.25)
    assert root.simulator.declination == cfg.sensors.compass.declination
    assert (root.simulator.system_id, root.simulator.component_id) == (cfg.link.system_id, cfg.link.component_id)


def test_a_ground_station_port_in_use_closes_the_hil_link_opened_before_it():
    busy = socket.socket()
    busy.bind(("127.0.0.1", 0))
    busy.listen(1)
    port = busy.getsockname()[1]
    listen = free_udp_port()
    cfg = settings.load(None, [f'autopilot.listen="127.0.0.1:{listen}"',
                               f'autopilot.actuators_to=["127.0.0.1:{free_udp_port()}"]',
                               f'gcs.endpoints=["tcpin:127.0.0.1:{port}"]'])
    world = World(np.zeros((20, 20), dtype=bool), 1.0, (15.0, 15.0), np.array([[5.0, 5.0], [15.0, 15.0]]), None,
                  cfg.planner, OnlineParams(), "ddrrt-star")
    try:
        with pytest.raises(SetupError, match=f"cannot listen on TCP 127.0.0.1:{port}") as refused:
            build_computer(computer_settings(cfg, lockstep=True), world, run_options(cfg, lockstep=True),
                           (20.0, 20.0), CycleInput(5.0, 5.0, 0.0, 0.0, 0))
    finally:
        busy.close()
    # The traceback still holds the link: its port binds again only because build_computer closed it.
    assert refused.traceback
    again = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    try:
        again.bind(("127.0.0.1", listen))
    finally:
        again.close()
