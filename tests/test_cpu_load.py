"""The soak's judgement of planner overruns against the load the run saw (hil/cpu_load.py, issue 16):
foreign CPU time is measured from /proc, and a busy machine alone never fails a soak."""

from __future__ import annotations

import json
import os
import subprocess
import sys

import pytest

from hil import cli
from hil.cpu_load import (
    HOST_LOAD_ENV,
    QUIET_FLOOR,
    HostLoadFeed,
    LoadWatch,
    overruns_allowed,
    read_host_load,
    tree_ticks,
)

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


def _record(path, wall, busy_s, ours_s, steal_s=0.0, cpus=2):
    from hil.cpu_load import TICK_S

    path.write_text(json.dumps({"wall": wall, "busy": round(busy_s / TICK_S), "steal": round(steal_s / TICK_S),
                                "ours": round(ours_s / TICK_S), "cpus": cpus}))


def test_inside_user_mode_linux_the_host_load_decides(tmp_path, monkeypatch):
    """`hil vcan -- hil soak`: the guest's /proc hides the host's other processes; the host feed's file
    (HIL_HOST_LOAD) carries them, and the soak's allowance follows the host's foreign load (issue 32)."""
    feed = tmp_path / "host_load.json"
    monkeypatch.setenv(HOST_LOAD_ENV, str(feed))
    watch = LoadWatch(every_s=0.0)
    _record(feed, 100.0, busy_s=1000.0, ours_s=200.0)
    watch.sample([os.getpid()], force=True)
    # 30 s on the host: 40 CPU-s busy, of which the guest (the UML process tree) took 10
    _record(feed, 130.0, busy_s=1040.0, ours_s=210.0, steal_s=1.0)
    watch.sample([os.getpid()], force=True)
    rep = watch.report()
    assert rep["source"] == "host" and rep["wall_s"] == 30.0 and rep["cpus"] == 2
    assert rep["foreign_cpu_s"] == 30.0 and rep["ours_cpu_s"] == 10.0 and rep["steal_cpu_s"] == 1.0
    assert rep["guest"] is not None and "source" not in rep["guest"]   # the guest's own view, kept
    assert overruns_allowed(0, rep, 1.0) == int(30.0 - QUIET_FLOOR * 30.0)


def test_without_a_readable_feed_the_guest_judges_by_its_own_load(tmp_path):
    feed = tmp_path / "host_load.json"
    feed.write_text("{not json")
    watch = LoadWatch(every_s=0.0, host_load=feed)
    watch.sample([os.getpid()], force=True)
    watch.sample([os.getpid()], force=True)
    rep = watch.report()
    assert rep is None or "source" not in rep


def test_the_host_feed_counts_everything_but_the_guest_as_foreign(tmp_path):
    """The host side (hil/uml.py runs it beside the UML process): a process outside the guest's tree
    burning 0.8 s of CPU is foreign; the feed's thread writes its file until stopped."""
    guest = subprocess.Popen([sys.executable, "-c", "import sys; sys.stdin.read()"], stdin=subprocess.PIPE)
    feed_path = tmp_path / "host_load.json"
    try:
        feed = HostLoadFeed(feed_path, guest.pid)
        watch = LoadWatch(every_s=0.0, host_load=feed_path)
        assert feed.write()
        watch.sample([os.getpid()], force=True)
        subprocess.run([sys.executable, "-c", BURN.format(s=0.8)], check=True)   # not the guest's
        assert feed.write()
        watch.sample([os.getpid()], force=True)
        rep = watch.report()
        assert rep["source"] == "host" and rep["foreign_cpu_s"] >= 0.7, rep
        feed_path.unlink()
        feed.start()
        feed.stop()
        assert read_host_load(feed_path) is not None   # the thread writes first, then waits
    finally:
        guest.kill()
        guest.wait()
