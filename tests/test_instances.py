"""Two runs on one machine never share a ground station (issue 31, point 6; hil/instances.py).

Before: every `hil run` streamed as system 1 to udp 14550, and a GCS meant for one run uploaded a
mission to another. Now each concurrent run holds its own instance (SITL's ``-I``): ground-station
ports + 10 N and system id + N. The end-to-end test starts two real `hil run` processes at once, both
configured for the same private GCS port, and listens on every instance's port: each port hears
exactly one vehicle, and the two vehicles have different system ids. Campaigns open no GCS link.
"""

from __future__ import annotations

import select
import socket
import subprocess
import sys
import time

import pytest
from support.cli import run_cli

from common.mavlink import mavlink2
from hil import instances
from hil.hilrun import NO_GCS
from tests.conftest import REPO


def test_shifted_endpoints_and_system_ids():
    assert instances.shifted_endpoint("udpout:127.0.0.1:14550", 1) == "udpout:127.0.0.1:14560"
    assert instances.shifted_endpoint("tcpin:0.0.0.0:5760", 3) == "tcpin:0.0.0.0:5790"
    assert instances.shifted_endpoint("serial:/dev/ttyUSB0:57600", 2) == "serial:/dev/ttyUSB0:57600"
    assert instances.overrides(("udpout:127.0.0.1:14550",), 1, 0) == []
    assert instances.overrides(("127.0.0.1:14550",), 1, 2) == ['gcs.endpoints=["udpout:127.0.0.1:14570"]',
                                                               "autopilot.system_id=3"]
    assert NO_GCS == ["gcs.endpoints=[]"]


def test_an_instance_held_by_another_run_is_a_one_line_error(capsys):
    held = instances.claim(97)
    try:
        r = run_cli(capsys, "run", "--instance", "97", "--duration", "1")
    finally:
        held.close()
    assert r.returncode == 2 and len(r.stderr.strip().splitlines()) == 1 and "--instance 97" in r.stderr
    again = instances.claim(97)   # given back when its holder closed it
    again.close()


def _listeners() -> tuple[int, list[socket.socket]]:
    """A private base port P with P + 10 k (k = 0..9) all free, bound."""
    for base in range(23000, 60000, 97):
        socks: list[socket.socket] = []
        try:
            for k in range(10):
                s = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
                socks.append(s)
                s.bind(("127.0.0.1", base + instances.PORT_STEP * k))
            return base, socks
        except OSError:
            for s in socks:
                s.close()
    pytest.skip("no free block of ports")


@pytest.mark.slow
def test_two_concurrent_runs_stream_to_their_own_ground_stations(tmp_path):
    base, socks = _listeners()
    cmd = [sys.executable, "-m", "hil", "run", "--scenario", "harbour", "--duration", "8", "--no-plot",
           "--set", f'gcs.endpoints=["udpout:127.0.0.1:{base}"]']
    procs = [subprocess.Popen(cmd + ["--out", str(tmp_path / f"run{i}")], cwd=REPO, stdout=subprocess.DEVNULL,
                              stderr=subprocess.PIPE, text=True) for i in range(2)]
    heard: dict[int, set[int]] = {}
    parser = mavlink2.MAVLink(None, 255, 190)
    parser.robust_parsing = True
    try:
        end = time.monotonic() + 240
        while time.monotonic() < end and any(p.poll() is None for p in procs):
            ready, _, _ = select.select(socks, [], [], 0.2)
            for s in ready:
                data = s.recv(65535)
                port = s.getsockname()[1]
                for m in parser.parse_buffer(data) or []:
                    if m.get_type() == "HEARTBEAT":
                        heard.setdefault(port, set()).add(m.get_srcSystem())
        errs = [p.communicate(timeout=60)[1] for p in procs]
    finally:
        for p in procs:
            if p.poll() is None:
                p.kill()
        for s in socks:
            s.close()
    assert all(p.returncode in (0, 1) for p in procs), errs
    assert len(heard) == 2, heard                       # two ports, one per run
    assert all(len(ids) == 1 for ids in heard.values()), heard   # each GCS port hears one vehicle
    ids = [next(iter(v)) for v in heard.values()]
    assert len(set(ids)) == 2, heard
    assert any("run: instance" in e for e in errs), errs
