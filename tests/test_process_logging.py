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
