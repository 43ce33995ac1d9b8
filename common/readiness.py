"""Readiness of a child process, told its parent on a pipe rather than guessed from its log.

The parent makes a pipe and passes its write end to the child (``--ready-fd N``). Once the child
serves (its sockets are bound, its planner is warmed up), it writes one :class:`Ready` as a JSON
line and closes the descriptor. End of file without a line means the child died while starting.

The other way round, a child set up ahead of time waits on ``--start-fd N`` (:func:`wait_for_start`)
until its parent says go: `hil run` starts the simulator beside the vessel computer, so that both
import and set up at once, and lets it send its first frame once the computer serves.
"""

from __future__ import annotations

import json
import os
import select
import time
from collections.abc import Callable
from dataclasses import asdict, dataclass


@dataclass(frozen=True)
class Ready:
    """A process serves: ``listen`` is the "HOST:PORT" it takes frames on."""

    process: str
    listen: str
    pid: int

    def encode(self) -> bytes:
        return (json.dumps(asdict(self)) + "\n").encode()

    @classmethod
    def decode(cls, line: bytes) -> Ready:
        """The message; ValueError if ``line`` is not one."""
        try:
            d = json.loads(line)
            return cls(str(d["process"]), str(d["listen"]), int(d["pid"]))
        except (json.JSONDecodeError, KeyError, TypeError, ValueError) as exc:
            raise ValueError(f"not a readiness message: {line[:80]!r}") from exc


def announce(fd: int | None, ready: Ready) -> None:
    """Write ``ready`` to ``fd`` and close it (nothing when ``fd`` is None; a parent gone is ignored)."""
    if fd is None:
        return
    try:
        os.write(fd, ready.encode())
    except OSError:
        pass
    finally:
        try:
            os.close(fd)
        except OSError:
            pass


class ReadyWait:
    """The parent's end: :meth:`poll` waits a bounded time for the child's :class:`Ready`."""

    MAX_LINE = 4096

    def __init__(self, fd: int) -> None:
        self.fd = fd
        self.buf = b""
        self.eof = False

    def poll(self, timeout: float) -> Ready | None:
        """The message once it has come; None while it has not (see :attr:`eof`). Waits at most
        ``timeout`` s. ValueError for a malformed or over-long line."""
        end = time.monotonic() + max(0.0, timeout)
        while not self.eof:
            if b"\n" in self.buf:
                return Ready.decode(self.buf.split(b"\n", 1)[0])
            left = end - time.monotonic()
            if not select.select([self.fd], [], [], max(0.0, left))[0]:
                return None
            chunk = os.read(self.fd, self.MAX_LINE)
            if not chunk:
                self.eof = True
            self.buf += chunk
            if len(self.buf) > self.MAX_LINE:
                raise ValueError("readiness message too long")
        if b"\n" in self.buf:
            return Ready.decode(self.buf.split(b"\n", 1)[0])
        return None

    def close(self) -> None:
        try:
            os.close(self.fd)
        except OSError:
            pass


GO = b"g"


def wait_for_start(fd: int | None, stopped: Callable[[], bool], poll_s: float = 0.05) -> bool:
    """Block until the parent writes :data:`GO` on ``fd`` (True), or closes it without a word or
    ``stopped()`` turns true (False: do not start). Closes ``fd``; None: start at once."""
    if fd is None:
        return True
    try:
        while not stopped():
            if select.select([fd], [], [], poll_s)[0]:
                return os.read(fd, 1) == GO
        return False
    except OSError:
        return False
    finally:
        try:
            os.close(fd)
        except OSError:
            pass
