"""Child processes of `hil` commands: they die with their parent and are stopped politely first."""

from __future__ import annotations

import signal
import subprocess
import sys
from typing import Any


def _die_with_parent() -> None:  # pragma: no cover - runs in the child between fork and exec
    """Linux: the child gets SIGTERM if its parent dies without cleaning up (e.g. SIGKILL)."""
    try:
        import ctypes

        ctypes.CDLL("libc.so.6", use_errno=True).prctl(1, signal.SIGTERM)  # 1 = PR_SET_PDEATHSIG
    except (OSError, AttributeError):
        pass


def start(cmd: list[str], **kwargs: Any) -> subprocess.Popen:
    """Start a child process that is stopped if this process dies."""
    return subprocess.Popen(cmd, preexec_fn=_die_with_parent if sys.platform.startswith("linux") else None, **kwargs)


def stop(proc: subprocess.Popen, timeout: float = 5.0) -> None:
    """SIGTERM, then SIGKILL if it has not ended within ``timeout`` seconds."""
    if proc.poll() is None:
        proc.terminate()
        try:
            proc.wait(timeout)
        except subprocess.TimeoutExpired:
            proc.kill()
            proc.wait(timeout)
