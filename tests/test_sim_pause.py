"""A paused simulator is reported, never replayed as a burst (issue 31, point 3).

The real `hil sim` process in real time is stopped with SIGSTOP for 2 s of wall time and continued
with SIGCONT. Before: it caught up by running the missed 2 s at once (a burst of 200 frames, most of
them under the thrust set before the pause) and reported nothing. Now: the missed steps are skipped,
the simulated time goes on at the wall clock's pace from where it stopped, and the summary carries
the stall as an event with its length.
"""

from __future__ import annotations

import signal
import time

from test_sim_udp import FRAME_WAIT_S, finish, start_sim

from hil.processes import stop as stop_process
from hil.sim_client import HilClient

PAUSE_S = 2.0


def test_sigstop_of_the_simulator_is_a_reported_stall_not_a_burst():
    client = HilClient()
    proc = start_sim(client.port, "--speedup", "1", "--duration", "0")
    try:
        first = client.next_frame(timeout=FRAME_WAIT_S)
        assert first is not None
        end = time.monotonic() + 1.0
        while time.monotonic() < end:        # a second of normal running, every frame answered
            f = client.next_frame(timeout=1.0)
            assert f is not None
            client.command(f.time_usec, 0.5, 0.5)
        proc.send_signal(signal.SIGSTOP)
        time.sleep(PAUSE_S)                  # the pause itself, measured by the simulator
        while client.next_frame(timeout=0.0) is not None:
            pass                             # what it sent before it stopped
        proc.send_signal(signal.SIGCONT)
        resumed = client.next_frame(timeout=FRAME_WAIT_S)
        assert resumed is not None
        # The simulated time of what arrives in the next 0.5 s of wall time: about 0.5 s, never the 2 s burst.
        times = [resumed.time_usec]
        end = time.monotonic() + 0.5
        while time.monotonic() < end:
            f = client.next_frame(timeout=0.1)
            if f is not None:
                times.append(f.time_usec)
                client.command(f.time_usec, 0.5, 0.5)
        proc.send_signal(signal.SIGTERM)
        summary = finish(proc)
    finally:
        proc.send_signal(signal.SIGCONT)
        stop_process(proc)
        client.close()
    span = (max(times) - min(times)) * 1e-6
    assert span < 1.2, f"{span:.2f} s of simulated time in 0.5 s of wall time after SIGCONT: a burst"
    stalls = summary["stalls"]
    assert stalls["count"] >= 1
    longest = max(e["length_s"] for e in stalls["events"])
    assert PAUSE_S - 0.3 <= longest <= PAUSE_S + 3.0, stalls
    assert stalls["total_s"] >= longest
