"""One connection-string grammar (common/connection.py, issue 16) on every endpoint, each form on real
sockets on 127.0.0.1 (serial through a pty pair), and refused forms that end the command with exit 2."""

from __future__ import annotations

import os
import socket
import time

import pytest

from autopilot_bridge.gcs.link import GcsLink
from autopilot_bridge.gcs.transport import open_endpoint
from common import connection as c
from common.mavlink import mavlink2
from common.udp import UdpEndpoint
from hil import cli, settings
from hil.errors import ConfigError
from hil.hilrun import free_udp_port
from tests.test_gcs_link import GEO, ais, free_tcp_port, gcs_heartbeat, params, read_until


@pytest.mark.parametrize("text, role, expected", [
    ("udpin:127.0.0.1:14550", c.GCS, ("udpin", "127.0.0.1", 14550)),
    ("udp:0.0.0.0:14550", c.GCS, ("udpin", "0.0.0.0", 14550)),
    ("UDPOUT:localhost:14550", c.GCS, ("udpout", "localhost", 14550)),
    ("tcp:127.0.0.1:5760", c.GCS, ("tcp", "127.0.0.1", 5760)),
    ("tcpin:127.0.0.1:5760", c.GCS, ("tcpin", "127.0.0.1", 5760)),
    ("127.0.0.1:14550", c.GCS, ("udpout", "127.0.0.1", 14550)),
    ("127.0.0.1:14560", c.SEND_UDP, ("udpout", "127.0.0.1", 14560)),
    ("udpout:127.0.0.1:14560", c.SEND_UDP, ("udpout", "127.0.0.1", 14560)),
    ("127.0.0.1:0", c.RECEIVE_UDP, ("udpin", "127.0.0.1", 0)),
    ("udp:127.0.0.1:14561", c.RECEIVE_UDP, ("udpin", "127.0.0.1", 14561)),
    ("[::1]:14550", c.GCS, ("udpout", "::1", 14550)),
])
def test_every_form_parses(text, role, expected):
    conn = c.parse(text, role)
    assert (conn.kind, conn.host, conn.port) == expected == conn.endpoint


def test_serial_form():
    conn = c.parse("serial:/dev/ttyUSB0:57600", c.GCS)
    assert (conn.kind, conn.device, conn.baud) == ("serial", "/dev/ttyUSB0", 57600) == conn.endpoint


@pytest.mark.parametrize("text, role, says", [
    ("tcp:127.0.0.1:5760", c.SEND_UDP, "accepted forms here: HOST:PORT, udpout:HOST:PORT"),
    ("udpout:127.0.0.1:5760", c.RECEIVE_UDP, "accepted forms here: HOST:PORT, udpin:HOST:PORT, udp:HOST:PORT"),
    ("serial:/dev/ttyS0:57600", c.SEND_UDP, "accepted forms here"),
    ("udpx:127.0.0.1:1", c.GCS, "unknown prefix 'udpx:'"),
    ("/dev/ttyUSB0:57600", c.GCS, "serial:/dev/ttyUSB0:57600"),
    ("serial:/dev/ttyUSB0:57601", c.GCS, "not a standard one"),
    ("udpout:127.0.0.1:0", c.GCS, "not 0"),
    ("tcp:127.0.0.1", c.GCS, "expected HOST:PORT"),
    ("127.0.0.1:70000", c.SEND_UDP, "outside 0-65535"),
    ("localhost", c.SEND_UDP, "expected HOST:PORT"),
])
def test_refused_forms_name_the_accepted_ones(text, role, says):
    with pytest.raises(ValueError, match=None) as exc:
        c.parse(text, role)
    assert says in str(exc.value) and "\n" not in str(exc.value)


def test_udp_endpoint_sends_to_udpout_and_binds_udpin():
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as rx:
        rx.bind(("127.0.0.1", 0))
        rx.settimeout(5.0)
        port = rx.getsockname()[1]
        with UdpEndpoint("udpin:127.0.0.1:0", [f"udpout:127.0.0.1:{port}", f"127.0.0.1:{port}"]) as ep:
            ep.send(b"x")
            assert rx.recvfrom(100) == (b"x", ep.address) and rx.recvfrom(100)[0] == b"x"
        with UdpEndpoint("udp:127.0.0.1:0") as ep:
            rx.sendto(b"y", ep.address)
            assert ep.recv(5.0) == b"y"


def test_hil_sim_state_to_udpout_really_sends():
    """The bug of issue 16: `--state-to udpout:...` was accepted and nothing arrived."""
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as rx:
        rx.bind(("127.0.0.1", 0))
        rx.settimeout(0.0)
        port = rx.getsockname()[1]
        rc = cli.main(["sim", "--state-to", f"udpout:127.0.0.1:{port}", "--commands-on", "udpin:127.0.0.1:0",
                       "--duration", "0.3", "--speedup", "20", "--json"])
        assert rc == 0
        got = 0
        while True:
            try:
                rx.recv(65535)
            except BlockingIOError:
                break
            got += 1
        assert got >= 10


@pytest.mark.parametrize("argv, says", [
    (["sim", "--state-to", "tcp:127.0.0.1:14560"], "--state-to: 'tcp:127.0.0.1:14560': this endpoint sends UDP"),
    (["sim", "--state-to", "udpot:127.0.0.1:14560"], "unknown prefix 'udpot:'"),
    (["sim", "--commands-on", "udpout:127.0.0.1:14561"], "accepted forms here: HOST:PORT, udpin:HOST:PORT"),
    (["autopilot", "--listen", "tcpin:127.0.0.1:14560"], "--listen"),
    (["autopilot", "--actuators-to", "udpin:127.0.0.1:14561"], "--actuators-to"),
    (["autopilot", "--gcs", "tcpout:127.0.0.1:5760"], "unknown prefix 'tcpout:'"),
    (["run", "--gcs", "serial:/dev/ttyUSB0:12"], "not a standard one"),
    (["sim", "--set", 'link.state_to=["tcpin:127.0.0.1:1"]'],
     "--set link.state_to=[\"tcpin:127.0.0.1:1\"]: link.state_to: 'tcpin:127.0.0.1:1'"),
])
def test_a_refused_form_never_runs(argv, says, capsys):
    with pytest.raises(SystemExit) as exc:
        rc = cli.main(argv + ["--duration", "0.1"] if argv[0] == "sim" else argv)
        raise SystemExit(rc)
    assert exc.value.code == 2
    err = capsys.readouterr().err
    assert says in err and err.count("\n") == 1, err


def test_a_config_file_with_a_bad_endpoint_names_file_and_key(tmp_path):
    p = tmp_path / "links.toml"
    p.write_text('[autopilot]\nactuators_to = ["tcp:127.0.0.1:14561"]\n')
    with pytest.raises(ConfigError, match=rf"^{p}: autopilot\.actuators_to: 'tcp:127.0.0.1:14561': this endpoint"):
        settings.load(p)


@pytest.fixture
def closing():
    items = []
    yield items.append
    for it in items:
        it.close()


def test_gcs_udp_is_udpin(closing):
    port = free_udp_port()
    link = GcsLink.open(params(f"udp:127.0.0.1:{port}"), 1, 1, GEO)
    closing(link)
    gcs = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    closing(gcs)
    gcs.bind(("127.0.0.1", 0))
    gcs.sendto(gcs_heartbeat(), ("127.0.0.1", port))
    end = time.monotonic() + 5.0
    while link.received["HEARTBEAT"] < 1 and time.monotonic() < end:
        link.service()
        time.sleep(0.01)
    ais(link)
    assert read_until(gcs, "AIS_VESSEL", link) is not None


def test_gcs_tcp_client_connects_talks_and_reconnects(closing):
    server = socket.socket()
    closing(server)
    server.bind(("127.0.0.1", 0))
    server.listen(1)
    port = server.getsockname()[1]
    link = GcsLink.open(params(f"tcp:127.0.0.1:{port}"), 1, 1, GEO)
    closing(link)
    conn, _ = server.accept()
    closing(conn)
    conn.sendall(gcs_heartbeat())
    ais(link)
    assert read_until(conn, "AIS_VESSEL", link) is not None
    assert link.received["HEARTBEAT"] >= 1
    conn.close()  # the ground station goes away and comes back: the boat reconnects by itself
    server.settimeout(0.05)
    end, again = time.monotonic() + 10.0, None
    while again is None and time.monotonic() < end:
        link.service()
        try:
            again, _ = server.accept()
        except TimeoutError:
            pass
    assert again is not None
    closing(again)
    while not link.transports[0].connected and time.monotonic() < end:
        link.service()
    ais(link)
    assert read_until(again, "AIS_VESSEL", link) is not None


def test_gcs_tcp_client_without_a_server_is_a_start_up_error():
    port = free_tcp_port()
    with pytest.raises(ValueError, match=f"cannot connect to TCP 127.0.0.1:{port}"):
        open_endpoint(c.parse(f"tcp:127.0.0.1:{port}", c.GCS))


def test_gcs_serial_through_a_pty_pair(closing):
    pytest.importorskip("serial", reason="the serial: form needs pyserial")
    master, slave = os.openpty()
    device = os.ttyname(slave)
    try:
        link = GcsLink.open(params(f"serial:{device}:57600"), 1, 1, GEO)
        closing(link)
        hb = gcs_heartbeat()
        os.write(master, hb[:5])
        link.service()
        os.write(master, hb[5:])
        end = time.monotonic() + 5.0
        while link.received["HEARTBEAT"] < 1 and time.monotonic() < end:
            link.service()
            time.sleep(0.01)
        assert link.received["HEARTBEAT"] == 1  # a frame split across reads is reassembled
        ais(link)
        parser = mavlink2.MAVLink(None, 255, 190)
        os.set_blocking(master, False)
        got = None
        while got is None and time.monotonic() < end:
            link.service()
            try:
                data = os.read(master, 65536)
            except BlockingIOError:
                time.sleep(0.01)
                continue
            got = next((m for m in parser.parse_buffer(data) or [] if m.get_type() == "AIS_VESSEL"), None)
        assert got is not None
    finally:
        os.close(master)
        os.close(slave)


def test_gcs_serial_that_does_not_exist_is_one_line():
    pytest.importorskip("serial", reason="the serial: form needs pyserial")
    with pytest.raises(ValueError, match="cannot open serial port /dev/nonexistent-tty"):
        open_endpoint(c.parse("serial:/dev/nonexistent-tty:57600", c.GCS))
