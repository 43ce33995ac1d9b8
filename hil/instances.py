"""Run instances: each concurrent `hil run` on a machine gets its own ground-station ports and system id
(issue 31, point 6), as ArduPilot's SITL does with ``-I N`` (each instance's ports 10 apart).

Instance N adds ``10 N`` to the port of every ground-station endpoint (``udpout:127.0.0.1:14550`` becomes
``udpout:127.0.0.1:14560`` for N = 1; a serial device is left as it is) and ``N`` to
``autopilot.system_id`` (1 becomes 2), so a ground station listening for one run never hears, or
commands, another. `hil run --instance N` asks for N and fails in one line (exit 2) when another run
on this machine holds it; without ``--instance`` a run takes the lowest free instance (0 when it runs
alone: the defaults unchanged). An instance is held with an advisory lock on
``$TMPDIR/usv-hil-instance-N.lock`` for the run's lifetime (the kernel drops it when the process ends).
"""

from __future__ import annotations

import fcntl
import tempfile
from pathlib import Path
from typing import IO

from common import connection
from hil.errors import UsageError

MAX_INSTANCE = 99
PORT_STEP = 10   # ports between instances, as SITL's -I


def lock_path(n: int) -> Path:
    return Path(tempfile.gettempdir()) / f"usv-hil-instance-{n}.lock"


def _try_lock(n: int) -> IO[str] | None:
    try:
        fh = open(lock_path(n), "a")
    except OSError:
        return None
    try:
        fcntl.flock(fh, fcntl.LOCK_EX | fcntl.LOCK_NB)
    except OSError:
        fh.close()
        return None
    return fh


class Instance:
    """A held instance number; :meth:`close` gives it back."""

    def __init__(self, n: int, lock: IO[str] | None) -> None:
        self.n, self._lock = n, lock

    def close(self) -> None:
        if self._lock is not None:
            self._lock.close()
            self._lock = None


def claim(requested: int | None) -> Instance:
    """Instance ``requested`` (UsageError when another run holds it), or the lowest free one."""
    if requested is not None:
        if not 0 <= requested <= MAX_INSTANCE:
            raise UsageError(f"--instance: {requested} is out of range [0, {MAX_INSTANCE}]")
        lock = _try_lock(requested)
        if lock is None:
            raise UsageError(f"--instance {requested}: another hil run on this machine holds it "
                             f"({lock_path(requested)}); choose another")
        return Instance(requested, lock)
    for n in range(MAX_INSTANCE + 1):
        lock = _try_lock(n)
        if lock is not None:
            return Instance(n, lock)
    raise UsageError(f"every instance 0-{MAX_INSTANCE} is held by another hil run on this machine")


def shifted_endpoint(spec: str, n: int) -> str:
    """``spec`` (a GCS connection string) with its port moved ``PORT_STEP * n`` up (serial: unchanged)."""
    c = connection.parse(spec, connection.GCS)
    if c.kind == "serial" or n == 0:
        return spec
    port = c.port + PORT_STEP * n
    if port > 65535:
        raise UsageError(f"--instance {n}: ground-station port {c.port} + {PORT_STEP * n} is above 65535")
    return f"{c.kind}:{c.host}:{port}"


def overrides(endpoints: tuple[str, ...], system_id: int, n: int) -> list[str]:
    """The ``--set`` overrides that give a run instance ``n``'s ports and system id."""
    if n == 0:
        return []
    if system_id + n > 255:
        raise UsageError(f"--instance {n}: system id {system_id} + {n} is above 255")
    import json

    return ["gcs.endpoints=" + json.dumps([shifted_endpoint(e, n) for e in endpoints]),
            f"autopilot.system_id={system_id + n}"]
