"""A small UDP endpoint in the spirit of python-can's ``Bus``: one socket, fan-out send, recv.

The socket is bound to ``bind`` ("HOST:PORT" or "udpin:HOST:PORT"; port 0 picks a free port, see :attr:`address`)
and sends every datagram to each destination, from that same socket, so a peer can answer to
the source address. Only the latest datagram matters on these links, hence :meth:`drain_latest`.
Optional seeded loss injection per direction simulates a lossy link (both ends can use it).
"""

from __future__ import annotations

import select
import socket

import numpy as np

from common.connection import RECEIVE_UDP, SEND_UDP, Role, parse


def parse_hostport(text: str, role: Role = RECEIVE_UDP) -> tuple[str, int]:
    """("host", port) from a UDP connection string of ``role`` (``common.connection``: HOST:PORT,
    udpin:/udp: for a bound address, udpout: for a destination); ValueError with one line otherwise."""
    return parse(text, role).address


class UdpEndpoint:
    """Bound UDP socket with fan-out :meth:`send` and :meth:`recv` / :meth:`drain_latest`.

    ``send_loss``/``recv_loss`` are probabilities in [0, 1] that a datagram is silently dropped
    on the way out / in, drawn from a numpy Generator seeded with ``loss_seed``.
    """

    MAX_DATAGRAM = 65535

    def __init__(self, bind: str = "127.0.0.1:0", destinations: list[str] | tuple[str, ...] = (),
                 send_loss: float = 0.0, recv_loss: float = 0.0, loss_seed: int = 0,
                 recv_buffer: int = 1 << 20) -> None:
        for p in (send_loss, recv_loss):
            if not 0.0 <= p <= 1.0:
                raise ValueError(f"loss probability {p} is outside [0, 1]")
        self.destinations = [parse_hostport(d, SEND_UDP) for d in destinations]
        host, port = parse_hostport(bind, RECEIVE_UDP)
        self.sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        try:
            self.sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, recv_buffer)
            self.sock.bind((host, port))
        except OSError as exc:
            self.sock.close()
            raise ValueError(f"cannot bind UDP {bind}: {exc.strerror or exc}") from None
        self.sock.setblocking(False)
        self.send_loss, self.recv_loss = send_loss, recv_loss
        self._rng = np.random.default_rng(loss_seed)
        self.sent = self.recv_count = self.dropped_out = self.dropped_in = 0
        self.last_sender: tuple[str, int] | None = None

    @property
    def address(self) -> tuple[str, int]:
        """The (host, port) the socket is bound to (the chosen port when bound to port 0)."""
        return self.sock.getsockname()

    def add_destination(self, dest: tuple[str, int]) -> None:
        if dest not in self.destinations:
            self.destinations.append(dest)

    def send(self, data: bytes) -> None:
        """Send ``data`` to every destination (an unreachable one is ignored: UDP is fire-and-forget)."""
        for dest in self.destinations:
            if self.send_loss and self._rng.random() < self.send_loss:
                self.dropped_out += 1
                continue
            try:
                self.sock.sendto(data, dest)
                self.sent += 1
            except (BlockingIOError, ConnectionRefusedError, OSError):
                self.dropped_out += 1

    def _read_one(self) -> bytes | None:
        while True:
            try:
                data, sender = self.sock.recvfrom(self.MAX_DATAGRAM)
            except (BlockingIOError, InterruptedError):
                return None
            except ConnectionRefusedError:  # ICMP from an earlier send on some platforms
                continue
            if self.recv_loss and self._rng.random() < self.recv_loss:
                self.dropped_in += 1
                continue
            self.recv_count += 1
            self.last_sender = sender
            return data

    def recv(self, timeout: float | None = 0.0) -> bytes | None:
        """The next datagram, waiting at most ``timeout`` seconds (None: forever); None if none."""
        data = self._read_one()
        if data is not None or timeout == 0.0:
            return data
        ready, _, _ = select.select([self.sock], [], [], timeout)
        return self._read_one() if ready else None

    def drain(self) -> list[bytes]:
        """Every datagram queued now, oldest first (bounded by what the socket holds)."""
        out = []
        while (data := self._read_one()) is not None:
            out.append(data)
        return out

    def drain_latest(self) -> bytes | None:
        """Read everything queued and return only the newest datagram (None if nothing queued)."""
        latest = None
        while (data := self._read_one()) is not None:
            latest = data
        return latest

    def close(self) -> None:
        self.sock.close()

    def __enter__(self) -> "UdpEndpoint":
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()
