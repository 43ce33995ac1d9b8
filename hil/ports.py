"""Loopback UDP ports for HIL runs that share a host (Monte Carlo workers, parallel tests).

A run chooses its ports before the processes that bind them exist, so "ask the kernel for a free
port and close it" races: a second run (or the kernel's own ephemeral choice for any socket bound
to port 0) can take the same port in between. Here ports come from a band just *below* the
kernel's ephemeral range (``/proc/sys/net/ipv4/ip_local_port_range``), which the kernel never hands
out for port 0, and every reservation is written, under an exclusive lock, to a small host-wide
registry file, so no two of our runs on one host get the same port while either holds it.
A reservation ends with :func:`release`, when its owner process is gone, or after ``ttl_s``.
"""

from __future__ import annotations

import fcntl
import json
import os
import socket
import tempfile
import time
from pathlib import Path

BAND = 8000   # ports reserved below the ephemeral range


def _registry() -> Path:
    return Path(tempfile.gettempdir()) / f"usv-hil-udp-ports-{os.getuid()}.json"


def _band() -> tuple[int, int] | None:
    try:
        low = int(Path("/proc/sys/net/ipv4/ip_local_port_range").read_text().split()[0])
    except (OSError, ValueError, IndexError):
        low = 32768
    lo = max(10000, low - BAND)
    return (lo, low) if low - lo >= 1000 else None


def _alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True
    return True


def _bindable(port: int) -> bool:
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        try:
            s.bind(("127.0.0.1", port))
        except OSError:
            return False
    return True


class _Locked:
    """The registry, read and rewritten under an exclusive lock."""

    def __enter__(self) -> dict[str, list]:
        path = _registry()
        self.fh = open(path.with_suffix(".lock"), "a+")
        fcntl.flock(self.fh, fcntl.LOCK_EX)
        self.path = path
        try:
            entries = json.loads(path.read_text()) if path.exists() else {}
        except (OSError, ValueError):
            entries = {}
        now = time.time()
        self.entries = {p: v for p, v in entries.items()
                        if isinstance(v, list) and len(v) == 2 and v[1] > now and _alive(int(v[0]))}
        return self.entries

    def __exit__(self, *exc: object) -> None:
        try:
            tmp = self.path.with_suffix(f".{os.getpid()}.tmp")
            tmp.write_text(json.dumps(self.entries))
            os.replace(tmp, self.path)
        finally:
            fcntl.flock(self.fh, fcntl.LOCK_UN)
            self.fh.close()


def reserve_udp_port(ttl_s: float = 1800.0) -> int:
    """A UDP port on 127.0.0.1, free now and reserved host-wide for this process for ``ttl_s``."""
    band = _band()
    if band is None:   # odd ephemeral range: fall back to the kernel's choice
        with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
            s.bind(("127.0.0.1", 0))
            return s.getsockname()[1]
    lo, hi = band
    with _Locked() as entries:
        start = (os.getpid() * 7919 + len(entries) * 31 + int(time.monotonic() * 1000)) % (hi - lo)
        for k in range(hi - lo):
            port = lo + (start + k) % (hi - lo)
            if str(port) not in entries and _bindable(port):
                entries[str(port)] = [os.getpid(), time.time() + ttl_s]
                return port
    raise OSError(f"no free UDP port in {lo}-{hi - 1} on 127.0.0.1")


def release(*ports: int) -> None:
    """End the reservations of ``ports`` (made by this process)."""
    if _band() is None:
        return
    with _Locked() as entries:
        for p in ports:
            v = entries.get(str(p))
            if v is not None and int(v[0]) == os.getpid():
                del entries[str(p)]
