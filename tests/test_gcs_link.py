"""The GCS link's transports in-process, on real loopback sockets: udpout, udpin with several ground
stations, tcpin with frames split across reads, forward() of any dialect message, the recorder copy."""

from __future__ import annotations

import socket
import time

import pytest

from autopilot_bridge.gcs.config import GcsParams
from autopilot_bridge.gcs.link import GcsLink, load_signing_key
from autopilot_bridge.gcs.transport import parse_endpoint
from common.geodesy import LocalFrame
from common.mavlink import MAV_TYPE as M
from common.mavlink import mavlink2
from hil.hilrun import free_udp_port

GEO = LocalFrame(38.92, 121.65, 0.0)


def params(*endpoints: str) -> GcsParams:
    return GcsParams(endpoints=tuple(endpoints), wait_for_arm=False, failsafe_timeout=5.0, failsafe_action="hold",
                     mission_timeout=0.25, mission_retries=5, max_mission_items=200, signing_key_file="",
                     allowed_sysids=(), max_peers=8)


def free_tcp_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def gcs_heartbeat(sysid: int = 255) -> bytes:
    mav = mavlink2.MAVLink(None, sysid, 190)
    return bytes(mav.heartbeat_encode(M.MAV_TYPE_GCS, M.MAV_AUTOPILOT_INVALID, 0, 0, 0).pack(mav))


def ais(link: GcsLink) -> None:
    link.forward("AIS_VESSEL", 412345678, 389210000, 1216510000, 9000, 9000, 500, 0, 0, 70, 50, 10, 5, 5,
                 b"BXYZ", b"TEST SHIP", 1, 0)


def read_until(sock: socket.socket, want: str, link: GcsLink, timeout: float = 5.0):
    """Service the link and parse what ``sock`` receives until a ``want`` message arrives (bounded)."""
    parser = mavlink2.MAVLink(None, 255, 190)
    parser.robust_parsing = True
    sock.settimeout(0.05)
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        link.service()
        try:
            data = sock.recv(65535)
        except TimeoutError:
            continue
        for m in parser.parse_buffer(data) or []:
            if m.get_type() == want:
                return m
    return None


@pytest.fixture
def closing():
    items = []
    yield items.append
    for it in items:
        it.close()


def _listening_gcs_and_udpout_link(closing):
    """A ground station's socket bound on a free loopback port, and a link sending to it (udpout)."""
    port = free_udp_port()
    gcs = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    closing(gcs)
    gcs.bind(("127.0.0.1", port))
    link = GcsLink.open(params(f"udpout:127.0.0.1:{port}"), 1, 1, GEO)
    closing(link)
    return gcs, link


def test_udpout_reaches_a_listening_gcs_without_it_talking_first(closing):
    gcs, link = _listening_gcs_and_udpout_link(closing)
    link.heartbeat()
    hb = read_until(gcs, "HEARTBEAT", link)
    assert hb is not None and hb.type == M.MAV_TYPE_SURFACE_BOAT and hb.get_srcSystem() == 1


def test_udpin_answers_several_gcs_and_forward_sends_any_message_to_each_and_to_the_recorder(closing):
    port, rec_port = free_udp_port(), free_udp_port()
    recorder = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    closing(recorder)
    recorder.bind(("127.0.0.1", rec_port))
    link = GcsLink.open(params(f"udpin:127.0.0.1:{port}"), 1, 1, GEO, mirror_to=(f"127.0.0.1:{rec_port}",))
    closing(link)
    clients = []
    for sysid in (255, 254):
        c = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        closing(c)
        c.bind(("127.0.0.1", 0))
        c.sendto(gcs_heartbeat(sysid), ("127.0.0.1", port))
        clients.append(c)
    end = time.monotonic() + 5.0
    while link.received["HEARTBEAT"] < 2 and time.monotonic() < end:
        link.service()
        time.sleep(0.01)
    assert link.received["HEARTBEAT"] == 2
    ais(link)
    for c in clients:
        m = read_until(c, "AIS_VESSEL", link)
        assert m is not None and m.MMSI == 412345678 and m.get_srcSystem() == 1 and m.name == "TEST SHIP"
    # The recorder got the ground stations' heartbeats and what the boat sent.
    parser = mavlink2.MAVLink(None)
    got = set()
    recorder.settimeout(0.2)
    try:
        while True:
            for m in parser.parse_buffer(recorder.recv(65535)) or []:
                got.add((m.get_type(), m.get_srcSystem()))
    except TimeoutError:
        pass
    assert {("HEARTBEAT", 255), ("HEARTBEAT", 254), ("AIS_VESSEL", 1)} <= got


def test_tcpin_parses_frames_split_across_reads_and_answers_the_connection(closing):
    port = free_tcp_port()
    link = GcsLink.open(params(f"tcpin:127.0.0.1:{port}"), 1, 1, GEO)
    closing(link)
    c = socket.create_connection(("127.0.0.1", port), timeout=5.0)
    closing(c)
    frame = gcs_heartbeat() + b"\x00garbage\xff" + gcs_heartbeat()
    c.sendall(frame[:7])
    end = time.monotonic() + 5.0
    while not link.transports[0].conns and time.monotonic() < end:
        link.service()
    link.service()
    c.sendall(frame[7:])
    while link.received["HEARTBEAT"] < 2 and time.monotonic() < end:
        link.service()
        time.sleep(0.01)
    assert link.received["HEARTBEAT"] == 2 and link.rejects["not_mavlink"] >= 1
    ais(link)
    assert read_until(c, "AIS_VESSEL", link) is not None


def test_gcs_endpoints_are_parsed_once_when_the_section_is_read():
    """[gcs] endpoints become typed connections as the section is read: a bad one is refused there, in one
    line naming the key; the devices open the parsed ones; written back, the section holds the strings only."""
    from common.tables import to_table

    p = GcsParams(endpoints=("udp:127.0.0.1:5", "tcpin:0.0.0.0:5760", "serial:/dev/ttyUSB0:57600"))
    assert [(c.kind, c.host or c.device, c.port or c.baud) for c in p.connections] == [
        ("udpin", "127.0.0.1", 5), ("tcpin", "0.0.0.0", 5760), ("serial", "/dev/ttyUSB0", 57600)]
    table = to_table(p)
    assert "connections" not in table and table["endpoints"] == list(p.endpoints)
    assert GcsParams(**{k: tuple(v) if isinstance(v, list) else v for k, v in table.items()}) == p
    with pytest.raises(ValueError, match="^endpoints: "):
        GcsParams(endpoints=("udpx:1.2.3.4:5",))


def test_endpoint_strings_and_signing_keys(tmp_path):
    assert parse_endpoint("udpout:127.0.0.1:14550") == ("udpout", "127.0.0.1", 14550)
    assert parse_endpoint("udp:1.2.3.4:5") == ("udpin", "1.2.3.4", 5)  # mavutil's udp: is udpin: (issue 16)
    for bad in ("udpx:1.2.3.4:5", "udpout:127.0.0.1", "tcpin:host:99999", "udpout:127.0.0.1:0"):
        with pytest.raises(ValueError):
            parse_endpoint(bad)
    (tmp_path / "raw").write_bytes(bytes(range(32)))
    (tmp_path / "hex").write_text(bytes(range(32)).hex() + "\n")
    (tmp_path / "pass").write_text("correct horse\n")
    import hashlib

    assert load_signing_key(str(tmp_path / "raw")) == bytes(range(32)) == load_signing_key(str(tmp_path / "hex"))
    assert load_signing_key(str(tmp_path / "pass")) == hashlib.sha256(b"correct horse").digest()
    with pytest.raises(ValueError):
        load_signing_key(str(tmp_path / "missing"))


def test_a_field_out_of_its_wire_range_costs_one_message_not_the_caller(closing):
    link = GcsLink.open(params(), 1, 1, GEO)
    closing(link)
    link.forward("VFR_HUD", 0.0, 1.0, 90, -40, 0.0, 0.0)   # throttle is uint16 on the wire
    link.forward("VFR_HUD", 0.0, 1.0, 90, 40, 0.0, 0.0)
    assert link.encode_errors["vfr_hud"] == 1 and link.sent == 1


def _command_long(cmd: int, *p: float, sysid: int = 245) -> bytes:
    mav = mavlink2.MAVLink(None, sysid, 190)
    p = list(p) + [0.0] * (7 - len(p))
    return bytes(mav.command_long_encode(1, 1, cmd, 0, *p).pack(mav))


class _VehicleOnly:
    """The command API (autopilot_bridge.vehicle_api.VehicleApi) over a bare Vehicle, position (0, 0)."""

    def __init__(self, vehicle) -> None:
        self.v = vehicle

    def set_mode(self, mode):
        from autopilot_bridge.vehicle_api import Result

        return Result(*self.v.set_mode(mode, (0.0, 0.0)))

    def goto(self, north, east):
        from autopilot_bridge.vehicle_api import Result

        return Result(*self.v.reposition((north, east), (0.0, 0.0)))

    def mission(self):
        return self.v.mission

    def parameters(self):
        return []


def test_set_mode_with_a_custom_sub_mode_is_refused_not_read_as_a_rover_mode(closing):
    """MAVSDK sets a non-ArduPilot vehicle's mode the PX4 way: DO_SET_MODE param2 = main mode, param3 = sub
    mode; its "start mission" is (4, 4). Rover's custom mode 4 is HOLD: that must be refused (DENIED),
    not acknowledged as a HOLD the GCS did not ask for. A Rover mode with param3 0 or NaN is accepted."""
    from types import SimpleNamespace

    from autopilot_bridge.vehicle import Mode, Vehicle, Waypoint

    port = free_udp_port()
    link = GcsLink.open(params(f"udpin:127.0.0.1:{port}"), 1, 1, GEO)
    closing(link)
    vehicle = Vehicle([Waypoint(10.0, 10.0, 3.0)], armed=True, mode=Mode.MANUAL)
    link.attach(_VehicleOnly(vehicle))
    link.status = SimpleNamespace(position=(0.0, 0.0))
    gcs = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    closing(gcs)
    gcs.bind(("127.0.0.1", 0))
    flag = M.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED
    for p2, p3, result, mode in ((4.0, 4.0, M.MAV_RESULT_DENIED, Mode.MANUAL),    # PX4 AUTO.MISSION
                                 (4.0, 5.0, M.MAV_RESULT_DENIED, Mode.MANUAL),    # PX4 AUTO.RTL
                                 (10.0, float("nan"), M.MAV_RESULT_ACCEPTED, Mode.AUTO),
                                 (4.0, 0.0, M.MAV_RESULT_ACCEPTED, Mode.HOLD)):
        gcs.sendto(_command_long(M.MAV_CMD_DO_SET_MODE, flag, p2, p3), ("127.0.0.1", port))
        ack = read_until(gcs, "COMMAND_ACK", link)
        assert ack is not None and ack.command == M.MAV_CMD_DO_SET_MODE and ack.result == result, (p2, p3, ack)
        assert (ack.target_system, ack.target_component) == (245, 190)
        assert vehicle.mode == mode, (p2, p3)
    # The counters the run summary carries.
    s = link.summary()
    assert s["datagrams_in"] == s["frames_in"] == 4 and s["datagrams_out"] >= 4
    assert s["command_acks"] == {"MAV_RESULT_DENIED": 2, "MAV_RESULT_ACCEPTED": 2}
    assert s["commands"] == {"MAV_CMD_DO_SET_MODE:MAV_RESULT_DENIED": 2, "MAV_CMD_DO_SET_MODE:MAV_RESULT_ACCEPTED": 2}
    assert s["failsafe_events"] == 0 and not s["signing"]


def test_a_ping_request_is_answered_to_its_sender(closing):
    """The ping protocol (https://mavlink.io/en/services/ping.html): a PING with target 0/0 is a request; the
    answer echoes time_usec and seq and is addressed to the requester (MAVSDK pings every connection)."""
    port = free_udp_port()
    link = GcsLink.open(params(f"udpin:127.0.0.1:{port}"), 1, 1, GEO)
    closing(link)
    gcs = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    closing(gcs)
    gcs.bind(("127.0.0.1", 0))
    mav = mavlink2.MAVLink(None, 245, 190)
    gcs.sendto(bytes(mav.ping_encode(123456789, 42, 0, 0).pack(mav)), ("127.0.0.1", port))
    pong = read_until(gcs, "PING", link)
    assert pong is not None and (pong.time_usec, pong.seq) == (123456789, 42)
    assert (pong.target_system, pong.target_component, pong.get_srcSystem()) == (245, 190, 1)
    # A response (target set) is not answered again.
    gcs.sendto(bytes(mav.ping_encode(5, 6, 1, 1).pack(mav)), ("127.0.0.1", port))
    assert read_until(gcs, "PING", link, timeout=0.5) is None


def test_guided_goto_by_position_target_and_by_reposition(closing):
    """SET_POSITION_TARGET_GLOBAL_INT (position bits used) and MAV_CMD_DO_REPOSITION (COMMAND_INT) both put the
    boat in GUIDED with a route to the target; a target off the chart is refused with a STATUSTEXT."""
    from types import SimpleNamespace

    from autopilot_bridge.vehicle import Mode, Vehicle, Waypoint

    port = free_udp_port()
    link = GcsLink.open(params(f"udpin:127.0.0.1:{port}"), 1, 1, GEO, chart_size=(150.0, 200.0))
    closing(link)
    vehicle = Vehicle([Waypoint(10.0, 10.0, 3.0)], armed=True, mode=Mode.HOLD)
    link.attach(_VehicleOnly(vehicle))
    link.status = SimpleNamespace(position=(0.0, 0.0))
    gcs = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    closing(gcs)
    gcs.bind(("127.0.0.1", 0))
    mav = mavlink2.MAVLink(None, 245, 190)
    lat, lon = GEO.sea_level_to_geodetic(40.0, 25.0)
    ignore_velocity_etc = 0b0000_1111_1111_1000
    gcs.sendto(bytes(mav.set_position_target_global_int_encode(
        0, 1, 1, M.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT, ignore_velocity_etc, int(round(lat * 1e7)),
        int(round(lon * 1e7)), 0.0, 0, 0, 0, 0, 0, 0, 0, 0).pack(mav)), ("127.0.0.1", port))
    deadline = time.monotonic() + 5.0
    while vehicle.mode != Mode.GUIDED and time.monotonic() < deadline:
        link.service()
        time.sleep(0.01)
    assert vehicle.mode == Mode.GUIDED
    assert vehicle.route.path[-1] == pytest.approx([40.0, 25.0], abs=0.01)
    lat, lon = GEO.sea_level_to_geodetic(12.0, 30.0)
    gcs.sendto(bytes(mav.command_int_encode(1, 1, M.MAV_FRAME_GLOBAL_INT, M.MAV_CMD_DO_REPOSITION, 0, 0, -1, 0, 0, 0,
                                            int(round(lat * 1e7)), int(round(lon * 1e7)), 0.0).pack(mav)),
               ("127.0.0.1", port))
    ack = read_until(gcs, "COMMAND_ACK", link)
    assert ack is not None and ack.result == M.MAV_RESULT_ACCEPTED
    assert vehicle.route.path[-1] == pytest.approx([12.0, 30.0], abs=0.01)
    lat, lon = GEO.sea_level_to_geodetic(400.0, 30.0)   # north of the 150 m chart
    gcs.sendto(bytes(mav.set_position_target_global_int_encode(
        0, 1, 1, M.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT, ignore_velocity_etc, int(round(lat * 1e7)),
        int(round(lon * 1e7)), 0.0, 0, 0, 0, 0, 0, 0, 0, 0).pack(mav)), ("127.0.0.1", port))
    text = read_until(gcs, "STATUSTEXT", link)
    assert text is not None and "off the chart" in text.text
    assert vehicle.route.path[-1] == pytest.approx([12.0, 30.0], abs=0.01)


def test_a_long_statustext_arrives_whole_in_chunks(closing):
    """STATUSTEXT holds 50 characters; a longer text (a refused mission item's reason) goes out in MAVLink 2
    chunks (same non-zero id, chunk_seq 0, 1, ..., the last one shorter than 50 or NUL-terminated) that a
    ground station joins, instead of being cut after 50 characters. A short one is one message, id 0."""
    gcs, link = _listening_gcs_and_udpout_link(closing)
    long = "mission item 1 rejected: waypoint 2000 m north is off the chart (0-150)"
    exact = "x" * 100                                   # a multiple of 50: a NUL-terminated empty chunk ends it
    for text in ("armed", long, exact, long):
        link.statustext(text)
    parser = mavlink2.MAVLink(None, 255, 190)
    gcs.settimeout(1.0)
    got: list = []
    while len(got) < 1 + 2 + 3 + 2:
        for m in parser.parse_buffer(gcs.recv(65535)) or []:
            if m.get_type() == "STATUSTEXT":
                got.append(m)

    def join(msgs) -> str:
        assert [m.chunk_seq for m in msgs] == list(range(len(msgs)))
        assert len({m.id for m in msgs}) == 1 and msgs[0].id != 0
        return "".join(m.text for m in msgs)

    assert got[0].text == "armed" and got[0].id == 0
    assert join(got[1:3]) == long
    assert join(got[3:6]) == exact and got[5].text == ""
    assert join(got[6:8]) == long and got[6].id != got[1].id     # each text its own id
