"""Child processes of `hil` commands: they die with their parent and are stopped politely first."""

from __future__ import annotations

import gc
import signal
import subprocess
import sys
from collections.abc import Sequence
from pathlib import Path
from typing import IO, TypedDict, Unpack


def freeze_heap() -> None:
    """Before a process's loop: move the objects alive now (modules, configuration, maps, compiled
    kernels) out of the garbage collector's generations, so that a full collection during the loop
    scans only what the loop made. Unfrozen, one took 87-115 ms in the middle of a 150 s lockstep
    run (docs/performance.md); it changes nothing that is computed."""
    gc.freeze()


def _die_with_parent() -> None:  # pragma: no cover - runs in the child between fork and exec
    """Linux: the child gets SIGTERM if its parent dies without cleaning up (e.g. SIGKILL)."""
    try:
        import ctypes

        ctypes.CDLL("libc.so.6", use_errno=True).prctl(1, signal.SIGTERM)  # 1 = PR_SET_PDEATHSIG
    except (OSError, AttributeError):
        pass


class ChildOptions(TypedDict, total=False):
    """The ``subprocess.Popen`` options this project starts children with."""

    stdout: int | IO[bytes] | None
    stderr: int | IO[bytes] | None
    cwd: str | Path
    start_new_session: bool
    pass_fds: Sequence[int]
    text: bool


def start(cmd: list[str], **kwargs: Unpack[ChildOptions]) -> subprocess.Popen:
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


def wait_for_marker(proc: subprocess.Popen, marker: bytes, timeout: float = 60.0) -> None:
    """Read the child's stderr until ``marker``; RunFailed after ``timeout`` seconds or if it ends."""
    import os
    import selectors
    import time

    from hil.errors import RunFailed

    stderr = proc.stderr
    if stderr is None:
        raise ValueError("wait_for_marker: the child needs stderr=subprocess.PIPE")
    sel = selectors.DefaultSelector()
    sel.register(stderr, selectors.EVENT_READ)
    seen = b""
    deadline = time.monotonic() + timeout
    while marker not in seen:
        left = deadline - time.monotonic()
        if left <= 0 or proc.poll() is not None:
            raise RunFailed(f"child not ready: {seen.decode(errors='replace').strip()[-300:]}")
        if sel.select(min(left, 0.2)):
            chunk = os.read(stderr.fileno(), 4096)
            if not chunk:
                continue
            seen += chunk
    sel.close()
