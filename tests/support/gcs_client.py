"""A small ground station written with pymavlink's mavutil, for the GCS-link tests.

It talks to a live `hil run` over loopback UDP: heartbeats at 1 Hz (wall), mission upload and
download the way a GCS does them (answering MISSION_REQUEST_INT or legacy MISSION_REQUEST), commands
with their COMMAND_ACK, parameters. Every wait is bounded and keeps the heartbeat going.
"""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

os.environ.setdefault("MAVLINK20", "1")  # before mavutil picks its dialect: MAVLink 2 frames

from pymavlink import mavutil

REPO = Path(__file__).resolve().parents[2]
M = mavutil.mavlink


class Gcs:
    def __init__(self, url: str, sysid: int = 255, compid: int = 190) -> None:
        self.conn = mavutil.mavlink_connection(url, source_system=sysid, source_component=compid,
                                               dialect="ardupilotmega", autoreconnect=False)
        self.mav = self.conn.mav
        self.target = (1, 1)
        self.heartbeats_on = True
        self._last_hb = 0.0
        self.seen: list[Any] = []

    def beat(self, force: bool = False) -> None:
        if (self.heartbeats_on or force) and time.monotonic() - self._last_hb >= 1.0:
            self._last_hb = time.monotonic()
            self.mav.heartbeat_send(M.MAV_TYPE_GCS, M.MAV_AUTOPILOT_INVALID, 0, 0, M.MAV_STATE_ACTIVE)

    def recv(self, types: list[str] | str | None, timeout: float,
             cond: Callable[[Any], bool] = lambda _m: True) -> Any:
        """The next message of ``types`` from the boat that satisfies ``cond`` (None after ``timeout`` s)."""
        if isinstance(types, str):
            types = [types]
        end = time.monotonic() + timeout
        while time.monotonic() < end:
            self.beat()
            m = self.conn.recv_match(blocking=True, timeout=0.2)
            if m is None or m.get_srcSystem() != self.target[0]:
                continue
            if types is None or m.get_type() in types:
                if cond(m):
                    return m
        return None

    def connect(self, timeout: float = 240.0) -> Any:
        self.beat(force=True)
        return self.recv("HEARTBEAT", timeout)

    def drain(self) -> None:
        while self.conn.recv_match(blocking=False) is not None:
            pass

    # -- commands ------------------------------------------------------------------------------
    def command(self, cmd: int, *params: float, timeout: float = 10.0) -> Any:
        p = list(params) + [0.0] * (7 - len(params))
        self.drain()  # acks the boat sent to other ground stations earlier
        self.mav.command_long_send(self.target[0], self.target[1], cmd, 0, *p)
        me = (self.mav.srcSystem, self.mav.srcComponent)
        return self.recv("COMMAND_ACK", timeout, lambda a: a.command == cmd and (a.target_system,
                                                                                 a.target_component) == me)

    def arm(self, on: bool = True) -> Any:
        return self.command(M.MAV_CMD_COMPONENT_ARM_DISARM, 1.0 if on else 0.0, float("nan"))

    def set_mode(self, custom_mode: int) -> Any:
        return self.command(M.MAV_CMD_DO_SET_MODE, M.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED, custom_mode,
                            float("nan"), float("nan"))

    # -- mission ------------------------------------------------------------------------------
    def upload(self, items: list[tuple], timeout: float = 30.0, stop_after: int | None = None,
               mission_type: int = M.MAV_MISSION_TYPE_MISSION) -> Any:
        """Upload (frame, command, p1, p2, p3, p4, lat_e7, lon_e7, alt) items; the MISSION_ACK (or None).

        ``stop_after``: answer only that many item requests, then go silent (an interrupted upload);
        ``mission_type``: MISSION, FENCE or RALLY.
        """
        self.drain()
        self.mav.mission_count_send(self.target[0], self.target[1], len(items), mission_type)
        answered = 0
        end = time.monotonic() + timeout
        self.requests: list[int] = []
        while time.monotonic() < end:
            m = self.recv(["MISSION_REQUEST_INT", "MISSION_REQUEST", "MISSION_ACK"], end - time.monotonic())
            if m is None:
                return None
            if m.get_type() == "MISSION_ACK":
                return m
            self.requests.append(m.seq)
            if stop_after is not None and answered >= stop_after:
                continue
            fr, cmd, p1, p2, p3, p4, x, y, z = items[m.seq]
            self.mav.mission_item_int_send(self.target[0], self.target[1], m.seq, fr, cmd, 0, 1, p1, p2, p3, p4,
                                           x, y, z, mission_type)
            answered += 1
        return None

    def download(self, timeout: float = 30.0) -> list[Any] | None:
        self.drain()
        self.mav.mission_request_list_send(self.target[0], self.target[1], M.MAV_MISSION_TYPE_MISSION)
        c = self.recv("MISSION_COUNT", timeout)
        if c is None:
            return None
        items = []
        for seq in range(c.count):
            self.mav.mission_request_int_send(self.target[0], self.target[1], seq, M.MAV_MISSION_TYPE_MISSION)
            it = self.recv("MISSION_ITEM_INT", timeout, lambda m, s=seq: m.seq == s)
            if it is None:
                return None
            items.append(it)
        self.mav.mission_ack_send(self.target[0], self.target[1], M.MAV_MISSION_ACCEPTED, M.MAV_MISSION_TYPE_MISSION)
        return items

    # -- parameters -----------------------------------------------------------------------------
    def param_set(self, name: str, value: float, timeout: float = 10.0) -> Any:
        self.drain()
        self.mav.param_set_send(self.target[0], self.target[1], name.encode(), value, M.MAV_PARAM_TYPE_REAL32)
        return self.recv("PARAM_VALUE", timeout, lambda m: m.param_id == name)

    def close(self) -> None:
        self.conn.close()


def start_run(out: Path, *args: str, identity: str = "generic") -> subprocess.Popen:
    """`hil run` as a real subprocess (own session, so the test can stop the whole tree). ``identity``:
    the boat's ``[gcs] identity`` (these sessions' missions were written for ``generic``, where item 0 is
    the first waypoint; tests/test_gcs_rover.py flies the default, ``ardupilot``, where item 0 is home)."""
    cmd = [sys.executable, "-m", "hil", "run", "--json", "--no-plot", "--out", str(out), *args,
           "--set", f'gcs.identity="{identity}"']
    return subprocess.Popen(cmd, cwd=REPO, stdout=subprocess.PIPE, stderr=subprocess.PIPE, start_new_session=True)


def stop_run(proc: subprocess.Popen, timeout: float = 60.0) -> tuple[str, str]:
    """SIGINT (the run stops its processes and writes its folder), SIGKILL of the group if it hangs."""
    if proc.poll() is None:
        os.killpg(proc.pid, signal.SIGINT)
    try:
        out, err = proc.communicate(timeout=timeout)
    except subprocess.TimeoutExpired:
        os.killpg(proc.pid, signal.SIGKILL)
        out, err = proc.communicate()
    return out.decode(errors="replace"), err.decode(errors="replace")


# -- the mission every GCS session test flies (issue 12): short legs in the harbour's open water ----------
HOME_MAP = (22.0, 40.0)                       # the harbour's start, map x east / y north, m
MISSION_SPEED = 0.75                          # m/s, the DO_CHANGE_SPEED item's (exact in float32, as on the wire)
LOITER_S = 5.0


def qgc_mission(geo: Any) -> list[tuple]:
    """The mission as QGroundControl writes it: (frame, command, p1, p2, p3, p4, lat, lon, alt) per item.

    0 home (NAV_WAYPOINT at the start), 1-2 waypoints ~11 m apart, 3 NAV_LOITER_TIME 5 s, 4 DO_CHANGE_SPEED
    0.75 m/s (frame MISSION, position 0/0, as QGC writes DO items; ArduPilot starts it with item 3), 5
    NAV_RETURN_TO_LAUNCH (28 m back home). Open water west of the first pier (clearance >= 7 m on every
    leg; the scenario's own reference path crosses that pier), every leg shorter than 30 m."""
    def at(x: float, y: float) -> tuple[float, float]:
        return geo.sea_level_to_geodetic(y, x)

    rel, mis = M.MAV_FRAME_GLOBAL_RELATIVE_ALT, M.MAV_FRAME_MISSION
    return [
        (M.MAV_FRAME_GLOBAL, M.MAV_CMD_NAV_WAYPOINT, 0, 0, 0, 0, *at(*HOME_MAP), 0.0),
        (rel, M.MAV_CMD_NAV_WAYPOINT, 0, 0, 0, 0, *at(28.0, 50.0), 0.0),
        (rel, M.MAV_CMD_NAV_WAYPOINT, 0, 0, 0, 0, *at(30.0, 60.0), 0.0),
        (rel, M.MAV_CMD_NAV_LOITER_TIME, LOITER_S, 0, 0, 0, *at(26.0, 68.0), 0.0),
        (mis, M.MAV_CMD_DO_CHANGE_SPEED, 1, MISSION_SPEED, -1, 0, 0.0, 0.0, 0.0),
        (rel, M.MAV_CMD_NAV_RETURN_TO_LAUNCH, 0, 0, 0, 0, 0.0, 0.0, 0.0),
    ]


def qgc_wpl(items: list[tuple]) -> str:
    """A QGC WPL 110 .waypoints file (MAVProxy `wp load`, QGroundControl's legacy export)."""
    lines = ["QGC WPL 110"]
    for i, (frame, cmd, p1, p2, p3, p4, lat, lon, alt) in enumerate(items):
        lines.append(f"{i}\t{int(i == 0)}\t{frame}\t{cmd}\t{p1:.8f}\t{p2:.8f}\t{p3:.8f}\t{p4:.8f}\t"
                     f"{lat:.8f}\t{lon:.8f}\t{alt:.6f}\t1")
    return "\n".join(lines) + "\n"


def check_mission_session(tlog: Path, geo: Any, count: int = 6, speedup: float = 4.0) -> None:
    """What the boat sent during the session (the run's tlog): every item reached, the speed change in
    VFR_HUD, the STATUSTEXTs of the speed and the loiter; and lockstep paced to at most ``speedup`` x wall
    time while armed (an upper bound: a slow machine only lowers the ratio)."""
    log = mavutil.mavlink_connection(str(tlog), dialect="ardupilotmega")
    reached, texts, speeds, current = [], [], {}, None
    armed, paced = False, []          # (wall s as the tap stamped it, vehicle s) while armed
    while (m := log.recv_match()) is not None:
        if m.get_srcSystem() != 1 or m.get_srcComponent() != 1:
            continue
        kind = m.get_type()
        if kind == "MISSION_ITEM_REACHED":
            reached.append(m.seq)
        elif kind == "MISSION_CURRENT":
            current = m.seq
        elif kind == "VFR_HUD" and current is not None and len(set(reached)) < count:
            speeds.setdefault(current, []).append(m.groundspeed)
        elif kind == "STATUSTEXT":
            texts.append(m.text)
        elif kind == "HEARTBEAT":
            armed = bool(m.base_mode & M.MAV_MODE_FLAG_SAFETY_ARMED)
        elif kind == "GLOBAL_POSITION_INT" and armed:
            paced.append((m._timestamp, m.time_boot_ms * 1e-3))
    assert set(range(count)) <= set(reached), reached
    assert len(paced) > 50
    sim, wall = paced[-1][1] - paced[0][1], paced[-1][0] - paced[0][0]
    assert sim <= speedup * 1.1 * wall + 1.0, (sim, wall)
    assert reached.count(5) >= 1 and reached.index(3) < reached.index(4), reached  # the DO item runs as item 3 ends
    before = speeds.get(1, []) + speeds.get(2, [])
    rtl = speeds.get(5, [])
    assert before and max(before) > 1.0, before            # cruise (1.5 m/s) before the change
    assert len(rtl) >= 8, rtl
    settled = sorted(rtl[len(rtl) // 2:])                   # the second half of the way home
    assert max(settled) <= MISSION_SPEED + 0.25 and abs(settled[len(settled) // 2] - MISSION_SPEED) <= 0.15, rtl
    assert any(f"speed {MISSION_SPEED:g} m/s" in t for t in texts), texts
    assert any(f"loiter {LOITER_S:g} s" in t for t in texts), texts


def at_home(p: Any, geo: Any, tol: float = 4.0) -> bool:
    n, e = geo.geodetic_to_sea_level(p.lat * 1e-7, p.lon * 1e-7)
    return abs(n - HOME_MAP[1]) <= tol and abs(e - HOME_MAP[0]) <= tol
