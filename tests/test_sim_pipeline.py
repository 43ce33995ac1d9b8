"""The pipelined lockstep (sim.lockstep_pipeline) over real loopback sockets: the simulator runs one
frame ahead, so the answer to the frame at t_k acts from t_(k+1) - exactly plain lockstep with every
command one frame later - and a lost command or frame neither deadlocks nor stops the loop."""

from __future__ import annotations

import subprocess

import numpy as np

from hil.processes import stop as stop_process
from hil.sim_client import HilClient
from tests.test_sim_udp import finish, start_sim

WAIT_S = 20.0
STEPS = 120


def _sim(client: HilClient, *extra: str) -> subprocess.Popen:
    return start_sim(client.port, "--lockstep", "--seed", "5", "--duration", repr(STEPS / 100.0), *extra)


def _commands() -> list[tuple[float, float]]:
    k = np.arange(STEPS)
    return [(float(0.9 * np.sin(i / 7)), float(0.6 + 0.4 * np.cos(i / 5))) for i in k]


def test_each_command_acts_one_frame_later_than_in_plain_lockstep():
    cmds = _commands()
    # Pipelined: two frames come before any command; the answer to frame k is sent when frame k+1 is in.
    client = HilClient()
    # No re-send within the test's reach (30 s), however loaded the machine: every frame read is a new one.
    proc = _sim(client, "--set", "sim.lockstep_pipeline=true", "--set", "sim.lockstep_resend=30")
    piped = []
    try:
        for k in range(2):
            f = client.next_frame(WAIT_S)
            assert f is not None and f.time_usec == k * 10_000
            piped.append(f.raw)
        for k in range(STEPS - 1):
            client.command(k * 10_000, *cmds[k])
            f = client.next_frame(WAIT_S)
            assert f is not None and f.time_usec == (k + 2) * 10_000, k
            piped.append(f.raw)
        s_piped = finish(proc)
    finally:
        stop_process(proc)
        client.close()
    # Plain lockstep, every command one frame later (thrust zero over the first frame, as with none).
    client = HilClient()
    proc = _sim(client, "--set", "sim.lockstep_resend=30")
    plain = []
    try:
        for k in range(STEPS + 1):
            f = client.next_frame(WAIT_S)
            assert f is not None and f.time_usec == k * 10_000
            plain.append(f.raw)
            if k < STEPS:
                client.command(k * 10_000, *((0.0, 0.0) if k == 0 else cmds[k - 1]))
        s_plain = finish(proc)
    finally:
        stop_process(proc)
        client.close()
    assert piped == plain            # byte for byte, every frame
    assert s_piped["final_state"] == s_plain["final_state"]
    assert s_piped["pipeline_skips"] == 0 and s_piped["lockstep_resends"] == 0 and s_piped["rejects"] == {}
    assert "pipeline_skips" not in s_plain
    # The speed is counted from the first step a command drove: the pipeline's first step has none.
    assert s_piped["stepping"]["steps"] == STEPS - 2 and s_plain["stepping"]["steps"] == STEPS - 1


def test_a_lost_command_or_frame_is_skipped_or_resent_and_the_loop_goes_on():
    client = HilClient()
    proc = _sim(client, "--set", "sim.lockstep_pipeline=true", "--set", "sim.lockstep_resend=0.2")
    try:
        pending = [client.next_frame(WAIT_S), client.next_frame(WAIT_S)]
        assert [f.time_usec for f in pending] == [0, 10_000]
        # Silence: both frames not yet answered come again, unchanged.
        again = [client.next_frame(WAIT_S), client.next_frame(WAIT_S)]
        assert [f.raw for f in again] == [f.raw for f in pending]
        # The answer to t0 "lost": the answer to t1 comes instead. t0 is skipped; the simulator steps
        # twice, so that two frames are pending again.
        client.command(10_000, 0.5, 0.5)
        fresh = [client.next_frame(WAIT_S), client.next_frame(WAIT_S)]
        while fresh[0].time_usec < 20_000:      # re-sends still in the socket
            fresh = [fresh[1], client.next_frame(WAIT_S)]
        assert [f.time_usec for f in fresh] == [20_000, 30_000]
        client.command(0, 1.0, 1.0)             # an answer to a frame no longer pending: refused
        for expect in range(40_000, STEPS * 10_000 + 1, 10_000):
            client.command(expect - 20_000, 0.5, 0.5)
            f = client.next_frame(WAIT_S)
            while f is not None and f.time_usec < expect:   # a late re-send
                f = client.next_frame(WAIT_S)
            assert f is not None and f.time_usec == expect
        s = finish(proc)
    finally:
        stop_process(proc)
        client.close()
    assert s["pipeline_skips"] == 1 and s["lockstep_resends"] >= 1
    assert s["rejects"] == {"out_of_step_command": 1}
    assert s["steps"] == STEPS


def test_the_pipeline_is_refused_with_can_actuators(hil_main):
    r = hil_main("sim", "--lockstep", "--set", "sim.lockstep_pipeline=true", "--set", 'can.actuators="can"',
                 "--duration", "0.1")
    assert r.returncode == 2 and "Traceback" not in r.stderr
    assert "not from CAN ESCs; drop one of the two" in r.stderr.strip().splitlines()[-1]
