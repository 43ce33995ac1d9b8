"""Readable output (issue 16): short human summaries with capped lists, the Markdown table of a Monte
Carlo campaign, plots that say where the run started, where it went and how it ended, and tlog time
stamps that follow simulated time in lockstep."""

from __future__ import annotations

import argparse
import json
import struct

import numpy as np
import pytest
from support.summaries import SIMULATOR, run_summary

from autopilot_bridge.summary import ControlLatency, NavigationCounts
from hil import cli, console, plots
from hil.commands.run import human_summary

SUMMARY = run_summary(
    outcome="collision", reached_goal=False, collisions=1, collision_time_s=45.25, min_clearance_m=0.0, sim_time_s=45.3,
    wall_time_s=12.0, path_length_m=50.1, energy_J=4000.0, planning_cycles=45, plans_accepted=40,
    deadline_overruns=3, worker_restarts=0, fallback_activations=2,
    tracking={"frames": 100, "cross_track_rms_m": 0.2, "cross_track_max_m": 0.9},
    navigation_rmse_m=0.1, control_latency_ms=ControlLatency(p50=0.4, p99=6.0, max=80.0, frames=100),
    navigation=NavigationCounts(updates={"gps_pos": 450}, rejected={"gps_pos": 4}, position_resets=0),
    simulator={**SIMULATOR, "stale_command_events": 1},
    events=tuple(f"{t:.2f}s fallback: reactive avoidance, no valid local path " + "x" * 300 for t in range(2000)),
    gcs={"rejects": {f"reason_{i}": i + 1 for i in range(60)}, "received": {}, "signing": False},
    actuators="mavlink", run_folder="/tmp/run", plot="/tmp/run/plot.png",
)


def test_the_run_summary_is_short_and_has_what_matters():
    lines = human_summary(SUMMARY)
    text = "\n".join(lines)
    assert len(lines) <= 15 and max(map(len, lines)) <= 200
    assert lines[0].startswith("outcome: COLLISION at 45.2 s")
    assert "45.3 s simulated" in text and "clearance: min 0 m" in text and "navigation RMSE 0.1 m" in text
    assert "deadline_overruns=3" in text and "fallback_activations=2" in text
    assert "navigation.rejected.gps_pos=4" in text and "simulator.stale_command_events=1" in text
    assert "worker_restarts" not in text and "steps=" not in text  # zero and ordinary counters stay out
    assert "events: 2000" in text and "more)" in text                  # capped and counted


def test_the_generic_summary_caps_lines_lists_and_line_length(capsys):
    summary = {"a": list(range(10_000)), "b": "y" * 50_000, "empty": [], "none": None,
               **{f"k{i}": i for i in range(40)}}
    console.emit(argparse.Namespace(json=False), summary)
    out = capsys.readouterr().out.splitlines()
    assert len(out) <= 15 and max(map(len, out)) <= console.MAX_LINE_CHARS
    assert out[0] == "a: [0, 1, 2, ...] (10000 items)" and "chars)" in out[1]
    assert not any(line.startswith(("empty", "none")) for line in out)
    assert out[-1].endswith("use --json")
    console.emit(argparse.Namespace(json=True), summary)  # --json keeps everything
    assert len(json.loads(capsys.readouterr().out)["a"]) == 10_000


def test_hil_sim_prints_a_short_summary(capsys):
    assert cli.main(["sim", "--state-to", "127.0.0.1:9", "--commands-on", "127.0.0.1:0",
                     "--duration", "0.2", "--speedup", "20"]) == 0
    out = capsys.readouterr().out.splitlines()
    assert 3 <= len(out) <= 15 and max(map(len, out)) <= console.MAX_LINE_CHARS


def test_run_plot_has_start_goal_outcome_and_axis_labels(tmp_path):
    from hil import scenario as scenarios
    from hil.run_plot import plot_run
    from hil.settings import load

    scen = scenarios.load("harbour")
    truth = {int(t * 1e6): (scen.start[1] + t, scen.start[0] + t, 1.0, 1.0) for t in range(20)}
    drawn = plot_run(tmp_path / "p.png", scen, truth, {}, load(), outcome="collision at 19.0 s")
    assert drawn["title"] == "HIL run: harbour: collision at 19.0 s"
    assert any(t.startswith("start (") for t in drawn["legend"])
    assert any(t.startswith("goal (") for t in drawn["legend"])
    assert drawn["xlabel"] == "x east (m)" and drawn["ylabel"] == "y north (m)"


def test_figure11_panels_have_axis_labels_and_start_goal_in_the_legend(tmp_path, monkeypatch):
    seen = {}
    real_save = plots._save

    def keep(fig, out):
        seen["axes"] = [(ax.get_xlabel(), ax.get_ylabel(), ax.axison) for ax in fig.axes]
        seen["legend"] = [t.get_text() for t in fig.axes[0].get_legend().get_texts()]
        return real_save(fig, out)

    monkeypatch.setattr(plots, "_save", keep)
    occ = np.zeros((40, 40), dtype=bool)
    panel = {"occ": occ, "resolution": 1.0, "start": (2, 2), "goal": (30, 30),
             "reference_path": np.array([[2, 2], [30, 30]]), "paths": [("ddrrt-star", np.array([[2, 2], [30, 30]]),
                                                                        True)]}
    plots.plot_runs_grid(tmp_path / "f11.png", [panel, panel])
    assert all(x == "x east (m)" and y == "y north (m)" for x, y, on in seen["axes"] if on)
    assert {"start", "goal", "ddrrt-star"} <= set(seen["legend"])


def test_lockstep_tlog_stamps_follow_simulated_time(tmp_path):
    from pymavlink import mavutil

    from common.geodesy import LocalFrame
    from common.mavlink import Codec
    from hil.tap import Tap

    tap = Tap(tmp_path / "run.tlog", LocalFrame(38.9, 121.6, 0.0), lockstep=True)
    sim = Codec(1, 51)
    ap = Codec(1, 191)
    for t in (0.0, 1.0, 2.5, 172.0):
        usec = int(t * 1e6)
        tap._handle(sim.encode("hil_sensor", usec, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0))
        tap._handle(ap.encode("hil_actuator_controls", usec, [0.0] * 16, 0, 0))
    tap.close()
    log = mavutil.mavlink_connection(str(tmp_path / "run.tlog"))
    stamps = []
    while (m := log.recv_match()) is not None:
        stamps.append((m.get_type(), m._timestamp))
    t0 = stamps[0][1]
    assert [round(ts - t0, 3) for _, ts in stamps] == [0.0, 0.0, 1.0, 1.0, 2.5, 2.5, 172.0, 172.0]
    # a raw look at the first record: 8-byte big-endian µs since the Unix epoch
    raw = (tmp_path / "run.tlog").read_bytes()
    assert struct.unpack(">Q", raw[:8])[0] == pytest.approx(t0 * 1e6, abs=1)


def test_tap_keeps_the_truth_times_sorted_whatever_order_they_come_in(tmp_path):
    """hil run judges the truth sample by sample from Tap.truth_times (kept sorted, not sorted on
    every pass): a late datagram takes its place, a repeated one is not counted twice."""
    from common.geodesy import LocalFrame
    from common.mavlink import Codec
    from hil.tap import Tap

    tap = Tap(tmp_path / "run.tlog", LocalFrame(38.9, 121.6, 0.0), lockstep=True)
    sim = Codec(1, 51)
    order = [0.0, 0.02, 0.06, 0.04, 0.08, 0.06, 0.10]     # 0.04 s comes late, 0.06 s twice
    for t in order:
        tap._handle(sim.encode("hil_state_quaternion", int(t * 1e6), [1, 0, 0, 0], 0, 0, 0,
                               389000000, 1216000000, 0, 100, 0, 0, 0, 0, 0, 0, 0))
    tap.close()
    assert tap.truth_times == sorted(tap.truth) == [int(t * 1e6) for t in sorted(set(order))]


def test_montecarlo_prints_the_markdown_table(tmp_path, capsys):
    rc = cli.main(["montecarlo", "--scenario", "labyrinth", "--runs", "1", "--jobs", "1", "--seed", "3",
                   "--local-iterations", "500", "--cycle-time", "8", "--no-plots", "--out", str(tmp_path)])
    assert rc == 0
    out = capsys.readouterr().out
    assert out.startswith((tmp_path / "table3.md").read_text().rstrip("\n"))
    assert "|---|" in out
    assert "'algorithm':" not in out  # not the raw Python list of dicts of before
    assert out.splitlines()[-1].startswith("3 runs (1 per algorithm) in ")
