"""ESC telemetry to the ground station: the DroneCAN ESC Status the autopilot reads back over CAN
(python-can's in-process `virtual` bus) reaches a GCS as ESC_TELEMETRY_1_TO_4 over real UDP."""

from __future__ import annotations

import math
import socket
from types import SimpleNamespace

import can
import pytest
from test_gcs_link import read_until

from autopilot_bridge.can_actuators import CanActuators
from autopilot_bridge.gcs.config import GcsParams
from autopilot_bridge.gcs.link import GcsLink
from common.geodesy import LocalFrame
from common.mavlink import MAV_TYPE as M
from common.mavlink import mavlink2
from hil import settings
from hil.assembly.simulator import simulator_settings
from hil.hilrun import free_udp_port
from simulator.core import SimulatorCore
from simulator.esc import EscBank


def _gcs_params(endpoint: str) -> GcsParams:
    return GcsParams(endpoints=(endpoint,), wait_for_arm=False, failsafe_timeout=5.0, failsafe_action="hold",
                     mission_timeout=0.25, mission_retries=5, max_mission_items=200, signing_key_file="",
                     allowed_sysids=(), max_peers=8)


@pytest.fixture
def can_rig():
    cfg = settings.load(None, ["can.interface=\"virtual\""])
    buses = [can.Bus(interface="virtual", channel="gcs-esc-telemetry") for _ in range(2)]
    core = SimulatorCore(simulator_settings(cfg))
    yield cfg, core, EscBank(buses[0], cfg.can, cfg.esc, core.vessel), CanActuators(buses[1], cfg.can)
    for b in buses:
        b.shutdown()


def _request(sock: socket.socket, port: int, link: GcsLink, msg_id: int, timeout: float = 5.0):
    """Ask the boat for ``msg_id`` with MAV_CMD_REQUEST_MESSAGE; the answer (bounded wait) or None."""
    mav = mavlink2.MAVLink(None, 255, 190)
    sock.sendto(bytes(mav.command_long_encode(1, 1, M.MAV_CMD_REQUEST_MESSAGE, 0, msg_id, 0, 0, 0, 0, 0, 0).pack(mav)),
                ("127.0.0.1", port))
    return read_until(sock, mavlink2.mavlink_map[msg_id].msgname, link, timeout)


def test_esc_status_from_can_is_forwarded_as_esc_telemetry(can_rig):
    cfg, core, esc, acts = can_rig
    port = free_udp_port()
    link = GcsLink.open(_gcs_params(f"udpin:127.0.0.1:{port}"), 1, 1, LocalFrame(38.92, 121.65, 0.0))
    link.api = SimpleNamespace(esc_telemetry=acts.esc_telemetry)  # only what REQUEST_MESSAGE touches
    sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    sock.settimeout(0.05)
    try:
        # Before any ESC Status: nothing to forward, the request is answered with nothing.
        assert _request(sock, port, link, mavlink2.MAVLINK_MSG_ID_ESC_TELEMETRY_1_TO_4, timeout=0.5) is None
        acts.send_controls(10_000, 0.5, -0.25)
        assert esc.poll(1.0) == 1
        p, s = esc.controls()
        esc.publish(0.0, (core.vessel.thrust(p), core.vessel.thrust(s)))
        for _ in range(6):
            acts.service(0.05)
        m = _request(sock, port, link, mavlink2.MAVLINK_MSG_ID_ESC_TELEMETRY_1_TO_4)
    finally:
        sock.close()
        link.close()
    assert m is not None
    status = acts.summary()["esc_status"]
    assert list(m.rpm) == [abs(status["port"]["rpm"]), abs(status["starboard"]["rpm"]), 0, 0]
    assert m.rpm[0] == round(cfg.esc.max_rpm * math.sqrt(0.5))
    assert list(m.voltage[:2]) == [round(cfg.esc.voltage * 100)] * 2           # cV
    assert m.temperature[0] == round(status["port"]["temperature"] - 273.15)     # K -> degC
    assert m.current[0] == round(status["port"]["current"] * 100) > 0            # cA
    assert list(m.count) == [1, 1, 0, 0]                                         # Status transfers received
