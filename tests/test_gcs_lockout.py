"""No process on the network can lock a ground station out (issue 31, points 1 and 4; docs/security.md).

Each attack of the issue's red-team round, reproduced in-process on real loopback sockets with
pymavlink bytes, on private ports, with the link's (and its transports') clock a fake advanced by the
test: nothing depends on machine load.

* UDP peer-table eviction: 12 sockets sending HEARTBEATs cannot push a ground station that keeps
  talking out of the ``udpin`` endpoint's 8-peer table; with signing on, a signed GCS that arrives
  after them displaces one.
* TCP exhaustion: 8 idle connections no longer lock out the 9th; idle connections are closed; a
  per-address cap.
* Mission-upload lock-out: a peer that re-sends MISSION_COUNT every second and never answers keeps
  the upload for at most a second after its first request; the real GCS's retry succeeds.
* Signing: one good frame stamped a day ahead is refused and changes no replay state.
"""

from __future__ import annotations

import socket
from typing import Any

import pytest
from test_gcs_security import KEY, Api, FrozenClock, frame, gcs_params, signer, udp_client

from autopilot_bridge.gcs import transport as tp
from autopilot_bridge.gcs.link import GcsLink
from autopilot_bridge.gcs.peers import PEER_STALE_S
from autopilot_bridge.gcs.signing import FUTURE_SLACK, signing_now
from common.geodesy import LocalFrame
from common.mavlink import MAV_TYPE as M
from common.mavlink import mavlink2
from hil.hilrun import free_udp_port

GEO = LocalFrame(38.92, 121.65, 0.0)


@pytest.fixture
def closing():
    items: list = []
    yield items.append
    for it in items:
        it.close()


def heartbeat(mav: Any, kind: int = M.MAV_TYPE_GCS) -> bytes:
    return frame(mav, "heartbeat", kind, M.MAV_AUTOPILOT_INVALID, 0, 0, 0)


def received(sock: socket.socket) -> list:
    """Every MAVLink message waiting on ``sock`` (non-blocking)."""
    parser = mavlink2.MAVLink(None, 255, 190)
    parser.robust_parsing = True
    out: list = []
    sock.setblocking(False)
    while True:
        try:
            data = sock.recv(65535)
        except (BlockingIOError, InterruptedError):
            return out
        if not data:
            return out
        out += [m for m in parser.parse_buffer(data) or [] if not isinstance(m, mavlink2.MAVLink_bad_data)]


def service_until(link: GcsLink, done: Any, calls: int = 400) -> None:
    """Service the link until ``done()`` (bounded by calls; each call waits on nothing)."""
    import select

    for _ in range(calls):
        link.service()
        if done():
            return
        select.select([t for t in link.transports], [], [], 0.005)


def service_past(link: GcsLink, n: int) -> None:
    """Service the link until it has read more than ``n`` datagrams in all (bounded)."""
    service_until(link, lambda: link.datagrams_in > n)


def statustexts(msgs: list) -> list[str]:
    return [m.text for m in msgs if m.get_type() == "STATUSTEXT"]


def make_link(closing: Any, clock: FrozenClock, *endpoints: str, key_file: str = "") -> GcsLink:
    link = GcsLink.open(gcs_params(*endpoints, key_file=key_file), 1, 1, GEO, clock=clock)
    closing(link)
    link.attach(Api())
    return link


def key_file(tmp_path: Any) -> str:
    p = tmp_path / "gcs.key"
    p.write_text(KEY.hex())
    return str(p)


# -- UDP peer table ---------------------------------------------------------------------------------

@pytest.mark.parametrize("signing", [True, False])
def test_twelve_heartbeat_senders_cannot_push_a_talking_gcs_out_of_the_udp_peer_table(tmp_path, closing, signing):
    clock = FrozenClock()
    port = free_udp_port()
    link = make_link(closing, clock, f"udpin:127.0.0.1:{port}", key_file=key_file(tmp_path) if signing else "")
    gcs = udp_client(closing)
    mav = signer(key=KEY if signing else None)
    gcs.sendto(heartbeat(mav), ("127.0.0.1", port))
    udp = link.transports[0]
    service_until(link, lambda: gcs.getsockname() in udp.peers)
    assert gcs.getsockname() in udp.peers
    strangers = [udp_client(closing) for _ in range(12)]
    for second in range(6):          # six seconds of the attack: the GCS sends its 1 Hz HEARTBEAT
        clock.t += 1.0
        gcs.sendto(heartbeat(mav), ("127.0.0.1", port))
        for i, s in enumerate(strangers):
            s.sendto(heartbeat(mavlink2.MAVLink(None, 100 + i, 190)), ("127.0.0.1", port))
        service_past(link, (second + 2) * 13 - 13)
    assert gcs.getsockname() in udp.peers
    received(gcs)
    link.statustext("still here")
    assert "still here" in statustexts(received(gcs))
    refused = link.summary()["security_rejects"]["peer_table_full"]
    assert refused >= 5 * 6 - 1       # 7 places for 12 strangers each second: the rest were refused
    if not signing:
        # Without signing a stranger that talks like a GCS takes a place once the GCS has been silent
        # for PEER_STALE_S: what holds with signing off (docs/security.md).
        clock.t += PEER_STALE_S + 0.1
        outsider = next(s for s in strangers if s.getsockname() not in udp.peers)
        outsider.sendto(heartbeat(mavlink2.MAVLink(None, 100, 190)), ("127.0.0.1", port))
        n = link.datagrams_in
        service_until(link, lambda: link.datagrams_in > n)
        assert gcs.getsockname() not in udp.peers


def test_with_signing_a_signed_gcs_arriving_after_the_strangers_displaces_one(tmp_path, closing):
    clock = FrozenClock()
    port = free_udp_port()
    link = make_link(closing, clock, f"udpin:127.0.0.1:{port}", key_file=key_file(tmp_path))
    udp = link.transports[0]
    strangers = [udp_client(closing) for _ in range(12)]
    for i, s in enumerate(strangers):
        s.sendto(heartbeat(mavlink2.MAVLink(None, 100 + i, 190)), ("127.0.0.1", port))
    service_until(link, lambda: link.datagrams_in >= 12)
    assert len(udp.peers) == 8
    gcs = udp_client(closing)
    gcs.sendto(heartbeat(signer()), ("127.0.0.1", port))
    service_until(link, lambda: gcs.getsockname() in udp.peers)
    assert gcs.getsockname() in udp.peers and len(udp.peers) == 8
    assert link.summary()["security_rejects"]["peer_displaced"] == 1
    # An unsigned write refused by the gate makes no peer of its sender.
    intruder = udp_client(closing)
    intruder.sendto(frame(mavlink2.MAVLink(None, 77, 190), "command_long", 1, 1,
                          M.MAV_CMD_COMPONENT_ARM_DISARM, 0, 1.0, 0, 0, 0, 0, 0, 0), ("127.0.0.1", port))
    n = link.datagrams_in
    service_until(link, lambda: link.datagrams_in > n)
    assert intruder.getsockname() not in udp.peers and link.api is not None and not link.api.v.armed


# -- TCP ----------------------------------------------------------------------------------------------

def tcp_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def connect(port: int, closing: Any, source: str = "127.0.0.1") -> socket.socket:
    s = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
    closing(s)
    s.bind((source, 0))
    s.connect(("127.0.0.1", port))
    return s


def closed_by_peer(s: socket.socket) -> bool:
    """Whether the link closed the connection (what it sent before is read and dropped)."""
    s.setblocking(False)
    for _ in range(1000):
        try:
            if s.recv(65535) == b"":
                return True
        except (BlockingIOError, InterruptedError):
            return False
        except OSError:
            return True
    return False


def test_eight_idle_tcp_connections_no_longer_lock_out_the_ninth(closing):
    clock = FrozenClock()
    port = tcp_port()
    link = make_link(closing, clock, f"tcpin:127.0.0.1:{port}")
    tr = link.transports[0]
    idle = [connect(port, closing, f"127.0.0.{2 + i // 4}") for i in range(8)]   # 4 per address: the cap
    service_until(link, lambda: tr.counts["tcp_pending_displaced"] >= 4)
    gcs = connect(port, closing)
    gcs.sendall(heartbeat(signer(key=None)))
    service_until(link, lambda: ("tcp", gcs.getsockname()) in tr.peers)
    assert ("tcp", gcs.getsockname()) in tr.peers
    received(gcs)
    link.statustext("tcp ok")
    service_until(link, lambda: False, calls=3)
    assert "tcp ok" in statustexts(received(gcs))
    # The idle ones: four displaced at once, the rest closed once TCP_PROVE_S has passed without a frame.
    clock.t += tp.TCP_PROVE_S + 0.1
    service_until(link, lambda: not tr.pending, calls=5)
    assert not tr.pending and all(closed_by_peer(s) for s in idle)
    s = link.summary()["security_rejects"]
    assert s["tcp_pending_displaced"] + s["tcp_idle_closed"] == 8
    # The GCS keeps its place while it talks, and loses it after TCP_IDLE_S of silence.
    for _ in range(3):
        gcs.sendall(heartbeat(signer(key=None)))
        service_past(link, link.datagrams_in)
        assert ("tcp", gcs.getsockname()) in tr.peers
        clock.t += tp.TCP_IDLE_S - 1.0
    clock.t += tp.TCP_IDLE_S + 0.1
    service_until(link, lambda: ("tcp", gcs.getsockname()) not in tr.conns, calls=5)
    assert ("tcp", gcs.getsockname()) not in tr.conns and closed_by_peer(gcs)


def test_the_issues_attack_eight_idle_connections_from_one_address_then_a_gcs(closing):
    clock = FrozenClock()
    port = tcp_port()
    link = make_link(closing, clock, f"tcpin:127.0.0.1:{port}")
    tr = link.transports[0]
    idle = [connect(port, closing) for _ in range(8)]
    service_until(link, lambda: tr.counts["tcp_per_address_cap"] >= 4)
    gcs = connect(port, closing)
    gcs.sendall(heartbeat(signer(key=None)))
    service_until(link, lambda: ("tcp", gcs.getsockname()) in tr.peers)
    assert ("tcp", gcs.getsockname()) in tr.peers        # before issue 31: accepted and closed at once
    assert sum(closed_by_peer(s) for s in idle) == 5      # 4 displaced by the cap, 1 by the GCS
    assert len(tr.conns) == tp.TCP_PER_ADDRESS


def test_one_address_gets_at_most_tcp_per_address_connections(closing):
    clock = FrozenClock()
    port = tcp_port()
    link = make_link(closing, clock, f"tcpin:127.0.0.1:{port}")
    tr = link.transports[0]
    talkers = [connect(port, closing, "127.0.0.9") for _ in range(tp.TCP_PER_ADDRESS)]
    for i, s in enumerate(talkers):
        s.sendall(heartbeat(mavlink2.MAVLink(None, 50 + i, 190)))
    service_until(link, lambda: len(tr.peers) == tp.TCP_PER_ADDRESS)
    extra = connect(port, closing, "127.0.0.9")   # every place of that address is earned: refused
    service_until(link, lambda: tr.counts["tcp_per_address_cap"] >= 1)
    assert link.summary()["security_rejects"]["tcp_per_address_cap"] == 1
    service_until(link, lambda: False, calls=2)
    assert closed_by_peer(extra) and len(tr.conns) == tp.TCP_PER_ADDRESS
    other = connect(port, closing, "127.0.0.1")   # another address is not affected
    other.sendall(heartbeat(signer(key=None)))
    service_until(link, lambda: ("tcp", other.getsockname()) in tr.peers)
    assert ("tcp", other.getsockname()) in tr.peers


# -- mission upload -----------------------------------------------------------------------------------

def mission_acks(msgs: list, sysid: int) -> list[int]:
    return [m.type for m in msgs if m.get_type() == "MISSION_ACK" and m.target_system == sysid]


def upload(link: GcsLink, sock: socket.socket, mav: Any, port: int, count: int = 2) -> list[int]:
    """A GCS's mission upload as MAVProxy does it; the MISSION_ACKs it got."""
    received(sock)
    sock.sendto(frame(mav, "mission_count", 1, 1, count, 0), ("127.0.0.1", port))
    lat, lon = int(GEO.lat0 * 1e7), int(GEO.lon0 * 1e7)
    got: list = []
    for _ in range(200):
        link.service()
        got += received(sock)
        reqs = [m for m in got if m.get_type() == "MISSION_REQUEST_INT" and m.target_system == mav.srcSystem]
        if mission_acks(got, mav.srcSystem):
            return mission_acks(got, mav.srcSystem)
        for r in reqs:
            sock.sendto(frame(mav, "mission_item_int", 1, 1, r.seq, M.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT,
                              M.MAV_CMD_NAV_WAYPOINT, 0, 1, 0, 0, 0, float("nan"), lat + 100 * (r.seq + 1), lon, 0),
                        ("127.0.0.1", port))
        got = [m for m in got if m.get_type() != "MISSION_REQUEST_INT"]
        import select

        select.select([sock], [], [], 0.005)
    return mission_acks(got, mav.srcSystem)


def test_a_peer_resending_mission_count_and_never_answering_cannot_hold_the_upload(closing):
    clock = FrozenClock()
    port = free_udp_port()
    link = make_link(closing, clock, f"udpin:127.0.0.1:{port}")   # signing off: any local process may try
    attacker, gcs = udp_client(closing), udp_client(closing)
    amav, gmav = mavlink2.MAVLink(None, 66, 190), mavlink2.MAVLink(None, 255, 190)
    gcs.sendto(heartbeat(gmav), ("127.0.0.1", port))
    attempts: list[list[int]] = []
    start = clock.t
    # The attack: MISSION_COUNT every second, never an item. The GCS tries to upload twice a second.
    for tick in range(12):
        if tick % 2 == 0:
            attacker.sendto(frame(amav, "mission_count", 1, 1, 5, 0), ("127.0.0.1", port))
            service_past(link, link.datagrams_in)
        else:
            acks = upload(link, gcs, gmav, port)
            attempts.append(acks)
            if acks == [M.MAV_MISSION_ACCEPTED]:
                break
        clock.t += 0.5
    # The first try came 0.5 s into the attacker's claim: denied; the next one, 1.5 s in, succeeds.
    assert attempts[-1] == [M.MAV_MISSION_ACCEPTED], attempts
    assert len(attempts) <= 2 and clock.t - start <= 2.0
    stats = link.summary()["mission"]
    assert stats["uploads_accepted"] == 1 and stats.get("upload_taken_over", 0) + stats.get("upload_timeouts", 0) >= 1
    # The attacker's restarts after that are refused while the GCS's upload is fresh, never the reverse.
    assert link.mission is not None and len(link.mission.items) == 2


def test_a_denied_gcs_is_owed_the_next_turn(closing):
    clock = FrozenClock()
    port = free_udp_port()
    link = make_link(closing, clock, f"udpin:127.0.0.1:{port}")
    attacker, gcs = udp_client(closing), udp_client(closing)
    amav, gmav = mavlink2.MAVLink(None, 66, 190), mavlink2.MAVLink(None, 255, 190)
    attacker.sendto(frame(amav, "mission_count", 1, 1, 5, 0), ("127.0.0.1", port))
    service_until(link, lambda: link.datagrams_in >= 1)
    assert upload(link, gcs, gmav, port) == [M.MAV_MISSION_DENIED]
    # The attacker's upload times out (re-requests unanswered) and it starts a new one at once: refused,
    # the turn is the GCS's.
    for _ in range(8):
        clock.t += 0.3
        link.service()
    assert link.mission is not None and link.mission.upload is None
    received(attacker)
    attacker.sendto(frame(amav, "mission_count", 1, 1, 5, 0), ("127.0.0.1", port))
    got: list = []
    service_until(link, lambda: bool(mission_acks(got, 66)) or bool(got.extend(received(attacker))))
    assert mission_acks(got, 66) == [M.MAV_MISSION_DENIED]
    assert upload(link, gcs, gmav, port) == [M.MAV_MISSION_ACCEPTED]
    assert link.summary()["mission"]["reserved_for_rival"] == 1


# -- signing clock ------------------------------------------------------------------------------------

def test_a_signed_frame_stamped_a_day_ahead_is_refused_and_locks_no_stream_out(tmp_path, closing):
    clock = FrozenClock()
    port = free_udp_port()
    link = make_link(closing, clock, f"udpin:127.0.0.1:{port}", key_file=key_file(tmp_path))
    wrong = udp_client(closing)
    wmav = signer(sysid=200)
    wmav.signing.timestamp = signing_now() + 86400 * 100_000      # a GCS whose clock is a day fast
    wrong.sendto(frame(wmav, "command_long", 1, 1, M.MAV_CMD_COMPONENT_ARM_DISARM, 0, 1.0, 0, 0, 0, 0, 0, 0),
                 ("127.0.0.1", port))
    service_until(link, lambda: link.datagrams_in >= 1)
    assert link.api is not None and not link.api.v.armed
    s = link.summary()
    assert s["signature_failures"] == {"future": 1} and s["security_rejects"] == {"future": 1}
    assert link.guard is not None and link.guard.streams == {}
    assert link.guard.timestamp <= signing_now() + FUTURE_SLACK
    # A new stream at the right time, and the same GCS once its clock is right, are accepted.
    gcs = udp_client(closing)
    gcs.sendto(frame(signer(sysid=201), "command_long", 1, 1, M.MAV_CMD_COMPONENT_ARM_DISARM, 0, 1.0,
                     0, 0, 0, 0, 0, 0), ("127.0.0.1", port))
    service_until(link, lambda: link.api is not None and link.api.v.armed)
    assert link.api.v.armed
    wmav.signing.timestamp = signing_now()
    wrong.sendto(frame(wmav, "command_long", 1, 1, M.MAV_CMD_COMPONENT_ARM_DISARM, 0, 0.0, 0, 0, 0, 0, 0, 0),
                 ("127.0.0.1", port))
    service_until(link, lambda: not link.api.v.armed)
    assert not link.api.v.armed
    # Within the bound (a few seconds fast) is still accepted.
    ahead = signer(sysid=202)
    ahead.signing.timestamp = signing_now() + 5 * 100_000
    gcs.sendto(frame(ahead, "command_long", 1, 1, M.MAV_CMD_COMPONENT_ARM_DISARM, 0, 1.0, 0, 0, 0, 0, 0, 0),
               ("127.0.0.1", port))
    service_until(link, lambda: link.api.v.armed)
    assert link.api.v.armed
