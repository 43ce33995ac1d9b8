"""Physical limits on every number (issue 31, point 2; docs/configuration-ranges.md).

* every configuration key and every numeric command-line option has a finite range, and the docs'
  tables are the code's;
* the issue's three numbers that hung or crashed a run, and the extremes of every range, are one-line
  errors naming the key (exit 2), in-process through hil.cli.main (no traceback can escape);
* values at the ends of the ranges load;
* the lockstep progress watch stops a run that advances too slowly, and only such a run.
"""

from __future__ import annotations

import math
from pathlib import Path

import pytest
from support.cli import run_cli

from hil import config, settings
from hil.cli import build_parser
from hil.commands.arg_types import CLI_RANGES, check_range
from hil.progress_watch import ProgressWatch

DOC = Path(__file__).resolve().parent.parent / "docs" / "configuration-ranges.md"


def test_every_configuration_number_has_a_finite_range_and_the_doc_lists_it():
    ranges = config.key_ranges(settings.HilConfig)
    assert len(ranges) > 150
    for key, _tp, low, high, _unit in ranges:
        assert math.isfinite(low) and math.isfinite(high) and low <= high, key
    text = DOC.read_text()
    assert config.range_table(settings.HilConfig) in text, "regenerate docs/configuration-ranges.md"
    for option, (low, high) in CLI_RANGES.items():
        assert f"| `{option}` | {low:g} | {high:g} |" in text


def test_every_numeric_option_of_every_command_is_range_checked():
    parser = build_parser()
    seen = 0

    def walk(p):
        nonlocal seen
        for action in p._actions:
            if hasattr(action, "choices") and isinstance(action.choices, dict):
                for sub in action.choices.values():
                    walk(sub)
            elif action.type in (float, int) and action.option_strings:
                seen += 1
                name = max(action.option_strings, key=len)
                assert check_range(name, 1e300 if action.type is float else 1 << 70) is not None, name
                assert check_range(name, -1e300 if action.type is float else -(1 << 70)) is not None, name
    walk(parser)
    assert seen > 40


@pytest.mark.parametrize("argv, key", [
    (("run", "--set", "autopilot.lockstep_iterations=1000000000000"), "autopilot.lockstep_iterations"),
    (("run", "--set", "autopilot.lockstep_iterations=1e12"), "autopilot.lockstep_iterations"),
    (("run", "--set", "sim.dt=1e-9"), "sim.dt"),
    (("run", "--set", "sensors.imu.rate_hz=1e-9"), "sensors.imu.rate_hz"),
    (("run", "--set", "autopilot.planning_period=1e-9"), "autopilot.planning_period"),
    (("run", "--set", "sim.seed=99999999999999999999"), "sim.seed"),
    (("run", "--set", "gcs.mission_retries=1000000"), "gcs.mission_retries"),
    (("plan", "--scenario", "harbour", "--resolution", "1e300"), "--resolution"),
    (("plan", "--scenario", "harbour", "--deadline", "inf"), "--deadline"),
    (("plan", "--scenario", "harbour", "--iterations", "100000000000"), "--iterations"),
    (("run", "--speedup", "nan"), "--speedup"),
    (("run", "--wall-timeout", "1e300"), "--wall-timeout"),
    (("montecarlo", "--runs", "0"), "--runs"),
])
def test_out_of_range_is_one_line_naming_the_key_exit_2(capsys, argv, key):
    r = run_cli(capsys, *argv)
    assert r.returncode == 2, r.stderr
    lines = r.stderr.strip().splitlines()
    assert len(lines) == 1 and key in lines[0] and "Traceback" not in r.stderr, r.stderr


def test_the_ends_of_the_ranges_load():
    overrides = [f"{k}={v}" for k, v in (("sim.dt", 0.001), ("autopilot.lockstep_iterations", 100000),
                                         ("sensors.imu.rate_hz", 1.0), ("autopilot.planning_period", 60.0),
                                         ("sim.seed", (1 << 63) - 1))]
    cfg = settings.load(None, overrides)
    assert cfg.sim.dt == 0.001 and cfg.autopilot.lockstep_iterations == 100000


def test_the_progress_watch_stops_a_crawling_lockstep_run_only():
    crawl = ProgressWatch(window_s=60.0, min_rate=0.02)
    assert crawl.check(0.0, 0.0) is None
    assert crawl.check(59.0, 0.5) is None        # the window is not over yet
    why = crawl.check(61.0, 1.0)                   # 1.0 s simulated in 61 s of wall: < 1/50
    assert why is not None and "1.00 s in 61 s" in why and "\n" not in why
    slow_but_moving = ProgressWatch(window_s=60.0, min_rate=0.02)
    slow_but_moving.check(0.0, 0.0)
    for k in range(1, 10):                         # 1.5 s simulated per minute: slow, not stalled
        assert slow_but_moving.check(60.0 * k, 1.5 * k) is None
