"""The simulator process over real loopback UDP sockets: lockstep loop, determinism, fuzzing, signals."""

from __future__ import annotations

import hashlib
import json
import os
import signal
import subprocess
import sys
import time

import numpy as np
import pytest

from common.mavlink import Codec
from hil.processes import stop as stop_process
from hil.sim_client import HilClient
from tests.conftest import REPO

FRAME_WAIT_S = 20.0  # bounded wait for any single frame


def start_sim(client_port: int, *extra: str, pass_fds: tuple[int, ...] = ()) -> subprocess.Popen:
    cmd = [sys.executable, "-m", "hil", "sim", "--json", "--state-to", f"127.0.0.1:{client_port}",
           "--commands-on", "127.0.0.1:0", *extra]
    return subprocess.Popen(cmd, cwd=REPO, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            pass_fds=pass_fds)


def finish(proc: subprocess.Popen) -> dict:
    try:
        out, err = proc.communicate(timeout=30)
    finally:
        stop_process(proc)
    assert proc.returncode == 0, err
    return json.loads(out.strip().splitlines()[-1])


def lockstep_run(steps: int, seed: int = 7) -> tuple[str, dict, int]:
    """Play the autopilot for `steps` lockstep steps; return (sha256 of every datagram, summary, frames)."""
    client = HilClient()
    proc = start_sim(client.port, "--lockstep", "--duration", repr(steps / 100.0), "--seed", str(seed))
    digest = hashlib.sha256()
    try:
        for k in range(steps + 1):
            frame = client.next_frame(timeout=FRAME_WAIT_S)
            assert frame is not None, f"no frame {k}"
            # exactly one sensor frame per step, for the step's time
            assert frame.time_usec == k * 10_000
            assert "HIL_SENSOR" in frame.messages
            digest.update(frame.raw)
            if k < steps:
                client.command(frame.time_usec, 0.8 + 0.2 * np.sin(k / 300), 0.6)
        assert client.ep.recv(timeout=0.0) is None  # nothing beyond the last frame
        summary = finish(proc)
    finally:
        stop_process(proc)
        client.close()
    return digest.hexdigest(), summary, client.frames


@pytest.mark.slow
def test_lockstep_10000_steps_one_frame_per_step_and_byte_identical_reruns():
    h1, s1, frames = lockstep_run(10_000)
    assert frames == 10_001
    assert s1["steps"] == 10_000 and s1["commands_received"] == 10_000
    assert s1["messages_sent"]["HIL_SENSOR"] == 10_001
    assert s1["messages_sent"]["HIL_GPS"] == 1001 and s1["messages_sent"]["HIL_STATE_QUATERNION"] == 5001
    assert s1["lockstep_resends"] == 0 and s1["stale_command_events"] == 0 and s1["rejects"] == {}
    h2, s2, _ = lockstep_run(10_000)
    assert h1 == h2
    assert s1["final_state"] == s2["final_state"]
    h3, _, _ = lockstep_run(200, seed=8)
    h4, _, _ = lockstep_run(200, seed=7)
    assert h3 != h4


def _junk(rng: np.random.Generator, valid: bytes, heartbeat: bytes, kind: int) -> tuple[bytes, str]:
    if kind == 0:
        return rng.integers(0, 256, int(rng.integers(1, 80)), dtype=np.uint8).tobytes(), "random"
    if kind == 1:
        return valid[: int(rng.integers(1, len(valid)))], "truncated"
    if kind == 2:
        b = bytearray(valid)
        bit = int(rng.integers(0, 8 * len(b)))
        b[bit // 8] ^= 1 << (bit % 8)
        return bytes(b), "bitflip"
    return heartbeat, "unwanted_message"


def test_fuzzed_command_port_keeps_stepping_and_counts_every_rejection():
    rng = np.random.default_rng(42)
    steps = 400
    client = HilClient()
    proc = start_sim(client.port, "--lockstep", "--duration", repr(steps / 100.0))
    other = Codec(1, 1)  # the autopilot's ids (autopilot.system_id/component_id): junk from the peer itself
    heartbeat = other.encode("heartbeat", 6, 8, 0, 0, 0)
    sent = {"random": 0, "truncated": 0, "bitflip": 0, "unwanted_message": 0, "nan": 0, "old": 0}
    try:
        frame = client.next_frame(timeout=FRAME_WAIT_S)
        for k in range(steps):
            assert frame is not None and frame.time_usec == k * 10_000
            sim_addr = client.ep.last_sender
            template = other.encode("hil_actuator_controls", frame.time_usec, [0.5] * 16, 0, 0)
            junk, kind = _junk(rng, template, heartbeat, k % 4)
            client.ep.sock.sendto(junk, sim_addr)
            sent[kind] += 1
            if k % 10 == 0:  # NaN control with the right time: rejected, not integrated, not stepped on
                client.ep.sock.sendto(other.encode("hil_actuator_controls", frame.time_usec,
                                                   [float("nan"), 0.5] + [0.0] * 14, 0, 0), sim_addr)
                sent["nan"] += 1
            if k % 10 == 5 and k > 0:  # a late duplicate for the previous step
                client.ep.sock.sendto(other.encode("hil_actuator_controls", frame.time_usec - 10_000,
                                                   [0.5] * 16, 0, 0), sim_addr)
                sent["old"] += 1
            client.command(frame.time_usec, 0.7, 0.7)
            frame = client.next_frame(timeout=FRAME_WAIT_S)
        summary = finish(proc)
    finally:
        stop_process(proc)
        client.close()
    rej = summary["rejects"]
    assert summary["steps"] == steps and summary["commands_received"] == steps
    assert rej.pop("invalid_controls") == sent["nan"]
    assert rej.pop("out_of_step_command") == sent["old"]
    assert rej.get("unwanted_message", 0) == sent["unwanted_message"]
    assert sum(rej.values()) == sent["random"] + sent["truncated"] + sent["bitflip"] + sent["unwanted_message"]
    assert summary["malformed_dropped"] == sum(rej.values()) + sent["nan"]
    assert rej.get("bad_crc", 0) > 0 and rej.get("truncated", 0) > 0 and rej.get("not_mavlink", 0) > 0
    assert all(np.isfinite(v) for v in summary["final_state"].values())


def test_lockstep_stepping_window_leaves_out_the_wait_before_the_first_step():
    """`stepping` (what `hil bench loop` reports as the loop's speed) spans the first to the last
    step: a peer that takes 0.3 s before its first command adds 0.3 s to wall_time_s, not to it."""
    steps, pause = 50, 0.3
    client = HilClient()
    proc = start_sim(client.port, "--lockstep", "--duration", repr(steps / 100.0))
    try:
        for k in range(steps + 1):
            frame = client.next_frame(timeout=FRAME_WAIT_S)
            assert frame is not None, f"no frame {k}"
            if k == 0:
                time.sleep(pause)  # a slow start-up on the other side, before the first step
            if k < steps:
                client.command(frame.time_usec, 0.8, 0.6)
        summary = finish(proc)
    finally:
        stop_process(proc)
        client.close()
    st = summary["stepping"]
    assert st["steps"] == steps - 1  # intervals between the first and the last step
    assert 0.0 < st["wall_s"] <= summary["wall_time_s"] - pause
    assert st["steps_per_s"] == pytest.approx(st["steps"] / st["wall_s"], rel=1e-3)


def _sim_waiting_on_start_fd(client: HilClient) -> tuple[subprocess.Popen, int]:
    """`hil sim --start-fd`, returned once it has said on stderr that it is set up (it prints its
    addresses just before it waits); the write end of the pipe is the caller's."""
    r, w = os.pipe()
    proc = start_sim(client.port, "--lockstep", "--duration", "0.05", "--start-fd", str(r), pass_fds=(r,))
    os.close(r)
    line = proc.stderr.readline()          # bounded by the process: EOF if it dies
    assert line.startswith("sim: commands on"), line
    return proc, w


def test_start_fd_holds_the_first_frame_until_the_parent_says_go():
    """How `hil run` starts the simulator beside the autopilot: set up, then no frame before GO."""
    from common.readiness import GO

    client = HilClient()
    proc, w = _sim_waiting_on_start_fd(client)
    try:
        assert client.next_frame(timeout=0.3) is None   # set up and waiting: nothing sent yet
        os.write(w, GO)
        os.close(w)
        w = -1
        for k in range(6):
            frame = client.next_frame(timeout=FRAME_WAIT_S)
            assert frame is not None and frame.time_usec == k * 10_000
            if k < 5:
                client.command(frame.time_usec, 0.5, 0.5)
        out, _ = proc.communicate(timeout=30)
        assert proc.returncode == 0 and json.loads(out.strip().splitlines()[-1])["steps"] == 5
    finally:
        if w >= 0:
            os.close(w)
        stop_process(proc)
        client.close()


def test_start_fd_closed_without_go_exits_without_a_frame():
    """The parent gave up (the autopilot failed to start): the simulator ends quietly, exit 0."""
    client = HilClient()
    proc, w = _sim_waiting_on_start_fd(client)
    try:
        os.close(w)
        out, err = proc.communicate(timeout=30)
        assert proc.returncode == 0 and "not started" in err and out.strip() == ""
        assert client.next_frame(timeout=0.0) is None
    finally:
        stop_process(proc)
        client.close()


def test_realtime_stale_commands_and_sigterm_summary():
    """Real time x20 with no commands: the failsafe fires once; SIGTERM ends with a summary, exit 0."""
    client = HilClient()
    proc = start_sim(client.port, "--speedup", "20", "--duration", "0", "--set", "sim.initial.u=1.0")
    try:
        for _ in range(200):  # 200 frames = 2 s simulated > 0.5 s timeout
            assert client.next_frame(timeout=FRAME_WAIT_S) is not None
        proc.send_signal(signal.SIGTERM)
        summary = finish(proc)
    finally:
        stop_process(proc)
        client.close()
    assert summary["mode"] == "realtime" and summary["steps"] >= 199
    assert summary["stale_command_events"] == 1 and summary["commands_received"] == 0
    assert set(summary["jitter_ms"]) == {"p50", "p99", "max"}
    assert summary["stepping"] is None  # a lockstep figure only
    assert summary["final_state"]["u"] < 1.0  # coasting down without thrust


def test_the_summary_with_can_escs_is_read_as_the_simulators_type():
    """The simulator with its ESC bank on a CAN bus (python-can's in-process bus: `hil sim` would refuse
    it) runs over its real UDP endpoint and gives a summary that, through JSON, reads strictly as
    SimulatorSummary, its ``can`` section included (what `hil run` reads with read_simulator_summary)."""
    from hil import settings
    from hil.assembly.simulator import build_simulator
    from hil.console import to_json
    from hil.run_summary import read_simulator_summary

    client = HilClient()
    cfg = settings.load(None, ['can.actuators="can"', 'can.interface="virtual"',
                               f'can.channel="sim-summary-{os.getpid()}"', "sim.lockstep=false", "sim.duration=0.5",
                               "sim.speedup=20.0", 'link.commands_on="127.0.0.1:0"',
                               f'link.state_to=["127.0.0.1:{client.port}"]'])
    parts = build_simulator(cfg, None, ())
    try:
        summary = parts.server.run()
    finally:
        parts.close(None)
        client.close()
    typed = read_simulator_summary(json.loads(to_json(summary)))
    assert typed == json.loads(to_json(summary)) and typed["steps"] == 50 and typed["mode"] == "realtime"
    can = typed.get("can")
    assert can is not None and can["node_ids"] and can["raw_commands_applied"] == 0


def test_realtime_applies_newest_command():
    client = HilClient()
    proc = start_sim(client.port, "--speedup", "5", "--duration", "3")
    try:
        for _ in range(100_000):  # bounded: 301 frames expected, idle polls end when the process has
            frame = client.next_frame(timeout=0.2)
            if frame is None:
                if proc.poll() is not None:
                    break
                continue
            client.command(frame.time_usec, 1.0, 1.0)
        summary = finish(proc)
    finally:
        stop_process(proc)
        client.close()
    # How many commands land before each tick depends on scheduling; that full thrust was applied
    # does not: from rest, 3 s of full thrust gives u ~ 2.3 m/s, coasting gives 0.
    assert 0 < summary["commands_received"] <= summary["steps"]
    assert summary["final_state"]["u"] > 1.0


def test_sim_cli_errors_are_one_line(hil_main):
    for args in (["sim", "--commands-on", "nonsense"], ["sim", "--set", "sensors.imu.rate_hz=30.0"],
                 ["sim", "--duration", "-1"], ["sim", "--start-fd", "-1"], ["sim", "--start-fd", "1000000"]):
        r = hil_main(*args, timeout=60)
        assert r.returncode == 2, r.stderr
        assert len(r.stderr.strip().splitlines()) == 1 and "Traceback" not in r.stderr


@pytest.mark.slow   # e2e: two whole `hil run --demo` loops (simulator process + vessel client)
def test_hil_run_lockstep_demo(hil):
    r = hil("run", "--demo", "--duration", "10", "--json", timeout=120)
    assert r.returncode == 0, r.stderr
    s = json.loads(r.stdout)
    assert s["mode"] == "lockstep" and s["sim_time_s"] == 10.0
    assert s["messages"]["commands_sent"] == 1000 == s["messages"]["simulator_commands_received"]
    assert s["distance_travelled_m"] > 5.0 and 0 < s["final_speed_m_s"] < 3.1
    r2 = hil("run", "--demo", "--duration", "10", "--json", timeout=120)
    assert json.loads(r2.stdout)["final_position"] == s["final_position"]


@pytest.mark.parametrize("sig", [signal.SIGTERM, signal.SIGINT])
def test_hil_run_signal_stops_the_simulator_subprocess(sig):
    import select
    import time
    proc = subprocess.Popen([sys.executable, "-m", "hil", "run", "--demo", "--duration", "1000", "--speedup", "1"],
                            cwd=REPO, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    sim_pid, lines = None, []
    try:
        deadline = time.monotonic() + 30
        while time.monotonic() < deadline:  # wait (bounded) until the simulator runs its loop
            ready, _, _ = select.select([proc.stderr], [], [], 1.0)
            if not ready:
                continue
            line = proc.stderr.readline()
            lines.append(line)
            if line.startswith("run: simulator pid"):
                sim_pid = int(line.split()[3].rstrip(","))
            if line.startswith("sim: commands on"):
                break
        assert sim_pid is not None, lines
        proc.send_signal(sig)
        proc.wait(timeout=30)
    finally:
        stop_process(proc)
    assert proc.returncode == 130
    with pytest.raises(ProcessLookupError):
        os.kill(sim_pid, 0)  # reaped by `hil run`: no orphan
