"""The ground-station port under attack, in-process on real loopback sockets with pymavlink bytes
(issue 14, points 3 and 4; docs/security.md):

* signing as MAVLink 2 specifies it: one replay state per link and key, shared by UDP and every TCP
  connection, so a captured signed ARM replayed over UDP or over a new TCP connection is refused and
  counted; every state- or rate-changing message needs a good signature when signing is on;
* the run's tlog and summaries are owner-only (0600) when a key is set;
* bounded work: one datagram packed with PARAM_REQUEST_LIST costs one parameter dump (replies smaller
  than the request), read-request floods are answered within the rate limits, at most a frame budget
  is handled per service call, and everything refused is counted.

The link's clock is a frozen fake where rate limits are judged (token buckets never refill): the
results do not depend on machine load or wall time.
"""

from __future__ import annotations

import os
import socket
import stat
import time
from typing import Any

import pytest

from autopilot_bridge.gcs.config import GcsParams
from autopilot_bridge.gcs.limits import FRAME_BUDGET, READ_COMMANDS, READ_LIMITS
from autopilot_bridge.gcs.link import GcsLink
from autopilot_bridge.gcs.mission_service import MISSION_WRITES
from autopilot_bridge.gcs.signing import WRITES, signing_now
from autopilot_bridge.modes import Mode
from autopilot_bridge.parameters import Param
from autopilot_bridge.vehicle import Vehicle, Waypoint
from autopilot_bridge.vehicle_api import Result
from common.geodesy import LocalFrame
from common.mavlink import MAV_TYPE as M
from common.mavlink import mavlink2
from hil.hilrun import free_udp_port

GEO = LocalFrame(38.92, 121.65, 0.0)
KEY = bytes(range(32))
# Every message the link handles that is not a write: these are answered without a signature.
READS = frozenset({"HEARTBEAT", "PING", "PARAM_REQUEST_LIST", "PARAM_REQUEST_READ", "MISSION_REQUEST_LIST",
                   "MISSION_REQUEST_INT", "MISSION_REQUEST", "MISSION_ACK"})


class Api:
    """The command API (VehicleApi) over a real Vehicle, at position (0, 0), with one parameter."""

    def __init__(self) -> None:
        self.v = Vehicle([Waypoint(10.0, 10.0, 3.0)], armed=False, mode=Mode.HOLD)
        self.gain = 1.0
        self.arms = 0
        self.forced = False

    def arm(self, on: bool, force: bool = False) -> Result:
        self.arms += 1
        self.forced = force
        return Result(*self.v.arm(on))

    def set_mode(self, mode: Mode) -> Result:
        return Result(*self.v.set_mode(mode, (0.0, 0.0)))

    def goto(self, north: float, east: float) -> Result:
        return Result(*self.v.reposition((north, east), (0.0, 0.0)))

    def set_mission_current(self, seq: int) -> Result:
        return Result(self.v.set_current(seq, (0.0, 0.0)))

    def replace_mission(self, commands: Any) -> None:
        self.v.replace_mission(commands, (0.0, 0.0))

    def check_mission(self, items: Any, to_ned: Any) -> None:
        return None

    def manual_input(self, x: float, r: float, wall_time: float) -> None:
        raise AssertionError("manual input reached the vessel")

    def mission(self) -> Any:
        return self.v.mission

    def parameters(self) -> list[Param]:
        return [Param("TEST_GAIN", lambda: self.gain, lambda v: setattr(self, "gain", v), 0.0, 10.0, "a gain")]

    def esc_telemetry(self) -> list:
        return []


def gcs_params(*endpoints: str, key_file: str = "") -> GcsParams:
    return GcsParams(endpoints=tuple(endpoints), signing_key_file=key_file)


class FrozenClock:
    def __init__(self) -> None:
        self.t = 1000.0

    def __call__(self) -> float:
        return self.t


@pytest.fixture
def closing():
    items: list = []
    yield items.append
    for it in items:
        it.close()


def signer(sysid: int = 245, key: bytes | None = KEY) -> Any:
    mav = mavlink2.MAVLink(None, sysid, 190)
    if key is not None:
        mav.signing.secret_key, mav.signing.sign_outgoing, mav.signing.link_id = key, True, 0
        mav.signing.timestamp = signing_now()
    return mav


def frame(mav: Any, name: str, *args: Any) -> bytes:
    return bytes(getattr(mav, f"{name}_encode")(*args).pack(mav))


def udp_client(closing: Any) -> socket.socket:
    s = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    closing(s)
    s.bind(("127.0.0.1", 0))
    return s


def collect(sock: socket.socket, link: GcsLink, until: Any, timeout: float = 5.0) -> list:
    """Service the link and decode what ``sock`` receives until ``until(messages)`` holds (bounded)."""
    parser = mavlink2.MAVLink(None, 255, 190)
    parser.robust_parsing = True
    got: list = []
    sock.settimeout(0.02)
    end = time.monotonic() + timeout
    while time.monotonic() < end and not until(got):
        link.service()
        try:
            data = sock.recv(65535)
        except TimeoutError:
            continue
        got += [m for m in parser.parse_buffer(data) or [] if not isinstance(m, mavlink2.MAVLink_bad_data)]
    return got


def drain(sock: socket.socket) -> None:
    """Drop what the link sent to every peer earlier (acks are fanned out to all ground stations)."""
    sock.settimeout(0.0)
    try:
        while sock.recv(65535):
            pass
    except (BlockingIOError, TimeoutError):
        pass


def acks(msgs: list) -> list[int]:
    return [m.result for m in msgs if m.get_type() == "COMMAND_ACK"]


def test_a_captured_signed_arm_replayed_over_udp_and_a_new_tcp_connection_is_refused_and_counted(tmp_path, closing):
    key_file = tmp_path / "gcs.key"
    key_file.write_text(KEY.hex())
    udp_port = free_udp_port()
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        tcp_port = s.getsockname()[1]
    link = GcsLink.open(gcs_params(f"udpin:127.0.0.1:{udp_port}", f"tcpin:127.0.0.1:{tcp_port}",
                                   key_file=str(key_file)), 1, 1, GEO)
    closing(link)
    api = Api()
    link.attach(api)
    gcs = udp_client(closing)
    mav = signer()
    arm = frame(mav, "command_long", 1, 1, M.MAV_CMD_COMPONENT_ARM_DISARM, 0, 1.0, 0, 0, 0, 0, 0, 0)
    gcs.sendto(arm, ("127.0.0.1", udp_port))
    got = collect(gcs, link, lambda ms: acks(ms))
    assert acks(got) == [M.MAV_RESULT_ACCEPTED] and api.v.armed and api.arms == 1
    api.v.arm(False)
    # The same bytes again over UDP: a replay.
    gcs.sendto(arm, ("127.0.0.1", udp_port))
    assert acks(collect(gcs, link, lambda ms: acks(ms))) == [M.MAV_RESULT_DENIED]
    # Over a new TCP connection (its own parser): the replay state is the link's, not the connection's.
    tcp = socket.create_connection(("127.0.0.1", tcp_port))
    closing(tcp)
    tcp.sendall(arm)
    assert acks(collect(tcp, link, lambda ms: acks(ms))) == [M.MAV_RESULT_DENIED]
    # A frame captured on one TCP connection, replayed on a second one.
    disarm = frame(mav, "command_long", 1, 1, M.MAV_CMD_COMPONENT_ARM_DISARM, 0, 0.0, 0, 0, 0, 0, 0, 0)
    tcp.sendall(disarm)
    assert acks(collect(tcp, link, lambda ms: acks(ms))) == [M.MAV_RESULT_ACCEPTED]
    tcp2 = socket.create_connection(("127.0.0.1", tcp_port))
    closing(tcp2)
    tcp2.sendall(disarm)
    assert acks(collect(tcp2, link, lambda ms: acks(ms))) == [M.MAV_RESULT_DENIED]
    assert not api.v.armed and api.arms == 2
    s = link.summary()
    assert s["security_rejects"] == {"replay": 3}
    assert s["signature_failures"] == {"replay": 3}
    # A fresh signed frame from the same GCS is still accepted (the refusals recorded nothing).
    drain(gcs)
    gcs.sendto(frame(mav, "command_long", 1, 1, M.MAV_CMD_COMPONENT_ARM_DISARM, 0, 1.0, 0, 0, 0, 0, 0, 0),
               ("127.0.0.1", udp_port))
    assert acks(collect(gcs, link, lambda ms: acks(ms))) == [M.MAV_RESULT_ACCEPTED] and api.v.armed


def _writes(mav: Any) -> dict[str, bytes]:
    """One frame of each state- or rate-changing message the link handles, addressed to system 1."""
    lat, lon = GEO.sea_level_to_geodetic(40.0, 25.0)
    return {
        "REQUEST_DATA_STREAM": frame(mav, "request_data_stream", 1, 1, M.MAV_DATA_STREAM_ALL, 0, 0),
        "COMMAND_LONG": frame(mav, "command_long", 1, 1, M.MAV_CMD_SET_MESSAGE_INTERVAL, 0,
                              mavlink2.MAVLINK_MSG_ID_ATTITUDE, -1, 0, 0, 0, 0, 0),
        "COMMAND_INT": frame(mav, "command_int", 1, 1, M.MAV_FRAME_GLOBAL_INT, M.MAV_CMD_DO_REPOSITION, 0, 0, -1, 0,
                             0, 0, int(lat * 1e7), int(lon * 1e7), 0.0),
        "PARAM_SET": frame(mav, "param_set", 1, 1, b"TEST_GAIN", 5.0, M.MAV_PARAM_TYPE_REAL32),
        "MISSION_COUNT": frame(mav, "mission_count", 1, 1, 3, 0),
        "MISSION_CLEAR_ALL": frame(mav, "mission_clear_all", 1, 1, 0),
        "MISSION_SET_CURRENT": frame(mav, "mission_set_current", 1, 1, 0),
        "MISSION_ITEM_INT": frame(mav, "mission_item_int", 1, 1, 0, M.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT,
                                  M.MAV_CMD_NAV_WAYPOINT, 0, 1, 0, 0, 0, 0, int(lat * 1e7), int(lon * 1e7), 0, 0),
        "SET_MODE": frame(mav, "set_mode", 1, M.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED, int(Mode.MANUAL)),
        "MANUAL_CONTROL": frame(mav, "manual_control", 1, 1000, 0, 0, 1000, 0),
        "SET_POSITION_TARGET_GLOBAL_INT": frame(mav, "set_position_target_global_int", 0, 1, 1,
                                                M.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT, 0b0000_1111_1111_1000,
                                                int(lat * 1e7), int(lon * 1e7), 0.0, 0, 0, 0, 0, 0, 0, 0, 0),
    }


def test_every_handled_message_is_a_declared_write_or_a_declared_read():
    """A handler added later cannot bypass the signature check silently: each message type the link
    dispatches is either gated (WRITES) or a read the limits know."""
    link = GcsLink.open(gcs_params(), 1, 1, GEO)
    assert set(link.handlers) <= WRITES | READS
    assert READS - {"HEARTBEAT", "MISSION_ACK"} <= set(READ_LIMITS)
    assert not READ_COMMANDS & {M.MAV_CMD_SET_MESSAGE_INTERVAL, M.MAV_CMD_COMPONENT_ARM_DISARM}
    assert MISSION_WRITES <= WRITES


@pytest.mark.parametrize("signed_with", [None, bytes(32 * [7])], ids=["unsigned", "wrong_key"])
def test_with_signing_on_every_state_or_rate_changing_message_needs_a_good_signature(tmp_path, closing, signed_with):
    key_file = tmp_path / "gcs.key"
    key_file.write_text(KEY.hex())
    port = free_udp_port()
    link = GcsLink.open(gcs_params(f"udpin:127.0.0.1:{port}", key_file=str(key_file)), 1, 1, GEO)
    closing(link)
    api = Api()
    link.attach(api)
    gcs = udp_client(closing)
    intervals = dict(link.telemetry.intervals)
    mission = api.v.mission
    bad = _writes(signer(key=signed_with))
    for data in bad.values():
        gcs.sendto(data, ("127.0.0.1", port))
    collect(gcs, link, lambda ms: sum(link.received.values()) >= len(bad))
    reason = "unsigned" if signed_with is None else "bad_signature"
    assert link.summary()["security_rejects"] == {reason: len(bad)}
    assert link.telemetry.intervals == intervals and api.gain == 1.0 and api.v.mode == Mode.HOLD
    assert api.v.mission == mission and link.mission is not None and link.mission.upload is None
    # The same messages signed with the key are obeyed (a few, checked by their effect).
    good = _writes(signer())
    for kind in ("REQUEST_DATA_STREAM", "PARAM_SET", "SET_MODE"):
        gcs.sendto(good[kind], ("127.0.0.1", port))
    collect(gcs, link, lambda ms: api.v.mode == Mode.MANUAL and api.gain == 5.0)
    assert api.v.mode == Mode.MANUAL and api.gain == 5.0
    assert all(link.telemetry.intervals[n] == 0.0 for n in ("ATTITUDE", "VFR_HUD", "SYS_STATUS"))
    assert link.summary()["security_rejects"] == {reason: len(bad)}


def test_tlog_and_summaries_are_owner_only_when_a_key_is_set(tmp_path):
    from hil.files import write_json_atomic
    from hil.tap import Tap

    old = tmp_path / "run.tlog"
    old.write_bytes(b"")
    old.chmod(0o644)                               # an older run's file in the same folder
    tap = Tap(old, GEO, lockstep=True, private=True)
    tap.close()
    assert stat.S_IMODE(os.stat(old).st_mode) == 0o600
    write_json_atomic(tmp_path / "summary.json", {"outcome": "goal"}, private=True)
    assert stat.S_IMODE(os.stat(tmp_path / "summary.json").st_mode) == 0o600
    write_json_atomic(tmp_path / "public.json", {"outcome": "goal"})     # no key: as the other run files
    assert stat.S_IMODE(os.stat(tmp_path / "public.json").st_mode) == 0o666 & ~_umask()
    public = Tap(tmp_path / "public.tlog", GEO, lockstep=True)
    public.close()
    assert stat.S_IMODE(os.stat(tmp_path / "public.tlog").st_mode) & 0o044 == 0o044 & ~_umask()


def _umask() -> int:
    mask = os.umask(0o022)
    os.umask(mask)
    return mask


def test_one_datagram_packed_with_param_request_list_costs_one_dump_and_is_counted(closing):
    port = free_udp_port()
    link = GcsLink.open(gcs_params(f"udpin:127.0.0.1:{port}"), 1, 1, GEO, clock=FrozenClock())
    closing(link)
    link.attach(Api())
    n_params = len(link.params_table)
    gcs = udp_client(closing)
    mav = signer(key=None)
    one = frame(mav, "param_request_list", 1, 1)
    packed = one * (60000 // len(one))
    gcs.sendto(packed, ("127.0.0.1", port))
    got = collect(gcs, link, lambda ms: len([m for m in ms if m.get_type() == "PARAM_VALUE"]) >= n_params)
    # Service a while longer: no second dump may follow.
    got += collect(gcs, link, lambda ms: False, timeout=0.3)
    values = [m for m in got if m.get_type() == "PARAM_VALUE"]
    assert sorted(v.param_index for v in values) == list(range(n_params))
    reply_bytes = sum(len(m.get_msgbuf()) for m in values)
    assert reply_bytes < len(packed)                    # no amplification
    sec = link.summary()["security_rejects"]
    assert link.received["PARAM_REQUEST_LIST"] == FRAME_BUDGET   # the rest of the datagram was never decoded
    assert sec["frame_budget"] == 1
    # Of the decoded ones: one dump, one more list request inside the burst joined it, the rest refused.
    assert sec["param_list_coalesced"] == READ_LIMITS["PARAM_REQUEST_LIST"].burst - 1
    assert sec["rate_limited_PARAM_REQUEST_LIST"] == FRAME_BUDGET - READ_LIMITS["PARAM_REQUEST_LIST"].burst


def test_a_flood_of_read_requests_is_answered_within_the_limits_and_every_refusal_counted(closing):
    port = free_udp_port()
    link = GcsLink.open(gcs_params(f"udpin:127.0.0.1:{port}"), 1, 1, GEO, clock=FrozenClock())
    closing(link)
    link.attach(Api())
    gcs = udp_client(closing)
    gcs.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 1 << 20)
    mav = signer(key=None)
    requests = {
        "PARAM_REQUEST_READ": (frame(mav, "param_request_read", 1, 1, b"", 0), "PARAM_VALUE"),
        "MISSION_REQUEST_LIST": (frame(mav, "mission_request_list", 1, 1, 0), "MISSION_COUNT"),
        "PING": (frame(mav, "ping", 1, 7, 0, 0), "PING"),
        "READ_COMMAND": (frame(mav, "command_long", 1, 1, M.MAV_CMD_REQUEST_MESSAGE, 0,
                               mavlink2.MAVLINK_MSG_ID_AUTOPILOT_VERSION, 0, 0, 0, 0, 0, 0), "AUTOPILOT_VERSION"),
    }
    per_kind = 40    # 160 small datagrams: within the socket's buffer, more than two frame budgets
    for _ in range(per_kind):
        for data, _reply in requests.values():
            gcs.sendto(data, ("127.0.0.1", port))
    link.service()
    assert sum(link.received.values()) == FRAME_BUDGET      # one service call handles one budget
    got = collect(gcs, link, lambda ms: sum(link.received.values()) >= per_kind * len(requests))
    got += collect(gcs, link, lambda ms: False, timeout=0.3)
    sec = link.summary()["security_rejects"]
    for kind, (_data, reply) in requests.items():
        answered = len([m for m in got if m.get_type() == reply])
        allowed = int(READ_LIMITS[kind].burst)
        assert answered == min(per_kind, allowed), kind
        assert sec.get(f"rate_limited_{kind}", 0) == per_kind - answered, kind
    # A read command that is let through is answered with its ACK; refused ones get nothing.
    assert acks(got).count(M.MAV_RESULT_ACCEPTED) == int(READ_LIMITS["READ_COMMAND"].burst)


def test_rate_limits_refill_with_time(closing):
    clock = FrozenClock()
    port = free_udp_port()
    link = GcsLink.open(gcs_params(f"udpin:127.0.0.1:{port}"), 1, 1, GEO, clock=clock)
    closing(link)
    link.attach(Api())
    gcs = udp_client(closing)
    ping = frame(signer(key=None), "ping", 1, 7, 0, 0)
    burst = int(READ_LIMITS["PING"].burst)

    def pings(n: int) -> int:
        before = link.received["PING"]
        for _ in range(n):
            gcs.sendto(ping, ("127.0.0.1", port))
        got = collect(gcs, link, lambda ms: link.received["PING"] >= before + n)
        got += collect(gcs, link, lambda ms: False, timeout=0.2)
        return len([m for m in got if m.get_type() == "PING"])

    assert pings(burst + 5) == burst
    clock.t += 1.0 / READ_LIMITS["PING"].per_s       # one token
    assert pings(3) == 1
    clock.t += 3600.0                                 # full again, never more than the burst
    assert pings(burst + 5) == burst


def test_a_tcp_burst_beyond_the_budget_is_handled_over_several_calls_not_dropped(closing):
    """A stream's frames beyond one call's budget stay in its parser and are handled on the next calls."""
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        tcp_port = s.getsockname()[1]
    link = GcsLink.open(gcs_params(f"tcpin:127.0.0.1:{tcp_port}"), 1, 1, GEO, clock=FrozenClock())
    closing(link)
    link.attach(Api())
    tcp = socket.create_connection(("127.0.0.1", tcp_port))
    closing(tcp)
    mav = signer(key=None)
    n = 3 * FRAME_BUDGET + 5
    tcp.sendall(b"".join(frame(mav, "heartbeat", M.MAV_TYPE_GCS, M.MAV_AUTOPILOT_INVALID, 0, 0, 0) for _ in range(n)))
    calls = 0
    end = time.monotonic() + 5.0
    while link.received["HEARTBEAT"] < n and time.monotonic() < end:
        before = link.received["HEARTBEAT"]
        link.service()
        assert link.received["HEARTBEAT"] - before <= FRAME_BUDGET
        calls += link.received["HEARTBEAT"] > before
    assert link.received["HEARTBEAT"] == n and calls >= 4
    assert "frame_budget" not in link.summary()["security_rejects"]


def test_a_second_tcp_ground_station_is_not_cut_when_the_first_spends_the_budget(closing):
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        tcp_port = s.getsockname()[1]
    link = GcsLink.open(gcs_params(f"tcpin:127.0.0.1:{tcp_port}"), 1, 1, GEO, clock=FrozenClock())
    closing(link)
    link.attach(Api())
    a, b = (socket.create_connection(("127.0.0.1", tcp_port)) for _ in range(2))
    closing(a)
    closing(b)
    mav = signer(key=None)
    hb = frame(mav, "heartbeat", M.MAV_TYPE_GCS, M.MAV_AUTOPILOT_INVALID, 0, 0, 0)
    n = 2 * FRAME_BUDGET
    a.sendall(hb * n)
    b.sendall(hb * n)
    end = time.monotonic() + 5.0
    while link.received["HEARTBEAT"] < 2 * n and time.monotonic() < end:
        link.service()
    assert link.received["HEARTBEAT"] == 2 * n and link.rejects == {}
    assert "frame_budget" not in link.summary()["security_rejects"]


def test_a_disarm_with_param2_21196_reaches_the_vehicle_as_forced_and_any_other_as_not(closing):
    """MAV_CMD_COMPONENT_ARM_DISARM's param2 = 21196 (MAVLink: force) is a forced disarm, which the vessel
    takes even where a disarm would leave the boat to drift onto the quay; any other param2 is not."""
    udp_port = free_udp_port()
    link = GcsLink.open(gcs_params(f"udpin:127.0.0.1:{udp_port}"), 1, 1, GEO)
    closing(link)
    api = Api()
    link.attach(api)
    gcs = udp_client(closing)
    mav = mavlink2.MAVLink(None, 255, 190)
    for param2, forced in ((0.0, False), (21196.0, True), (2989.0, False)):
        gcs.sendto(frame(mav, "command_long", 1, 1, M.MAV_CMD_COMPONENT_ARM_DISARM, 0, 0.0, param2, 0, 0, 0, 0, 0),
                   ("127.0.0.1", udp_port))
        assert acks(collect(gcs, link, lambda ms: acks(ms))) == [M.MAV_RESULT_ACCEPTED]
        assert api.forced is forced, param2
