"""Readiness on a pipe (common/readiness.py): a real child process and a real pipe."""

from __future__ import annotations

import os
import subprocess
import sys

import pytest

from common.readiness import Ready, ReadyWait, announce


def _child(code: str) -> tuple[subprocess.Popen, ReadyWait]:
    r, w = os.pipe()
    proc = subprocess.Popen([sys.executable, "-c", code.replace("FD", str(w))], pass_fds=(w,))
    os.close(w)
    return proc, ReadyWait(r)


def test_the_message_a_child_announces_is_what_the_parent_reads():
    proc, wait = _child(f"import os, sys; sys.path.insert(0, {os.getcwd()!r})\n"
                        "from common.readiness import Ready, announce\n"
                        "announce(FD, Ready('autopilot', '127.0.0.1:5760', os.getpid()))")
    try:
        got = None
        for _ in range(600):                       # bounded: 600 x 0.05 s
            got = wait.poll(0.05)
            if got is not None or wait.eof:
                break
        assert got == Ready("autopilot", "127.0.0.1:5760", proc.pid)
    finally:
        proc.wait(timeout=30)
        wait.close()


def test_a_child_that_dies_before_it_is_ready_is_end_of_file_not_a_hang():
    proc, wait = _child("import sys; sys.exit(3)")
    try:
        for _ in range(600):
            assert wait.poll(0.05) is None
            if wait.eof:
                break
        assert wait.eof
        assert proc.wait(timeout=30) == 3
    finally:
        wait.close()


def test_a_malformed_or_endless_line_is_refused():
    r, w = os.pipe()
    os.write(w, b"listening on 127.0.0.1\n")
    wait = ReadyWait(r)
    with pytest.raises(ValueError, match="not a readiness message"):
        wait.poll(1.0)
    wait.close()
    os.close(w)
    r, w = os.pipe()
    os.write(w, b"x" * (ReadyWait.MAX_LINE + 10))
    wait = ReadyWait(r)
    with pytest.raises(ValueError, match="too long"):
        wait.poll(1.0)
    wait.close()
    os.close(w)


def test_announce_without_a_descriptor_or_a_parent_does_nothing():
    announce(None, Ready("autopilot", "127.0.0.1:1", 1))
    r, w = os.pipe()
    os.close(r)                                     # the parent has gone
    announce(w, Ready("autopilot", "127.0.0.1:1", 1))
    with pytest.raises(OSError):
        os.close(w)                                 # announce closed it
