"""Ground-station transports, configured like MAVProxy/MAVSDK connection strings.

* ``udpout:HOST:PORT`` - a socket on a free local port sends everything to HOST:PORT (the way SITL
  sends to 14550, so a GCS listening there sees the boat with no configuration); whoever sends
  a valid MAVLink frame to that socket is answered too.
* ``udpin:HOST:PORT`` - listen on HOST:PORT; every peer heard is answered.
* ``tcpin:HOST:PORT`` - accept TCP connections on HOST:PORT; each connection is one peer with its
  own stream parser (frames may span reads).

Peers are learned only from valid MAVLink frames (a fuzzer's garbage does not make it a peer) and
kept up to ``max_peers`` per endpoint, the least recently heard dropped first. Every transport
has the same small interface: :meth:`receive` gives ``(peer, bytes)`` chunks, :meth:`send`
fans a frame out to every peer, :meth:`heard` records a peer as a talker.
"""

from __future__ import annotations

import socket
from collections import OrderedDict
from typing import Any

from common.udp import UdpEndpoint, parse_hostport

KINDS = ("udpout", "udpin", "tcpin")


def parse_endpoint(text: str) -> tuple[str, str, int]:
    """("udpout" | "udpin" | "tcpin", host, port) from "KIND:HOST:PORT"; ValueError with one line otherwise."""
    kind, sep, rest = str(text).partition(":")
    if not sep or kind not in KINDS:
        raise ValueError(f"{text!r}: expected udpout:HOST:PORT, udpin:HOST:PORT or tcpin:HOST:PORT")
    host, port = parse_hostport(rest)
    if kind == "udpout" and port == 0:
        raise ValueError(f"{text!r}: udpout needs the port a ground station listens on")
    return kind, host, port


class UdpTransport:
    """udpout / udpin over :class:`common.udp.UdpEndpoint`."""

    stream = False

    def __init__(self, kind: str, host: str, port: int, max_peers: int = 8) -> None:
        self.kind = kind
        bind = f"{host}:{port}" if kind == "udpin" else ("127.0.0.1:0" if host in ("127.0.0.1", "localhost")
                                                         else "0.0.0.0:0")
        self.ep = UdpEndpoint(bind, [])
        self.fixed = [(socket.gethostbyname(host), port)] if kind == "udpout" else []
        self.peers: OrderedDict[Any, None] = OrderedDict()
        self.max_peers = max_peers
        self.sent = 0

    @property
    def address(self) -> tuple[str, int]:
        return self.ep.address

    def fileno(self) -> int:
        return self.ep.sock.fileno()

    def receive(self) -> list[tuple[Any, bytes]]:
        out = []
        for _ in range(256):  # bounded per call: a flood cannot starve the control loop
            data = self.ep.recv(timeout=0.0)
            if data is None:
                break
            out.append((self.ep.last_sender, data))
        return out

    def heard(self, peer: Any) -> None:
        self.peers[peer] = None
        self.peers.move_to_end(peer)
        while len(self.peers) > self.max_peers:
            self.peers.popitem(last=False)

    def send(self, data: bytes) -> None:
        for dest in self.fixed + [p for p in self.peers if p not in self.fixed]:
            try:
                self.ep.sock.sendto(data, dest)
                self.sent += 1
            except OSError:
                pass

    def close(self) -> None:
        self.ep.close()


class TcpServerTransport:
    """tcpin: a listening socket; each accepted connection is a peer (bounded)."""

    stream = True

    def __init__(self, host: str, port: int, max_peers: int = 8) -> None:
        self.lsock = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
        self.lsock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        try:
            self.lsock.bind((host, port))
        except OSError as exc:
            self.lsock.close()
            raise ValueError(f"cannot listen on TCP {host}:{port}: {exc.strerror or exc}") from None
        self.lsock.listen(4)
        self.lsock.setblocking(False)
        self.conns: dict[Any, socket.socket] = {}
        self.max_peers = max_peers
        self.sent = 0

    @property
    def address(self) -> tuple[str, int]:
        return self.lsock.getsockname()

    def fileno(self) -> int:
        return self.lsock.fileno()

    def _accept(self) -> None:
        while True:
            try:
                conn, addr = self.lsock.accept()
            except (BlockingIOError, InterruptedError):
                return
            except OSError:
                return
            if len(self.conns) >= self.max_peers:
                conn.close()
                continue
            conn.setblocking(False)
            conn.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
            self.conns[("tcp", addr)] = conn

    def receive(self) -> list[tuple[Any, bytes]]:
        self._accept()
        out = []
        for peer, conn in list(self.conns.items()):
            for _ in range(16):
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

    def heard(self, peer: Any) -> None:
        pass  # every connection is a peer already

    def _drop(self, peer: Any) -> None:
        conn = self.conns.pop(peer, None)
        if conn is not None:
            conn.close()

    def send(self, data: bytes) -> None:
        for peer, conn in list(self.conns.items()):
            try:
                conn.sendall(data)
                self.sent += 1
            except (BlockingIOError, InterruptedError):
                pass  # a GCS that does not read loses telemetry, the boat never blocks
            except OSError:
                self._drop(peer)

    def close(self) -> None:
        for peer in list(self.conns):
            self._drop(peer)
        self.lsock.close()


def open_endpoint(spec: str, max_peers: int = 8) -> UdpTransport | TcpServerTransport:
    """A transport from "KIND:HOST:PORT" (ValueError with one line on bad input or a busy port)."""
    kind, host, port = parse_endpoint(spec)
    if kind == "tcpin":
        return TcpServerTransport(host, port, max_peers)
    try:
        return UdpTransport(kind, host, port, max_peers)
    except socket.gaierror as exc:
        raise ValueError(f"{spec!r}: unknown host ({exc})") from None

