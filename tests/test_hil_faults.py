"""The HIL loop under faults: a hung planner, a simulator restart, a lossy link (real processes)."""

from __future__ import annotations

from pathlib import Path

import pytest

from hil import settings
from hil.hilrun import RunOptions, run_loop

TESTS = Path(__file__).resolve().parent


def _run(tmp_path, **kw):
    opts = RunOptions(out=tmp_path / "run", plot=False, wall_timeout=300.0, **kw)
    return run_loop(opts, settings.load(None, opts.overrides))


@pytest.mark.slow
def test_hung_planner_is_killed_and_costs_the_control_loop_nothing(tmp_path, monkeypatch):
    # The autopilot's planner worker gets a handler that never answers; real time x1 for 20 s, so
    # the simulator's 0.5 s stale-command failsafe is also 0.5 s of wall time.
    monkeypatch.setenv("PYTHONPATH", str(TESTS))
    s = _run(tmp_path, scenario="harbour", lockstep=False, speedup=1.0, duration=20.0, seed=1,
             extra_autopilot_args=["--planner-factory", "planner_doubles:hanging_handler"])
    assert s["plans_accepted"] == 0
    assert s["worker_restarts"] >= 5 and s["deadline_overruns"] >= 5
    assert any("killed" in e for e in s["events"])
    # The control loop kept answering every frame: the simulator never hit its stale-command
    # failsafe and received a command for (nearly) every step it ran.
    sim = s["simulator"]
    assert sim["stale_command_events"] == 0
    assert sim["commands_received"] >= 0.95 * sim["steps"]
    # The reactive behaviour kept the vessel clear of obstacles and moving towards the goal.
    assert s["collisions"] == 0 and s["min_clearance_m"] >= 1.0
    assert s["path_length_m"] > 10.0


@pytest.mark.slow
def test_simulator_restart_mid_run_still_reaches_the_goal(tmp_path):
    restarted = []

    def restart_once(tap, run):
        if not restarted and tap.truth and max(tap.truth) >= 40_000_000:
            restarted.append(True)
            run.restart_simulator()

    s = _run(tmp_path, scenario="harbour", lockstep=True, duration=300.0, seed=2, hooks=[restart_once])
    assert restarted and s["simulator_restarts"] == 1
    assert any("simulator restarted" in e for e in s["events"])
    assert s["outcome"] == "goal" and s["collisions"] == 0


@pytest.mark.slow
def test_twenty_percent_datagram_loss_both_ways(tmp_path):
    # Lockstep, so the physics does not depend on this machine's load; every lost frame or command
    # costs the simulator's re-send timeout (3 ms here instead of 1 s) in wall time only.
    s = _run(tmp_path, scenario="labyrinth", lockstep=True, duration=300.0, seed=1,
             overrides=["autopilot.send_loss=0.2", "autopilot.recv_loss=0.2", "sim.lockstep_resend=0.003"])
    assert s["outcome"] == "goal" and s["collisions"] == 0
    # The loss really happened: a re-send for about (1 - 0.8 * 0.8) / (0.8 * 0.8) = 0.56 of the steps.
    sim = s["simulator"]
    assert 0.4 * sim["steps"] < sim["lockstep_resends"] < 0.75 * sim["steps"]
