"""A small UDP endpoint in the spirit of python-can's ``Bus``: one socket, fan-out send, recv.

The socket is bound to ``bind`` ("HOST:PORT" or "udpin:HOST:PORT"; port 0 picks a free port, see :attr:`address`)
and sends every datagram to each destination, from that same socket, so a peer can answer to
the source address. Only the latest datagram matters on these links, hence :meth:`drain_latest`.
Optional seeded loss injection per direction simulates a lossy link (both ends can use it).

Only the peer: :meth:`UdpEndpoint.set_peer` makes the endpoint drop, unread by its caller, every
datagram whose source address is not the peer's (counted in :attr:`UdpEndpoint.wrong_source`).
An unprivileged local process cannot send from a port another socket holds, so the source
address is the one thing on loopback that a forger cannot fake (docs/security.md). Reads are
bounded per call (:attr:`UdpEndpoint.READ_BUDGET`), and :meth:`UdpEndpoint.kernel_drops` reports
what the kernel dropped because the socket's buffer was full.
"""

from __future__ import annotations

import os
import select
import socket
import time
from typing import TypedDict

import numpy as np

from common.connection import RECEIVE_UDP, SEND_UDP, Role, parse


def parse_hostport(text: str, role: Role = RECEIVE_UDP) -> tuple[str, int]:
    """("host", port) from a UDP connection string of ``role`` (``common.connection``: HOST:PORT,
    udpin:/udp: for a bound address, udpout: for a destination); ValueError with one line otherwise."""
    return parse(text, role).address


def usable_cpus() -> int:
    """The CPUs this process may run on (its affinity mask where the OS has one)."""
    try:
        return len(os.sched_getaffinity(0))
    except AttributeError:  # not on Linux
        return os.cpu_count() or 1


class BusyPollSummary(TypedDict):
    """How a lockstep end's waits for frames went: the longest spin (us), frames caught while
    spinning, missed (slept instead), pauses, and waits held for a peer."""

    max_us: float
    caught: int
    missed: int
    pauses: int
    held: int


class EndpointCounters(TypedDict):
    """What a UDP endpoint refused or lost (``kernel_drops`` None where the kernel does not say)."""

    wrong_source: int
    budget_stops: int
    kernel_drops: int | None


class LossCounts(TypedDict):
    """Datagrams of a fault-injecting endpoint: sent and dropped out, received and dropped in."""

    sent: int
    dropped_out: int
    received: int
    dropped_in: int


class BusyPoll:
    """How long to poll a socket in a busy loop before sleeping on it, adapted to what it catches.

    In lockstep the simulator and the vessel computer wait for each other on every step. Sleeping
    in ``select`` costs a wake-up per datagram, and on a virtual machine waking a halted core takes
    50-60 us each way; with both processes sleeping, the scheduler then runs them one after the
    other on one core, where each evicts the other's caches (docs/performance.md measured the
    vessel computer's frame at 0.37 ms there against 0.13-0.21 ms on a core of its own). Polling for
    up to ``max_s`` keeps each on its own core and catches the peer's answer within microseconds.

    A poll that ends empty is CPU taken from whatever else needs the cores (the tap, the planner
    worker, a second run); so after ``MISSES_BEFORE_PAUSE`` empty polls in a row the endpoint
    sleeps without polling for a pause that doubles each time (up to ``MAX_PAUSE`` waits) and is
    reset by the first poll that catches something. A process that may use one CPU only never polls.
    A held poll (:meth:`hold`) sleeps at once, so that a process that shares its CPU on purpose (the
    vessel computer and its planner worker) hands it over while it waits.
    Which path delivered a datagram changes nothing in what is delivered: lockstep runs stay
    byte-identical.
    """

    MISSES_BEFORE_PAUSE = 3
    FIRST_PAUSE = 16      # waits without polling after the first run of misses
    MAX_PAUSE = 4096

    def __init__(self, max_s: float) -> None:
        if not max_s >= 0.0:
            raise ValueError(f"busy-poll window {max_s} s must be >= 0")
        # On one core a poll only keeps the peer it waits for from running.
        self.max_s = max_s if usable_cpus() >= 2 else 0.0
        self.hits = self.misses = self.pauses = 0
        self._misses_in_row = 0
        self._pause = self.FIRST_PAUSE
        self._paused_for = 0
        self._held = False
        self.held_waits = 0

    def hold(self, held: bool) -> None:
        """While held, every wait sleeps at once: the CPU goes to whatever else is runnable on it
        (the vessel computer holds its polls while its planner worker has a request)."""
        self._held = held

    def window(self) -> float:
        """Seconds to poll before this wait sleeps (0: sleep at once)."""
        if self._held:
            self.held_waits += 1
            return 0.0
        if self._paused_for > 0:
            self._paused_for -= 1
            return 0.0
        return self.max_s

    def caught(self) -> None:
        self.hits += 1
        self._misses_in_row = 0
        self._pause = self.FIRST_PAUSE

    def missed(self) -> None:
        self.misses += 1
        self._misses_in_row += 1
        if self._misses_in_row >= self.MISSES_BEFORE_PAUSE:
            self.pauses += 1
            self._misses_in_row = 0
            self._paused_for = self._pause
            self._pause = min(2 * self._pause, self.MAX_PAUSE)

    def summary(self) -> BusyPollSummary:
        return {"max_us": round(self.max_s * 1e6, 1), "caught": self.hits, "missed": self.misses,
                "pauses": self.pauses, "held": self.held_waits}


class UdpEndpoint:
    """Bound UDP socket with fan-out :meth:`send` and :meth:`recv` / :meth:`drain_latest`.

    ``send_loss``/``recv_loss`` are probabilities in [0, 1] that a datagram is silently dropped
    on the way out / in, drawn from a numpy Generator seeded with ``loss_seed``.
    """

    MAX_DATAGRAM = 65535
    READ_BUDGET = 4096  # datagrams one recv()/drain() reads at most (refused ones included)

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
        self.peer: tuple[str, int] | None = None
        self.wrong_source = 0     # datagrams dropped: not from the peer
        self.budget_stops = 0     # drain() calls that stopped at READ_BUDGET with more queued

    def set_peer(self, addr: tuple[str, int] | str | None) -> None:
        """Accept datagrams only from ``addr`` ("HOST:PORT" or (host, port); None: from anyone)."""
        if isinstance(addr, str):
            host, port = parse_hostport(addr)
            addr = (socket.gethostbyname(host), port)
        self.peer = None if addr is None else (addr[0], int(addr[1]))

    def kernel_drops(self) -> int | None:
        """Datagrams the kernel dropped for this socket (receive buffer full), from /proc/net/udp
        on Linux; None where that is not available."""
        try:
            inode = os.fstat(self.sock.fileno()).st_ino
            with open("/proc/net/udp") as fh:
                next(fh)
                for line in fh:
                    f = line.split()
                    if len(f) >= 13 and f[9] == str(inode):
                        return int(f[12])
        except (OSError, ValueError, StopIteration):
            return None
        return None

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

    def _read_one(self, budget: list[int] | None = None) -> bytes | None:
        budget = budget if budget is not None else [self.READ_BUDGET]
        while budget[0] > 0:
            budget[0] -= 1
            try:
                data, sender = self.sock.recvfrom(self.MAX_DATAGRAM)
            except (BlockingIOError, InterruptedError):
                return None
            except ConnectionRefusedError:  # ICMP from an earlier send on some platforms
                continue
            if self.peer is not None and sender != self.peer:
                self.wrong_source += 1
                continue
            if self.recv_loss and self._rng.random() < self.recv_loss:
                self.dropped_in += 1
                continue
            self.recv_count += 1
            self.last_sender = sender
            return data
        return None

    def recv(self, timeout: float | None = 0.0, poll: BusyPoll | None = None) -> bytes | None:
        """The next datagram, waiting at most ``timeout`` seconds (None: forever); None if none.
        With ``poll``, the wait polls the socket in a busy loop for up to ``poll.window()`` (within
        ``timeout``) before it sleeps."""
        budget = [self.READ_BUDGET]
        data = self._read_one(budget)
        if data is not None or timeout == 0.0:
            return data
        deadline = None if timeout is None else time.monotonic() + timeout
        if poll is not None and (window := poll.window()) > 0.0:
            end = time.monotonic() + (window if timeout is None else min(window, timeout))
            while True:
                data = self._read_one()   # a budget of its own per read: the wait below keeps the call's
                if data is not None:
                    poll.caught()
                    return data
                if time.monotonic() >= end:
                    break
            poll.missed()
        while budget[0] > 0:  # datagrams refused by source do not end the wait
            left = None if deadline is None else max(0.0, deadline - time.monotonic())
            ready, _, _ = select.select([self.sock], [], [], left)
            if not ready:
                return None
            data = self._read_one(budget)
            if data is not None or (deadline is not None and time.monotonic() >= deadline):
                return data
        return None

    def drain(self, limit: int | None = None) -> list[bytes]:
        """The datagrams queued now, oldest first: at most ``limit`` accepted ones and
        READ_BUDGET reads in all (the rest stays queued for the next call)."""
        out: list[bytes] = []
        budget = [self.READ_BUDGET]
        while limit is None or len(out) < limit:
            data = self._read_one(budget)
            if data is None:
                if budget[0] <= 0:
                    self.budget_stops += 1
                return out
            out.append(data)
        self.budget_stops += 1
        return out

    def drain_latest(self) -> bytes | None:
        """Read what is queued (READ_BUDGET at most) and return only the newest datagram."""
        latest = None
        budget = [self.READ_BUDGET]
        while (data := self._read_one(budget)) is not None:
            latest = data
        return latest

    def counters(self) -> EndpointCounters:
        """What this endpoint refused or lost: ``wrong_source`` (not from the peer),
        ``budget_stops`` and ``kernel_drops`` (receive buffer full; None: unknown)."""
        return {"wrong_source": self.wrong_source, "budget_stops": self.budget_stops,
                "kernel_drops": self.kernel_drops()}

    def close(self) -> None:
        self.sock.close()

    def __enter__(self) -> UdpEndpoint:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()
