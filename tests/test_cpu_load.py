"""The soak's judgement of planner overruns against the load the run saw (hil/cpu_load.py, issue 16):
foreign CPU time is measured from /proc, and a busy machine alone never fails a soak."""

from __future__ import annotations

import os
import subprocess
import sys

import pytest

from hil import cli
from hil.cpu_load import QUIET_FLOOR, LoadWatch, overruns_allowed, tree_ticks

pytestmark = pytest.mark.skipif(not os.path.exists("/proc/stat"), reason="needs Linux /proc")

# A child that burns a fixed amount of its own CPU time (not wall time), then exits.
BURN = "import time\nend = time.process_time() + {s}\nwhile time.process_time() < end: pass\n"


def test_a_child_reaped_by_a_watched_process_is_ours():
    watch = LoadWatch(every_s=0.0)
    watch.sample([os.getpid()], force=True)
    subprocess.run([sys.executable, "-c", BURN.format(s=0.6)], check=True)
    watch.sample([os.getpid()], force=True)
    r = watch.report()
    assert r["ours_cpu_s"] >= 0.55   # cutime of the reaped child (a restarted planner worker, say)
    assert tree_ticks([os.getpid()]) > 0


def test_foreign_load_from_an_unrelated_process_tree():
    # A grandchild re-parented away (double fork) is nobody's descendant here: foreign load.
    code = ("import os, sys\nif os.fork() == 0:\n    os.setsid()\n    " + BURN.format(s=0.8).replace("\n", "\n    ")
            + "\n    os._exit(0)\nos._exit(0)\n")
    watch = LoadWatch(every_s=0.0)
    r, w = os.pipe()
    watch.sample([os.getpid()], force=True)
    p = subprocess.Popen([sys.executable, "-c", code + "\n"], stdout=w)
    os.close(w)
    p.wait()
    os.read(r, 1)  # EOF once the grandchild (holding the pipe) has finished burning and exited
    os.close(r)
    watch.sample([os.getpid()], force=True)
    rep = watch.report()
    assert rep["foreign_cpu_s"] >= 0.7, rep
    assert rep["ours_cpu_s"] < rep["busy_cpu_s"]


@pytest.mark.parametrize("foreign, wall, expected", [
    (0.0, 60.0, 0),                 # quiet machine: no excuse
    (QUIET_FLOOR * 60.0, 60.0, 0),  # daemons' background: still none
    (3.0 + QUIET_FLOOR * 60, 60.0, 3),
    (60.0, 60.0, 57),               # one CPU busy with someone else the whole minute
])
def test_the_rule(foreign, wall, expected):
    load = {"foreign_cpu_s": foreign, "wall_s": wall}
    assert overruns_allowed(0, load, 1.0) == expected
    assert overruns_allowed(2, load, 1.0) == expected + 2
    assert overruns_allowed(2, None, 1.0) == 2


@pytest.mark.parametrize("argv", [["--load-per-overrun", "0"], ["--duration", "inf"], ["--max-fd-growth", "-1"]])
def test_soak_arguments_are_checked(argv, capsys):
    assert cli.main(["soak", "--actuators", "mavlink", *argv]) == 2
    assert capsys.readouterr().err.count("\n") == 1
