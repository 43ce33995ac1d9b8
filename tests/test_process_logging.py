"""The processes' per-package loggers: a `hil` command shows their INFO records as bare lines on stderr."""

from __future__ import annotations

import logging

import pytest

from autopilot_bridge.route_planning import RouteKeeper
from hil import console
from planner.gridmap import OccupancyGrid


@pytest.fixture
def restore_loggers():
    saved = {n: (list(lg.handlers), lg.level, lg.propagate)
             for n in console.PROCESS_PACKAGES for lg in [logging.getLogger(n)]}
    yield
    for n, (handlers, level, propagate) in saved.items():
        lg = logging.getLogger(n)
        lg.handlers[:] = handlers
        lg.setLevel(level)
        lg.propagate = propagate


def test_records_of_the_packages_are_bare_progress_lines_once(restore_loggers, capsys):
    console.configure_logging()
    console.configure_logging()  # idempotent: still one handler a package
    logging.getLogger("autopilot_bridge.autopilot").info("autopilot t=1.00s: planner restarted")
    logging.getLogger("simulator.core").info("sim: 10 frames")
    logging.getLogger("simulator.core").debug("below INFO: not shown")
    logging.getLogger("somebody_else").warning("not ours: left to the root logger")
    err = capsys.readouterr().err
    assert err.splitlines()[:2] == ["autopilot t=1.00s: planner restarted", "sim: 10 frames"]
    assert "below INFO" not in err


def test_a_component_without_a_log_callback_logs_under_its_module():
    keeper = RouteKeeper(OccupancyGrid([[False]], 1.0), 0.0)
    assert keeper.log == logging.getLogger("autopilot_bridge.route_planning").info


def test_a_progress_bar_reports_the_first_and_last_item_and_throttles_between(capsys):
    bar = console.ProgressBar(5, "work", every_s=3600.0)
    for done in range(1, 6):
        bar.update(done, f"ok {done}")
    lines = capsys.readouterr().err.splitlines()
    assert [ln.split(" (")[0] for ln in lines] == ["work: 1/5", "work: 5/5"]
    assert lines[0].endswith("ok 1") and "ETA" in lines[0]
