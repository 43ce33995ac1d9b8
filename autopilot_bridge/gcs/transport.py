"""Ground-station transports, configured by the connection strings of :mod:`common.connection`
(pymavlink mavutil's grammar, as MAVProxy and MAVSDK write them).

* ``udpout:HOST:PORT`` - a socket on a free local port sends everything to HOST:PORT (the way SITL
  sends to 14550, so a GCS listening there sees the boat with no configuration); whoever sends
  a valid MAVLink frame to that socket is answered too.
* ``udpin:HOST:PORT`` (or ``udp:HOST:PORT``) - listen on HOST:PORT; every peer heard is answered.
* ``tcpin:HOST:PORT`` - accept TCP connections on HOST:PORT; each connection is one peer with its
  own stream parser (frames may span reads).
* ``tcp:HOST:PORT`` - connect to a ground station's TCP server; a lost connection is retried once
  a second (the boat never waits for it).
* ``serial:DEVICE:BAUD`` - a telemetry radio on a serial port, through pyserial.
* ``HOST:PORT`` - as ``udpout:``.

Peers are earned (issue 31, :mod:`.peers`): a sender becomes a peer only once one of its frames has
passed the link's security gate, and the table of up to ``max_peers`` peers per endpoint keeps signed
ground stations (or, without signing, those that talk like one) ahead of strangers; a TCP connection
that earns no place, or falls silent, is closed. Every transport has the same small interface:
:meth:`receive` gives ``(peer, bytes)`` chunks (at most ``max_reads`` reads per peer, none from the
peers in ``hold``: the link's frame budget; a held TCP peer is throttled by TCP's own flow control;
``(peer, b"")`` says a stream ended), :meth:`send` fans a frame out to every peer, :meth:`heard`
records that a frame of a given rank from a peer passed the gate.
"""

from __future__ import annotations

import socket
import time
from collections import Counter
from collections.abc import Callable, Collection, Hashable
from typing import cast

from autopilot_bridge.gcs.peers import RANK_STRANGER, PeerTable
from common import connection
from common.udp import UdpEndpoint

KINDS = ("udpout", "udpin", "tcp", "tcpin", "serial")
RECONNECT_S = 1.0  # tcp: seconds between connection attempts while the ground station is away
TCP_PENDING = 4          # tcpin: connections at once that have not yet sent a frame that passed the gate
TCP_PER_ADDRESS = 4      # tcpin: connections at once from one IP address
TCP_PROVE_S = 5.0        # tcpin: s a new connection has to send a frame that passes the gate
TcpPeer = tuple[str, tuple[str, int]]   # an accepted connection: ("tcp", (host, port))
TCP_IDLE_S = 10.0        # tcpin: s without a frame (a GCS sends a HEARTBEAT every second) before a peer is closed
TCP_ACCEPTS_PER_CALL = 16


def parse_endpoint(text: str) -> tuple[str, str, int]:
    """(kind, host, port) from a connection string (``common.connection``, role GCS); ``udp:`` gives
    "udpin"; for ``serial:DEVICE:BAUD`` the host is the device and the port the baud rate.
    ValueError with one line naming the accepted forms otherwise."""
    return connection.parse(text, connection.GCS).endpoint


class UdpTransport:
    """udpout / udpin over :class:`common.udp.UdpEndpoint`; the peers answered are a :class:`.peers.PeerTable`."""

    stream = False

    def __init__(self, kind: str, host: str, port: int, peers: PeerTable) -> None:
        """``peers``: the endpoint's peer table, built by :func:`open_endpoint`."""
        self.kind = kind
        self.peers = peers
        bind = f"{host}:{port}" if kind == "udpin" else ("127.0.0.1:0" if host in ("127.0.0.1", "localhost")
                                                         else "0.0.0.0:0")
        self.ep = UdpEndpoint(bind, [])
        self.fixed = [(socket.gethostbyname(host), port)] if kind == "udpout" else []
        self.sent = 0

    @property
    def address(self) -> tuple[str, int]:
        return self.ep.address

    def fileno(self) -> int:
        return self.ep.sock.fileno()

    def receive(self, max_reads: int = 256, hold: Collection[Hashable] = ()) -> list[tuple[Hashable, bytes]]:
        out: list[tuple[Hashable, bytes]] = []
        for _ in range(min(256, max_reads)):  # bounded per call: a flood cannot starve the control loop
            data = self.ep.recv(timeout=0.0)
            if data is None:
                break
            out.append((self.ep.last_sender, data))
        return out

    def heard(self, peer: Hashable, rank: int = RANK_STRANGER) -> None:
        """A frame from ``peer`` passed the security gate with ``rank``: it becomes (or stays) a peer if it
        earns a place in the table."""
        self.peers.earn(peer, rank)

    def send(self, data: bytes) -> None:
        # a UDP peer is its sender's (host, port)
        dests = self.fixed + [cast(tuple[str, int], p) for p in self.peers if p not in self.fixed]
        for dest in dests:
            try:
                self.ep.sock.sendto(data, dest)
                self.sent += 1
            except OSError:
                pass

    def close(self) -> None:
        self.ep.close()


class TcpServerTransport:
    """tcpin: a listening socket; each accepted connection is a peer, bounded and earned.

    A new connection is *pending* until a frame of it passes the security gate; then it asks the
    :class:`.peers.PeerTable` (``max_peers`` places, ranks as for UDP) for a place. At most
    :data:`TCP_PENDING` connections are pending at once (a newcomer closes the oldest pending one),
    at most :data:`TCP_PER_ADDRESS` connections come from one IP address (a newcomer closes that
    address's oldest pending connection, or is closed itself when none is pending), a pending
    connection that has not earned a place within :data:`TCP_PROVE_S` is closed, and a peer not heard
    for :data:`TCP_IDLE_S` is closed. Every close is counted in ``counts``.
    """

    stream = True

    def __init__(self, host: str, port: int, peers: PeerTable) -> None:
        """``peers``: the endpoint's peer table, built by :func:`open_endpoint`; its clock times the
        connections and its counts receive the closes."""
        self.lsock = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
        self.lsock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        try:
            self.lsock.bind((host, port))
        except OSError as exc:
            self.lsock.close()
            raise ValueError(f"cannot listen on TCP {host}:{port}: {exc.strerror or exc}") from None
        self.lsock.listen(16)
        self.lsock.setblocking(False)
        self.peers = peers
        self.clock, self.counts = peers.clock, peers.counts
        self.conns: dict[TcpPeer, socket.socket] = {}
        self.pending: dict[Hashable, float] = {}      # connection -> when it was accepted (s, clock)
        self.sent = 0
        self._closed: list[Hashable] = []             # connections closed here, reported by the next receive()

    @property
    def address(self) -> tuple[str, int]:
        return self.lsock.getsockname()

    def fileno(self) -> int:
        return self.lsock.fileno()

    def _from(self, ip: str) -> list[TcpPeer]:
        return [p for p in self.conns if p[1][0] == ip]

    def _accept(self) -> None:
        for _ in range(TCP_ACCEPTS_PER_CALL):
            try:
                conn, addr = self.lsock.accept()
            except OSError:   # nothing waiting (BlockingIOError) or the listener failed
                return
            peer = ("tcp", addr)
            same = self._from(addr[0])
            if len(same) >= TCP_PER_ADDRESS:
                pending = [p for p in same if p in self.pending]
                if not pending:
                    self.counts["tcp_per_address_cap"] += 1
                    conn.close()
                    continue
                self._close(min(pending, key=self.pending.__getitem__), "tcp_per_address_cap")
            if len(self.pending) >= TCP_PENDING:
                self._close(min(self.pending, key=self.pending.__getitem__), "tcp_pending_displaced")
            conn.setblocking(False)
            conn.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
            self.conns[peer] = conn
            self.pending[peer] = self.clock()

    def _expire(self) -> None:
        now = self.clock()
        for peer, since in list(self.pending.items()):
            if now - since > TCP_PROVE_S:
                self._close(peer, "tcp_idle_closed")
        for peer in self.peers.idle(TCP_IDLE_S):
            self._close(peer, "tcp_idle_closed")

    def receive(self, max_reads: int = 16, hold: Collection[Hashable] = ()) -> list[tuple[Hashable, bytes]]:
        self._expire()
        self._accept()
        out: list[tuple[Hashable, bytes]] = [(peer, b"") for peer in self._closed]   # tells the link they ended
        self._closed.clear()
        for peer, conn in list(self.conns.items()):
            if peer in hold:
                continue
            for _ in range(min(16, max_reads)):
                try:
                    data = conn.recv(65536)
                except (BlockingIOError, InterruptedError):
                    break
                except OSError:
                    data = b""
                if not data:
                    self._drop(peer)
                    out.append((peer, b""))  # tells the link the stream ended
                    break
                out.append((peer, data))
        return out

    def heard(self, peer: Hashable, rank: int = RANK_STRANGER) -> None:
        if peer not in self.conns:
            return
        ok, victim = self.peers.earn(peer, rank)
        if ok:
            self.pending.pop(peer, None)
        if victim is not None:
            self._close(victim, "tcp_peer_displaced")

    def _close(self, peer: Hashable, why: str) -> None:
        if peer in self.conns:
            self.counts[why] += 1
            self._drop(peer)
            self._closed.append(peer)

    def _drop(self, peer: Hashable) -> None:
        self.pending.pop(peer, None)
        self.peers.drop(peer)
        conn = self.conns.pop(cast(TcpPeer, peer), None)   # this transport's peer table holds its connections only
        if conn is not None:
            conn.close()

    def send(self, data: bytes) -> None:
        for peer, conn in list(self.conns.items()):   # pending ones too: at most TCP_PENDING, and they
            try:                                         # hear the refusal of what they sent
                conn.sendall(data)
                self.sent += 1
            except (BlockingIOError, InterruptedError):
                pass  # a GCS that does not read loses telemetry, the boat never blocks
            except OSError:
                self._drop(peer)
                self._closed.append(peer)

    def close(self) -> None:
        for peer in list(self.conns):
            self._drop(peer)
        self.lsock.close()


class TcpClientTransport:
    """tcp: one connection to a ground station's TCP server, retried every RECONNECT_S when lost.

    The first connection must succeed (a wrong port is a start-up error, not a silent boat); later
    attempts are non-blocking, so a ground station that goes away never stalls the control loop.
    """

    stream = True

    def __init__(self, host: str, port: int, clock: Callable[[], float] | None = None) -> None:
        import time

        self.host, self.port = host, port
        self.clock = clock or time.monotonic
        self.sent = 0
        self.connects = 0
        self.sock: socket.socket | None = None
        self._connecting = False
        self._next_try = 0.0
        try:
            sock = socket.create_connection((host, port), timeout=2.0)
        except OSError as exc:
            raise ValueError(f"cannot connect to TCP {host}:{port}: {exc.strerror or exc} "
                             f"(is the ground station's TCP server running?)") from None
        self._connected(sock)

    def _connected(self, sock: socket.socket) -> None:
        sock.setblocking(False)
        sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
        self.sock, self._connecting = sock, False
        self.connects += 1
        self._local = sock.getsockname()

    @property
    def address(self) -> tuple[str, int]:
        return self._local

    @property
    def connected(self) -> bool:
        return self.sock is not None and not self._connecting

    @property
    def peer(self) -> Hashable:
        return ("tcp", (self.host, self.port), self.connects)

    def fileno(self) -> int:
        return self.sock.fileno() if self.sock is not None else -1

    def _retry(self) -> None:
        now = self.clock()
        if self._connecting and self.sock is not None:
            err = self.sock.getsockopt(socket.SOL_SOCKET, socket.SO_ERROR)
            import select

            _, w, _ = select.select([], [self.sock], [], 0)
            if w and err == 0:
                self._connected(self.sock)
            elif w or now >= self._next_try:
                self.sock.close()
                self.sock, self._connecting = None, False
            return
        if now < self._next_try:
            return
        self._next_try = now + RECONNECT_S
        sock = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
        sock.setblocking(False)
        rc = sock.connect_ex((self.host, self.port))
        if rc == 0:
            self._connected(sock)
        else:
            self.sock, self._connecting = sock, True

    def _drop(self) -> None:
        if self.sock is not None:
            self.sock.close()
        self.sock, self._connecting = None, False
        self._next_try = self.clock() + RECONNECT_S

    def receive(self, max_reads: int = 16, hold: Collection[Hashable] = ()) -> list[tuple[Hashable, bytes]]:
        if self.sock is None or self._connecting:
            self._retry()
            return []
        if self.peer in hold:
            return []
        out = []
        peer = self.peer
        for _ in range(min(16, max_reads)):
            try:
                data = self.sock.recv(65536)
            except (BlockingIOError, InterruptedError):
                break
            except OSError:
                data = b""
            if not data:
                self._drop()
                out.append((peer, b""))
                break
            out.append((peer, data))
        return out

    def heard(self, peer: Hashable, rank: int = RANK_STRANGER) -> None:
        pass

    def send(self, data: bytes) -> None:
        if self.sock is None or self._connecting:
            return
        try:
            self.sock.sendall(data)
            self.sent += 1
        except (BlockingIOError, InterruptedError):
            pass
        except OSError:
            self._drop()

    def close(self) -> None:
        if self.sock is not None:
            self.sock.close()
            self.sock = None


class SerialTransport:
    """serial: a telemetry radio through pyserial (non-blocking reads and writes)."""

    stream = True

    def __init__(self, device: str, baud: int) -> None:
        try:
            import serial  # type: ignore[import-untyped,unused-ignore]
        except ImportError:
            raise ValueError(f"serial:{device}:{baud}: needs pyserial (pip install pyserial)") from None
        try:
            self.port = serial.Serial(device, baud, timeout=0, write_timeout=0)
        except (serial.SerialException, OSError, ValueError) as exc:
            raise ValueError(f"cannot open serial port {device}: {exc}") from None
        self._serial_error = serial.SerialException
        self.device, self.baud = device, baud
        self.sent = 0
        self.write_drops = 0

    @property
    def address(self) -> tuple[str, int]:
        return self.device, self.baud

    def fileno(self) -> int:
        return self.port.fileno()

    def receive(self, max_reads: int = 16, hold: Collection[Hashable] = ()) -> list[tuple[Hashable, bytes]]:
        out: list[tuple[Hashable, bytes]] = []
        if ("serial", self.device) in hold:
            return out
        for _ in range(min(16, max_reads)):
            try:
                data = self.port.read(65536)
            except (self._serial_error, OSError):
                break
            if not data:
                break
            out.append((("serial", self.device), data))
        return out

    def heard(self, peer: Hashable, rank: int = RANK_STRANGER) -> None:
        pass

    def send(self, data: bytes) -> None:
        try:
            self.port.write(data)
            self.sent += 1
        except (self._serial_error, OSError):  # a full radio buffer: telemetry is dropped, the boat never blocks
            self.write_drops += 1

    def close(self) -> None:
        self.port.close()


def open_endpoint(c: connection.Connection, max_peers: int = 8, counts: Counter[str] | None = None,
                  clock: Callable[[], float] = time.monotonic
                  ) -> UdpTransport | TcpServerTransport | TcpClientTransport | SerialTransport:
    """A transport from a parsed connection string (``GcsParams.connections``): ValueError with one line
    on a busy port, a ground station that cannot be reached, a serial port that cannot be opened.
    ``counts`` receives the peer table's and the TCP server's refusals (``peer_table_full``,
    ``tcp_idle_closed`` ...); ``clock`` (s, monotonic) times the peers' silences."""
    kind, host, port = c.endpoint
    counts = counts if counts is not None else Counter()
    peers = PeerTable(max_peers, clock, counts)   # the servers' (tcpin, udp*) place table
    if kind == "tcpin":
        return TcpServerTransport(host, port, peers)
    if kind == "tcp":
        return TcpClientTransport(host, port)
    if kind == "serial":
        return SerialTransport(host, port)
    try:
        return UdpTransport(kind, host, port, peers)
    except socket.gaierror as exc:
        raise ValueError(f"{c.text!r}: unknown host ({exc})") from None

