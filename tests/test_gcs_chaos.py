"""A chaos ground station against a live `hil run` (issue 31, point 7; tests/support/chaos_gcs.py).

A real `hil run --wait-for-arm` (lockstep paced to wall time, udpin and tcpin GCS endpoints) takes the
seeded chaos client for ``CHAOS_S`` seconds (default 150 per leg: the suite's five-minute version, five
minutes of chaos with both legs, about six with the runs' starts), with signing off and on. Then:

* nothing crashed: the run is still going (ended by our SIGINT, outcome "interrupted"), no collision;
* the vessel computer's and the simulator's memory and descriptors grew within a stated bound (RSS <= 64 MB,
  fds <= 8 each);
* every refusal the client heard was counted by the vessel (its mission and command acks by result),
  and with signing on the refused frames are counted by reason.

The long versions: ``CHAOS_S=300 python -m pytest tests/test_gcs_chaos.py`` (5 minutes a leg) and
``CHAOS_S=3600 ...`` (an hour a leg); docs/security.md records the figures.
"""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest
from support.chaos_gcs import ChaosGcs
from support.gcs_client import REPO

from hil import instances
from hil.hilrun import free_udp_port

CHAOS_S = float(os.environ.get("CHAOS_S", "150"))
CHAOS_SEED = int(os.environ.get("CHAOS_SEED", "31"))
RSS_GROWTH_MB = 64.0
FD_GROWTH = 8
KEY = bytes(range(100, 132))


def _child_pid(run_pid: int, role: bytes, timeout: float = 120.0) -> int | None:
    """The pid of `hil run`'s child ``hil <role>`` (b"autopilot" or b"sim")."""
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        for p in Path("/proc").iterdir():
            if not p.name.isdigit():
                continue
            try:
                stat = (p / "stat").read_text().rsplit(")", 1)[1].split()
                cmd = (p / "cmdline").read_bytes().split(b"\0")
            except OSError:
                continue
            if int(stat[1]) == run_pid and role in cmd:
                return int(p.name)
        time.sleep(0.5)
    return None


def _usage(pid: int) -> tuple[float, int]:
    """(RSS in MB, open descriptors) of a process."""
    rss = next(int(line.split()[1]) for line in Path(f"/proc/{pid}/status").read_text().splitlines()
               if line.startswith("VmRSS:"))
    return rss / 1024.0, len(os.listdir(f"/proc/{pid}/fd"))


def _start_run(out: Path, *args: str) -> subprocess.Popen:
    """`hil run` in its own session, its stdout and stderr to files beside ``out`` (a pipe that nobody
    reads for an hour would fill and block the run)."""
    out.parent.mkdir(parents=True, exist_ok=True)
    cmd = [sys.executable, "-m", "hil", "run", "--json", "--no-plot", "--out", str(out), *args,
           "--set", 'gcs.identity="generic"']
    with open(out.parent / "run.stdout", "wb") as so, open(out.parent / "run.stderr", "wb") as se:
        return subprocess.Popen(cmd, cwd=REPO, stdout=so, stderr=se, start_new_session=True)


def _stop_run(proc: subprocess.Popen, out: Path, timeout: float = 60.0) -> str:
    """SIGINT (the run stops its processes and writes its folder), SIGKILL of the group if it hangs;
    returns the run's stderr."""
    if proc.poll() is None:
        os.killpg(proc.pid, signal.SIGINT)
    try:
        proc.wait(timeout=timeout)
    except subprocess.TimeoutExpired:
        os.killpg(proc.pid, signal.SIGKILL)
        proc.wait()
    return (out.parent / "run.stderr").read_text(errors="replace")


def _free_tcp_port() -> int:
    import socket

    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


@pytest.mark.slow
@pytest.mark.parametrize("signing", [False, True], ids=["signing_off", "signing_on"])
def test_a_chaos_ground_station_crashes_nothing_and_every_refusal_is_counted(tmp_path, signing):
    held = instances.claim(None)          # an instance no other run holds: its ports are ours alone
    n = held.n
    held.close()
    udp, tcp = free_udp_port(), _free_tcp_port()
    args = ["--scenario", "harbour", "--wait-for-arm", "--duration", "100000", "--instance", str(n),
            "--gcs", f"udpin:127.0.0.1:{udp - 10 * n}", "--gcs", f"tcpin:127.0.0.1:{tcp - 10 * n}"]
    if signing:
        key_file = tmp_path / "gcs.key"
        key_file.write_text(KEY.hex())
        args += ["--set", f'gcs.signing_key_file="{key_file}"']
    proc = _start_run(tmp_path / "run", *args)
    chaos = None
    try:
        ap, sim = _child_pid(proc.pid, b"autopilot"), _child_pid(proc.pid, b"sim")
        assert ap is not None and sim is not None, "no autopilot or simulator process"
        chaos = ChaosGcs(seed=CHAOS_SEED, udp=("127.0.0.1", udp), tcp=("127.0.0.1", tcp), key=KEY if signing else None,
                         vessel=1 + n)
        chaos.wait_for(("HEARTBEAT",), 120.0)
        rss0, fd0 = _usage(ap)
        sim_rss0, sim_fd0 = _usage(sim)
        sampled_at = [time.monotonic()]
        last: dict[str, tuple[float, int]] = {"ap": (rss0, fd0), "sim": (sim_rss0, sim_fd0)}

        def alive() -> bool:
            """The run is up; its children's usage is sampled every 30 s (the last sample stands in for the
            end's when the run ends under the chaos)."""
            if proc.poll() is not None:
                return False
            if time.monotonic() - sampled_at[0] >= 30.0:
                sampled_at[0] = time.monotonic()
                try:
                    last.update(ap=_usage(ap), sim=_usage(sim))
                except (OSError, StopIteration):
                    return proc.poll() is None
            return True

        stats = chaos.run(CHAOS_S, alive=alive)
        ended = proc.poll() is not None
        if not ended:
            last.update(ap=_usage(ap), sim=_usage(sim))
        (rss1, fd1), (sim_rss1, sim_fd1) = last["ap"], last["sim"]
    finally:
        if chaos is not None:
            chaos.close()
        err = _stop_run(proc, tmp_path / "run")
        print("hil run stderr (tail):\n" + err[-3000:])
    summary = json.loads((tmp_path / "run" / "summary.json").read_text())
    print(f"\nchaos {'signed' if signing else 'unsigned'} {stats.wall_s:.0f} s: actions {dict(stats.actions)}; "
          f"mission acks {dict(stats.mission_acks)}; command acks {dict(stats.command_acks)}; "
          f"connections {stats.connections}; frames {stats.frames_sent}; foreign frames {stats.foreign}; "
          f"RSS {rss0:.1f} -> {rss1:.1f} MB; "
          f"fds {fd0} -> {fd1}; simulator RSS {sim_rss0:.1f} -> {sim_rss1:.1f} MB, fds {sim_fd0} -> {sim_fd1}; "
          f"gcs security_rejects {summary['gcs']['security_rejects']}; "
          f"signature_failures {summary['gcs']['signature_failures']}; attacks {dict(stats.attacks)}")
    assert not ended, (f"the run ended under the chaos after {stats.wall_s:.0f} s: {summary['outcome']} at "
                       f"t = {summary['sim_time_s']:.1f} s", err[-2000:])
    assert summary["outcome"] == "interrupted", (summary["outcome"], err[-2000:])
    assert summary["collision_time_s"] is None
    assert rss1 - rss0 <= RSS_GROWTH_MB and fd1 - fd0 <= FD_GROWTH, (rss0, rss1, fd0, fd1)
    assert sim_rss1 - sim_rss0 <= RSS_GROWTH_MB and sim_fd1 - sim_fd0 <= FD_GROWTH, \
        (sim_rss0, sim_rss1, sim_fd0, sim_fd1)
    gcs = summary["gcs"]
    assert stats.heard["HEARTBEAT"] > 0 and sum(stats.actions.values()) > 20
    assert stats.tcp_connect_failures == 0, "the vessel's TCP server refused a connection"
    # Every refusal the client heard, the vessel counted (it counts those to every GCS, so >=).
    for result, count in stats.mission_acks.items():
        assert gcs["mission_acks"].get(result, 0) >= count, (result, gcs["mission_acks"])
    for result, count in stats.command_acks.items():
        assert gcs["command_acks"].get(result, 0) >= count, (result, gcs["command_acks"])
    if signing:
        # Each kind of bad signed frame the client sent was refused and counted by reason (a replay may be
        # counted as one only while its stream has moved on, so replays are judged together with "future").
        refused = gcs["signature_failures"]
        if stats.attacks["bad_signature"]:
            assert refused.get("bad_signature", 0) >= 1, refused
        if stats.attacks["future"]:
            assert refused.get("future", 0) >= 1, refused
        assert sum(refused.values()) >= 1 or not stats.attacks, refused
