"""Judging a run from records alone (issue 30 point 6: supervision and judging apart): the summary
that `hil run` writes, computed in-process from a tap's records and the processes' tables, with
figures worked out by hand."""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import pytest

from hil import settings
from hil.judging import RunRecord, summarise


@dataclass
class Records:
    truth: dict[int, tuple[float, float, float, float]] = field(default_factory=dict)
    truth_raw: dict[tuple[int, int], tuple[float, float, int]] = field(default_factory=dict)
    estimate: dict[tuple[int, int], tuple[float, float]] = field(default_factory=dict)
    commands: list[tuple[int, float, float]] = field(default_factory=list)
    ais_forwarded: int = 0
    counters_at_close: dict[str, Any] | None = None
    frames: int = 0


def straight_run(seconds: int = 10) -> Records:
    """1 m/s due north for ``seconds`` s, sampled at 1 Hz; full ahead on both thrusters; the estimate
    0.3 m east of the truth."""
    rec = Records(frames=3 * (seconds + 1))
    for k in range(seconds + 1):
        t = k * 1_000_000
        rec.truth[t] = (float(k), 0.0, 1.0, 0.0)
        rec.truth_raw[(0, t)] = (float(k), 0.0, t)
        rec.estimate[(0, k * 1000)] = (float(k), 0.3)
    rec.commands.append((0, 1.0, 1.0))
    return rec


def record(**kw: Any) -> RunRecord:
    base: dict[str, Any] = dict(scenario="harbour", seed=3, lockstep=True, speedup=1.0, outcome="goal",
                                collision_at=None, min_clearance=4.25, wall_s=1.234, decided=None, autopilot=None,
                                simulator=None, simulator_restarts=0, pinned={}, warnings=(), can_log=None,
                                tlog=Path("run.tlog"))
    base.update(kw)
    return RunRecord(**base)


def test_length_energy_and_navigation_error_from_the_records():
    cfg = settings.load()
    s = summarise(record(), straight_run(), cfg)
    assert s.outcome == "goal" and s.reached_goal and s.collisions == 0
    assert s.path_length_m == pytest.approx(10.0)
    # (|T_max| + |T_max|) * 1 m/s * 10 s, the command held from t = 0
    assert s.energy_J == pytest.approx(round(2 * cfg.vessel.T_max * 10.0, 1))
    assert s.navigation_rmse_m == pytest.approx(0.3)
    assert s.sim_time_s == 10.0 and s.min_clearance_m == 4.25 and s.mode == "lockstep" and s.tlog_messages == 33
    assert s.planning_cycles is None          # no vessel-computer summary: its counters are unknown, not 0


def test_the_run_is_judged_up_to_the_deciding_sample():
    cfg = settings.load()
    s = summarise(record(outcome="collision", collision_at=4.0, decided=4_000_000), straight_run(), cfg)
    assert not s.reached_goal and s.collisions == 1 and s.collision_time_s == 4.0
    assert s.path_length_m == pytest.approx(4.0) and s.sim_time_s == 4.0
    assert s.energy_J == pytest.approx(round(2 * cfg.vessel.T_max * 4.0, 1))


def test_a_run_without_samples_is_summarised_without_figures():
    s = summarise(record(outcome="autopilot_exited", min_clearance=math.inf), Records(), settings.load())
    assert s.path_length_m == 0.0 and s.energy_J == 0.0 and s.min_clearance_m is None
    assert s.navigation_rmse_m is None and s.sim_time_s == 0.0
