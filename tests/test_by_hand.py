"""`hil sim` and `hil autopilot` started by hand, as two real processes on the same --scenario, make the
loop `hil run` makes (issue 16): the simulator starts at the scenario's start, not at (0, 0) in the quay,
and the autopilot plans and follows instead of sitting in fallback."""

from __future__ import annotations

import json
import math
import signal
import subprocess
import sys

import pytest

from hil import scenario as scenarios
from hil.hilrun import free_udp_port
from tests.conftest import REPO


@pytest.mark.timeout(600)
def test_sim_and_autopilot_by_hand_on_one_scenario(tmp_path):
    ap_port, sim_port = free_udp_port(), free_udp_port()
    summary_file = tmp_path / "autopilot.json"
    ap = subprocess.Popen(
        [sys.executable, "-m", "hil", "autopilot", "--scenario", "harbour", "--lockstep", "--seed", "1",
         "--listen", f"udpin:127.0.0.1:{ap_port}", "--actuators-to", f"udpout:127.0.0.1:{sim_port}",
         "--gcs", "none", "--summary-out", str(summary_file), "--json"],
        cwd=REPO, stdout=subprocess.DEVNULL, stderr=open(tmp_path / "autopilot.log", "wb"))
    try:
        sim = subprocess.run(
            [sys.executable, "-m", "hil", "sim", "--scenario", "harbour", "--lockstep", "--seed", "1",
             "--state-to", f"127.0.0.1:{ap_port}", "--commands-on", f"127.0.0.1:{sim_port}",
             "--duration", "40", "--json"],
            cwd=REPO, capture_output=True, text=True, timeout=500)
    finally:
        ap.send_signal(signal.SIGTERM)
        ap.wait(timeout=60)
    assert sim.returncode == 0, sim.stderr[-2000:]
    s = json.loads(sim.stdout.strip().splitlines()[-1])
    a = json.loads(summary_file.read_text())
    scen = scenarios.load("harbour")
    fs = s["final_state"]
    north0, east0 = scen.start[1], scen.start[0]
    # The simulator started at the scenario's start and the boat made way towards the goal.
    assert s["commands_received"] > 1000
    assert s["distance_m"] > 20.0
    d0 = math.hypot(scen.goal[0] - east0, scen.goal[1] - north0)
    d1 = math.hypot(scen.goal[0] - fs["y"], scen.goal[1] - fs["x"])
    assert d1 < d0 - 20.0, (fs, scen.start, scen.goal)
    # The autopilot planned and followed (its estimate started where the truth did), no fallback.
    assert a["plans_accepted"] >= 10 and a["fallback_activations"] == 0, {k: a[k] for k in (
        "plans_accepted", "fallback_activations", "events")}
    first = a["estimated_track"][0]
    assert math.hypot(first[1] - north0, first[2] - east0) < 5.0
