"""The GCS session with MAVProxy (no graphical modules) against a live `hil run`.

Skipped, with the reason, where MAVProxy is not installed. It is not in the `test` extra (so CI skips
this): measured on Python 3.11, `pip install MAVProxy` (1.8.75) pulls in VTK, OpenCV, matplotlib, lxml and
shapely, 1.2 GB installed (VTK alone 566 MB), 25 s here; even MAVProxy by itself is 123 MB installed
(a 28.9 MB wheel). What this session needs is MAVProxy's own code and pyserial, beside this project's
pymavlink, numpy and matplotlib: `pip install --no-deps MAVProxy pyserial` (4 s) runs it, without the
graphical modules. MAVProxy is driven through its console: each command is sent when the previous one's
answer has been printed (bounded waits, no sleeps; a MAVProxy that exits fails at once with its output).
"""

from __future__ import annotations

import math
import queue
import shutil
import subprocess
import sys
import threading
import time
from pathlib import Path

import pytest
from support.gcs_client import (
    MISSION_SPEED,
    Gcs,
    at_home,
    check_mission_session,
    qgc_mission,
    qgc_wpl,
    start_run,
    stop_run,
)

from common.geodesy import LocalFrame
from hil.hilrun import free_udp_port

MAVPROXY = shutil.which("mavproxy.py") or str(Path(sys.executable).with_name("mavproxy.py"))
pytestmark = pytest.mark.skipif(not Path(MAVPROXY).exists(), reason="MAVProxy is not installed (pip install MAVProxy)")

GEO = LocalFrame(38.92, 121.65, 0.0)
WAYPOINTS_MAP = [(28.3, 47.5), (31.0, 51.0), (30.0, 58.0), (47.3, 70.0), (53.7, 77.5), (60.0, 85.0)]


class Console:
    def __init__(self, cmd: list[str], cwd: Path) -> None:
        self.proc = subprocess.Popen(cmd, cwd=cwd, stdin=subprocess.PIPE, stdout=subprocess.PIPE,
                                     stderr=subprocess.STDOUT, text=True, bufsize=1, start_new_session=True)
        self.lines: queue.Queue[str] = queue.Queue()
        self.seen: list[str] = []
        threading.Thread(target=self._read, daemon=True).start()

    def _read(self) -> None:
        for line in self.proc.stdout:
            self.lines.put(line.rstrip("\n"))

    def send(self, line: str) -> None:
        self.proc.stdin.write(line + "\n")
        self.proc.stdin.flush()

    def expect(self, *texts: str, timeout: float = 60.0) -> str:
        """The first line holding one of ``texts`` (AssertionError after ``timeout`` s)."""
        end = time.monotonic() + timeout
        while time.monotonic() < end:
            try:
                line = self.lines.get(timeout=0.2)
            except queue.Empty:
                if self.proc.poll() is not None and self.lines.empty():
                    break  # MAVProxy exited (e.g. a missing module): no point waiting
                continue
            self.seen.append(line)
            if any(t in line for t in texts):
                return line
        state = "" if self.proc.poll() is None else f" (it exited with {self.proc.returncode})"
        raise AssertionError(f"MAVProxy never printed {texts!r}{state}; last lines:\n" + "\n".join(self.seen[-30:]))

    def close(self) -> None:
        if self.proc.poll() is None:
            try:
                self.send("exit")
                self.proc.wait(timeout=10)
            except (OSError, subprocess.TimeoutExpired):
                self.proc.kill()
                self.proc.wait()


def test_mavproxy_session(tmp_path):
    wp = tmp_path / "mission.txt"
    lines = ["QGC WPL 110"]
    for i, (x, y) in enumerate(WAYPOINTS_MAP):
        lat, lon = GEO.sea_level_to_geodetic(y, x)
        lines.append(f"{i}\t0\t3\t16\t0\t3\t0\t0\t{lat:.7f}\t{lon:.7f}\t0\t1")
    wp.write_text("\n".join(lines) + "\n")
    port = free_udp_port()
    proc = start_run(tmp_path / "run", "--scenario", "harbour", "--duration", "5000", "--wait-for-arm",
                     "--gcs", f"udpin:127.0.0.1:{port}")
    state = tmp_path / "mavproxy"
    mp = Console([MAVPROXY, f"--master=udpout:127.0.0.1:{port}", "--source-system=255",
                  "--default-modules=wp,param,mode,arm,cmdlong,log", f"--state-basedir={state}"], tmp_path)
    try:
        mp.expect("Detected vehicle 1:1", timeout=240)
        mp.expect("Mode HOLD")
        mp.send(f"wp load {wp}")
        mp.expect("Got MISSION_ACK: TYPE_MISSION: ACCEPTED")
        mp.send("wp list")
        mp.expect("Saved 6 waypoints")
        got = [ln.split("\t") for ln in (state / "way.txt").read_text().splitlines()[1:]]
        assert len(got) == 6
        for (x, y), row in zip(WAYPOINTS_MAP, got, strict=False):
            lat, lon = GEO.sea_level_to_geodetic(y, x)
            # MAVProxy writes its file with 6 decimals (0.1 m); the exact comparison is test_gcs_session's.
            assert abs(float(row[8]) - lat) <= 6e-7 and abs(float(row[9]) - lon) <= 6e-7 and row[3] == "16"
        # The boat refuses to arm before its navigation has a fix; a second ground station (a pymavlink
        # script, beside MAVProxy on the same port) watches for the first position.
        watcher = Gcs(f"udpout:127.0.0.1:{port}", sysid=254)
        try:
            assert watcher.connect(60) is not None and watcher.recv("GLOBAL_POSITION_INT", 60) is not None
        finally:
            watcher.close()
        mp.send("arm throttle")
        mp.expect("COMPONENT_ARM_DISARM: ACCEPTED")
        mp.send("mode AUTO")
        mp.expect("DO_SET_MODE: ACCEPTED")
        mp.expect("waypoint 3", timeout=120)       # MISSION_CURRENT advancing, as MAVProxy reports it
        mp.send("disarm")
        mp.expect("DISARMED")
    finally:
        mp.close()
        stop_run(proc)


def test_mavproxy_mission_with_speed_loiter_and_return_to_launch(tmp_path):
    """Issue 12: a QGC WPL 110 mission with DO_CHANGE_SPEED, NAV_LOITER_TIME and NAV_RETURN_TO_LAUNCH, loaded by
    MAVProxy (`wp load`) and flown in AUTO; the boat comes home, stays up and takes the next mission."""
    from common.mavlink import MAV_TYPE as M

    wp = tmp_path / "mission.waypoints"
    wp.write_text(qgc_wpl(qgc_mission(GEO)))
    port = free_udp_port()
    out = tmp_path / "run"
    # Lockstep paced to 4x wall time (a GCS is attached); the session ends with Ctrl-C, not at a goal.
    proc = start_run(out, "--scenario", "harbour", "--duration", "5000", "--wait-for-arm", "--speedup", "4",
                     "--gcs", f"udpin:127.0.0.1:{port}")
    state = tmp_path / "mavproxy"
    mp = Console([MAVPROXY, f"--master=udpout:127.0.0.1:{port}", "--source-system=255",
                  "--default-modules=wp,param,mode,arm,cmdlong,log", f"--state-basedir={state}"], tmp_path)
    watcher = None
    try:
        mp.expect("Detected vehicle 1:1", timeout=240)
        mp.expect("Mode HOLD")
        mp.send(f"wp load {wp}")
        mp.expect("Got MISSION_ACK: TYPE_MISSION: ACCEPTED")
        mp.send("wp list")
        mp.expect("Saved 6 waypoints")
        got = [ln.split("\t") for ln in (state / "way.txt").read_text().splitlines()[1:]]
        assert [int(r[3]) for r in got] == [16, 16, 16, 19, 178, 20]      # read back as written
        assert float(got[4][5]) == MISSION_SPEED and float(got[3][4]) == 5.0
        watcher = Gcs(f"udpout:127.0.0.1:{port}", sysid=254)
        assert watcher.connect(60) is not None and watcher.recv("GLOBAL_POSITION_INT", 60) is not None
        mp.send("arm throttle")
        mp.expect("COMPONENT_ARM_DISARM: ACCEPTED")
        mp.send("mode AUTO")
        mp.expect("DO_SET_MODE: ACCEPTED")
        done = watcher.recv("MISSION_ITEM_REACHED", 300, lambda m: m.seq == 5)
        assert done is not None, "RTL (item 5) never reached"
        pos = watcher.recv("GLOBAL_POSITION_INT", 10)
        assert pos is not None and at_home(pos, GEO), pos
        # Still up, still in AUTO at the mission's end: the next mission (one waypoint) is taken and flown.
        assert proc.poll() is None
        lat, lon = GEO.sea_level_to_geodetic(50.0, 28.0)
        ack = watcher.upload([(M.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT, M.MAV_CMD_NAV_WAYPOINT, 0, 0, 0, 0,
                               int(round(lat * 1e7)), int(round(lon * 1e7)), 0.0)])
        assert ack is not None and ack.type == M.MAV_MISSION_ACCEPTED
        assert watcher.recv("MISSION_ITEM_REACHED", 120, lambda m: m.seq == 0) is not None
        mp.send("mode HOLD")
        mp.expect("DO_SET_MODE: ACCEPTED")
    finally:
        if watcher is not None:
            watcher.close()
        mp.close()
        stop_run(proc)
    check_mission_session(out / "run.tlog", GEO)


def test_mavproxy_flies_a_qgc_plan_as_ardurover_with_pause_resume_guided_hold_and_rtl(tmp_path):
    """Issue 36, with the boat in its default identity (ArduPilot Rover): MAVProxy's Rover mode table and
    its mission convention (item 0 of the QGC file is home, never executed). The mission is flown with a
    pause (HOLD) and a resume (AUTO), every item from 1 reached once and in order; then GUIDED to a point
    (MAVProxy's `guided`), HOLD and RTL."""
    wp = tmp_path / "mission.waypoints"
    wp.write_text(qgc_wpl(qgc_mission(GEO)))
    port = free_udp_port()
    out = tmp_path / "run"
    proc = start_run(out, "--scenario", "harbour", "--duration", "5000", "--wait-for-arm", "--speedup", "6",
                     "--gcs", f"udpin:127.0.0.1:{port}", identity="ardupilot")
    state = tmp_path / "mavproxy"
    mp = Console([MAVPROXY, f"--master=udpout:127.0.0.1:{port}", "--source-system=255",
                  "--default-modules=wp,param,mode,arm,cmdlong,log", f"--state-basedir={state}"], tmp_path)
    watcher = None
    try:
        mp.expect("Detected vehicle 1:1", timeout=240)
        mp.expect("Mode HOLD")
        mp.send(f"wp load {wp}")
        mp.expect("Got MISSION_ACK: TYPE_MISSION: ACCEPTED")
        watcher = Gcs(f"udpout:127.0.0.1:{port}", sysid=254)
        assert watcher.connect(60) is not None and watcher.recv("GLOBAL_POSITION_INT", 60) is not None
        mp.send("arm throttle")
        mp.expect("COMPONENT_ARM_DISARM: ACCEPTED")
        mp.send("mode AUTO")
        mp.expect("DO_SET_MODE: ACCEPTED")
        assert watcher.recv("MISSION_ITEM_REACHED", 120, lambda m: m.seq == 1) is not None
        mp.send("mode HOLD")                                  # pause ...
        mp.expect("DO_SET_MODE: ACCEPTED")
        assert watcher.recv("HEARTBEAT", 10, lambda h: h.custom_mode == 4) is not None
        mp.send("mode AUTO")                                  # ... and resume where it stood
        mp.expect("DO_SET_MODE: ACCEPTED")
        assert watcher.recv("MISSION_ITEM_REACHED", 300, lambda m: m.seq == 5) is not None
        pos = watcher.recv("GLOBAL_POSITION_INT", 10)
        assert pos is not None and at_home(pos, GEO), pos
        lat, lon = GEO.sea_level_to_geodetic(50.0, 28.0)
        mp.send(f"guided {lat:.7f} {lon:.7f} 0")
        assert watcher.recv("HEARTBEAT", 30, lambda h: h.custom_mode == 15) is not None     # GUIDED
        assert watcher.recv("STATUSTEXT", 300, lambda t: "destination reached" in t.text) is not None
        mp.send("mode HOLD")
        mp.expect("DO_SET_MODE: ACCEPTED")
        mp.send("mode RTL")
        mp.expect("DO_SET_MODE: ACCEPTED")
        assert watcher.recv("HEARTBEAT", 10, lambda h: h.custom_mode == 11) is not None
        assert watcher.recv("STATUSTEXT", 300, lambda t: "RTL: destination reached" in t.text) is not None
    finally:
        if watcher is not None:
            watcher.close()
        mp.close()
        stop_run(proc)
    from pymavlink import mavutil

    log = mavutil.mavlink_connection(str(out / "run.tlog"), dialect="ardupilotmega")
    reached = []
    while (m := log.recv_match(type="MISSION_ITEM_REACHED")) is not None:
        if m.get_srcSystem() == 1:
            reached.append(m.seq)
    assert reached[:5] == [1, 2, 3, 4, 5], reached          # item 0 (home) never: ArduPilot's convention


def _harbour_session(tmp_path: Path) -> tuple[subprocess.Popen, Console, Gcs]:
    """`hil run` of the harbour waiting for arm at --speedup 4, MAVProxy (system 255) on its ground-station
    endpoint and a second ground station (254) that watches."""
    port = free_udp_port()
    proc = start_run(tmp_path / "run", "--scenario", "harbour", "--duration", "5000", "--wait-for-arm",
                     "--speedup", "4", "--gcs", f"udpin:127.0.0.1:{port}")
    mp = Console([MAVPROXY, f"--master=udpout:127.0.0.1:{port}", "--source-system=255",
                  "--default-modules=mode,arm,cmdlong,wp", f"--state-basedir={tmp_path / 'mavproxy'}"], tmp_path)
    watcher = Gcs(f"udpout:127.0.0.1:{port}", sysid=254)
    return proc, mp, watcher


def _ned(p) -> tuple[float, float]:
    """A GLOBAL_POSITION_INT's position, NED m from the harbour's origin."""
    return GEO.geodetic_to_sea_level(p.lat * 1e-7, p.lon * 1e-7)


def _guided_to(mp: Console, target: tuple[float, float]) -> None:
    """MAVProxy: `mode GUIDED`, then `guided` to ``target`` (NED m) as a mission item (not DO_REPOSITION)."""
    mp.send("mode GUIDED")
    mp.expect("DO_SET_MODE: ACCEPTED")
    lat, lon = GEO.sea_level_to_geodetic(*target)
    mp.send("set guided_use_reposition 0")
    mp.send(f"guided {lat:.7f} {lon:.7f} 0")
    mp.expect("TYPE_MISSION: ACCEPTED")


def test_mavproxy_guided_then_disarm_beside_the_breakwater_is_refused_and_disarm_force_is_taken(tmp_path):
    """Issue 31: MAVProxy's `guided LAT LON ALT` as ArduPilot's guided "fly to" (MISSION_ITEM_INT with
    current = 2, as QGroundControl's "Go to location" on an ArduPilot vehicle) is refused in HOLD
    (MISSION_ACK ERROR, as ArduRover) and taken in GUIDED: the boat keeps station at the target 4 m south
    of the breakwater, the harbour's current (0.5 m/s) setting onto it. MAVProxy's `disarm` is refused
    there (TEMPORARILY_REJECTED, the boat stays armed: drifting, it would be set onto the breakwater within
    10 s); `disarm force` (param2 = 21196) is taken."""
    from common.mavlink import MAV_TYPE as M

    target = (104.0, 92.0)                  # NED m, as tests/test_holding_ground.py's
    proc, mp, watcher = _harbour_session(tmp_path)
    try:
        mp.expect("Detected vehicle 1:1", timeout=240)
        assert watcher.connect(60) is not None and watcher.recv("GLOBAL_POSITION_INT", 60) is not None
        mp.send("arm throttle")
        mp.expect("COMPONENT_ARM_DISARM: ACCEPTED")
        lat, lon = GEO.sea_level_to_geodetic(*target)
        mp.send("set guided_use_reposition 0")    # MAVProxy 1.8 sends DO_REPOSITION unless told otherwise
        mp.send(f"guided {lat:.7f} {lon:.7f} 0")
        mp.expect("not GUIDED")                   # in HOLD: refused, the reason in a STATUSTEXT
        mp.send("mode GUIDED")
        mp.expect("DO_SET_MODE: ACCEPTED")
        mp.send(f"guided {lat:.7f} {lon:.7f} 0")
        mp.expect("TYPE_MISSION: ACCEPTED")

        def there(p) -> bool:
            return math.dist(_ned(p), target) <= 1.0
        assert watcher.recv("GLOBAL_POSITION_INT", 240, there) is not None
        mp.send("disarm")
        mp.expect("COMPONENT_ARM_DISARM: TEMPORARILY_REJECTED")
        hb = watcher.recv("HEARTBEAT", 10, lambda h: h.get_srcSystem() == 1)
        assert hb is not None and hb.base_mode & M.MAV_MODE_FLAG_SAFETY_ARMED
        mp.send("disarm force")
        mp.expect("COMPONENT_ARM_DISARM: ACCEPTED")
        hb = watcher.recv("HEARTBEAT", 10, lambda h: h.get_srcSystem() == 1 and
                          not h.base_mode & M.MAV_MODE_FLAG_SAFETY_ARMED)
        assert hb is not None
    finally:
        watcher.close()
        mp.close()
        stop_run(proc)


def test_mavproxy_mode_changes_every_second_beside_the_breakwater_keep_the_boat_off_it(tmp_path):
    """Issue 31, the chaos hour's last collisions flown by hand with MAVProxy: GUIDED to a target 2.5 m
    (cell-centre measure) south of the breakwater, where the harbour's current sets north onto it, then
    `mode LOITER`, `mode HOLD`, `mode MANUAL` (no stick: HOLD) and `mode GUIDED` in turn, each taken as soon
    as MAVProxy printed the last one's ACCEPTED, for a minute of vehicle time. MAVProxy shows each mode
    taken; a second ground station watching GLOBAL_POSITION_INT sees the hull's centre stay clear of what
    `hil run`'s judge calls a collision (1.25 m), and the run does not end."""
    from support.closed_loop import COLLISION_CLEARANCE, clearance

    target = (105.9, 92.0)
    proc, mp, watcher = _harbour_session(tmp_path)
    try:
        mp.expect("Detected vehicle 1:1", timeout=240)
        assert watcher.connect(60) is not None and watcher.recv("GLOBAL_POSITION_INT", 60) is not None
        mp.send("arm throttle")
        mp.expect("COMPONENT_ARM_DISARM: ACCEPTED")
        _guided_to(mp, target)
        arrived = watcher.recv("GLOBAL_POSITION_INT", 240, lambda p: math.dist(_ned(p), target) <= 3.0)
        assert arrived is not None
        t0, worst, k = arrived.time_boot_ms, math.inf, 0
        modes = ("LOITER", "HOLD", "MANUAL", "GUIDED")
        while True:
            mp.send(f"mode {modes[k % len(modes)]}")
            mp.expect("DO_SET_MODE: ACCEPTED")
            k += 1
            p = watcher.recv("GLOBAL_POSITION_INT", 10)
            assert p is not None, "the run stopped streaming"
            worst = min(worst, clearance(*_ned(p)))
            if p.time_boot_ms - t0 > 60_000:
                break
        assert k >= 8, k
        assert worst > COLLISION_CLEARANCE, worst
        assert proc.poll() is None
    finally:
        watcher.close()
        mp.close()
        stop_run(proc)


def test_mavproxy_guided_entered_again_keeps_station_instead_of_resuming_the_old_target(tmp_path):
    """ArduRover's boats start a loiter on every entry into GUIDED (``ModeGuided::_enter``); only a new goto
    gives a target. Flown with MAVProxy: `guided` to open water 24 m north of the harbour's start, `mode LOITER`
    half-way, then `mode GUIDED` again. A second ground station sees the boat keep station where GUIDED was
    entered (80 s of vehicle time at --speedup 4); until b26c891 it went on to the old target."""
    target = (64.0, 22.0)                   # NED m, 24 m north of the start, open water (15 m clear)
    proc, mp, watcher = _harbour_session(tmp_path)
    try:
        mp.expect("Detected vehicle 1:1", timeout=240)
        assert watcher.connect(60) is not None
        start = watcher.recv("GLOBAL_POSITION_INT", 60)
        assert start is not None
        mp.send("arm throttle")
        mp.expect("COMPONENT_ARM_DISARM: ACCEPTED")
        _guided_to(mp, target)
        half = math.dist(_ned(start), target) / 2.0
        assert watcher.recv("GLOBAL_POSITION_INT", 240, lambda p: math.dist(_ned(p), target) <= half) is not None
        mp.send("mode LOITER")
        mp.expect("DO_SET_MODE: ACCEPTED")
        mp.send("mode GUIDED")
        mp.expect("DO_SET_MODE: ACCEPTED")
        assert watcher.recv("HEARTBEAT", 10, lambda h: h.get_srcSystem() == 1 and h.custom_mode == 15) is not None
        entered = watcher.recv("GLOBAL_POSITION_INT", 10)
        assert entered is not None
        here, t0, farthest, nearest = _ned(entered), entered.time_boot_ms, 0.0, math.inf
        while True:
            p = watcher.recv("GLOBAL_POSITION_INT", 10)
            assert p is not None, "the run stopped streaming"
            farthest = max(farthest, math.dist(_ned(p), here))
            nearest = min(nearest, math.dist(_ned(p), target))
            if p.time_boot_ms - t0 > 80_000:
                break
        assert farthest <= 5.0, farthest                          # kept station where GUIDED was entered
        assert nearest >= math.dist(here, target) - 5.0, nearest  # never went on to the old target
        assert proc.poll() is None
    finally:
        watcher.close()
        mp.close()
        stop_run(proc)
