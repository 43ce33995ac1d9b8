"""`hil run --autopilot ardupilot`: the real ArduRover SITL flies the simulated boat (hil/ardupilot.py).

The end-to-end tests need the ArduRover SITL binary at ../shared/ardupilot/ardurover (from the
repository's root) and skip, saying so, where it is absent; the errors a user meets without it do not."""

from __future__ import annotations

import json
import os
import subprocess
import sys
import time
from pathlib import Path

import pytest
from conftest import REPO, run_hil

from hil.run_summary import read_summary

SITL = REPO.parent / "shared" / "ardupilot" / "ardurover"
needs_sitl = pytest.mark.skipif(not SITL.is_file(), reason=f"the ArduRover SITL binary is not at {SITL}")
NO_ENV = {"ARDUPILOT_SITL": ""}


def _one_line_error(r: subprocess.CompletedProcess, *words: str) -> str:
    assert r.returncode == 2, r.stderr
    lines = [ln for ln in r.stderr.strip().splitlines() if ln.strip()]
    assert len(lines) == 1 and "Traceback" not in r.stderr, r.stderr
    for w in words:
        assert w in lines[0], lines[0]
    return lines[0]



def announced_gcs_port(proc: subprocess.Popen, timeout_s: float = 120.0) -> int:
    """The TCP port `hil run --autopilot ardupilot` announces for ground stations (ArduRover's SERIAL1),
    read from its stderr; fails the test when none is announced in ``timeout_s``."""
    assert proc.stderr is not None
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        line = proc.stderr.readline()
        if not line:
            break
        if "ground stations on TCP" in line:
            return int(line.rsplit(" ", 1)[1])
    raise AssertionError("no ground-station port announced")

def test_without_a_binary_the_user_is_told_how_in_one_line(tmp_path: Path) -> None:
    r = run_hil("run", "--scenario", "harbour", "--autopilot", "ardupilot", "--out", str(tmp_path / "r"),
                env=NO_ENV, timeout=120)
    _one_line_error(r, "--ardupilot-bin", "ARDUPILOT_SITL")
    r = run_hil("run", "--autopilot", "ardupilot", "--ardupilot-bin", str(tmp_path / "none"),
                "--out", str(tmp_path / "r2"), timeout=120)
    _one_line_error(r, "no such file")


def test_a_broken_binary_is_one_line(tmp_path: Path) -> None:
    for name, body in (("garbage", b"\x7fELF not really"), ("script", b"#!/bin/sh\necho hello\n")):
        folder = tmp_path / name
        folder.mkdir()
        fake = folder / "ardurover"
        fake.write_bytes(body)
        fake.chmod(0o755)
        for parm in ("rover.parm", "motorboat.parm", "rover-skid.parm"):
            (folder / parm).write_text("FRAME_CLASS 2\n")
        r = run_hil("run", "--autopilot", "ardupilot", "--out", str(folder / "r"), env={"ARDUPILOT_SITL": str(fake)},
                    timeout=120)
        _one_line_error(r, str(fake))
    os.chmod(fake, 0o644)
    r = run_hil("run", "--autopilot", "ardupilot", "--ardupilot-bin", str(fake), "--out", str(tmp_path / "r3"),
                timeout=120)
    _one_line_error(r, "not executable")


def test_a_firmware_that_never_calls_the_physics_ends_the_run_with_its_reason(tmp_path: Path) -> None:
    """A binary that passes the check but exits at once: no servo packet for IDLE_TIMEOUT_S, one line
    that names its exit code and its last output, exit 1, and no ArduRover left behind."""
    folder = tmp_path / "sitl"
    folder.mkdir()
    fake = folder / "ardurover"
    fake.write_text('#!/bin/sh\nif [ "$1" = --help ]; then echo "--model MODEL"; exit 0; fi\n'
                    'echo "cannot open the JSON socket"; exit 3\n')
    fake.chmod(0o755)
    for parm in ("rover.parm", "motorboat.parm", "rover-skid.parm"):
        (folder / parm).write_text("SERVO1_FUNCTION 73\nSERVO3_FUNCTION 74\n")
    r = run_hil("run", "--autopilot", "ardupilot", "--ardupilot-bin", str(fake), "--out", str(tmp_path / "r"),
                "--no-plot", timeout=180)
    assert r.returncode == 1, r.stderr
    last = r.stderr.strip().splitlines()[-1]
    assert "sent no servo packet" in last and "exit code 3" in last and "cannot open the JSON socket" in last
    assert "Traceback" not in r.stderr


def test_lockstep_only(tmp_path: Path) -> None:
    r = run_hil("run", "--autopilot", "ardupilot", "--speedup", "2", "--ardupilot-bin", str(SITL),
                "--out", str(tmp_path / "r"), timeout=120)
    _one_line_error(r, "--speedup")


def test_the_fence_is_for_arduRover_only(tmp_path: Path) -> None:
    r = run_hil("run", "--scenario", "harbour", "--ardupilot-fence", "--out", str(tmp_path / "r"), timeout=120)
    _one_line_error(r, "--ardupilot-fence", "--autopilot ardupilot")


@needs_sitl
def test_a_chart_arduRover_cannot_store_as_its_fence_is_one_line(tmp_path: Path) -> None:
    """The labyrinth's walls and islands need more fence vertices than ArduRover stores (84)."""
    r = run_hil("run", "--scenario", "labyrinth", "--autopilot", "ardupilot", "--ardupilot-fence",
                "--ardupilot-bin", str(SITL), "--out", str(tmp_path / "r"), timeout=120)
    assert r.returncode == 2 and "Traceback" not in r.stderr, r.stderr
    errors = [ln for ln in r.stderr.splitlines() if "error" in ln]    # after the run's opening line
    assert len(errors) == 1 and errors[0] == r.stderr.strip().splitlines()[-1], r.stderr
    assert "--ardupilot-fence" in errors[0] and "labyrinth" in errors[0] and "84 fence vertices" in errors[0]
    assert not list(tmp_path.glob("r/ardupilot/ardurover.log"))   # refused before ArduRover started


@needs_sitl
def test_ardurover_flies_the_harbour_route_and_a_rerun_is_byte_identical(tmp_path: Path) -> None:
    """ArduRover (motorboat-skid parameters plus the project's) flies the harbour's global route to the
    goal without collision, in lockstep with the JSON physics; two runs write the same run.tlog, byte for
    byte. A third, with a ground station connected to ArduRover's SERIAL1 at a moment of wall time, is
    judged the same (its run.tlog is not compared: docs/ardupilot.md, "Repeatability")."""
    from pymavlink import mavutil

    outs = [tmp_path / "a", tmp_path / "b", tmp_path / "gcs"]
    # One instance for all three: with another hil run on the machine the lowest free instance, and with it
    # the system id in every frame, would differ between the runs.
    instance = str(60 + os.getpid() % 30)
    cmd = [sys.executable, "-m", "hil", "run", "--scenario", "harbour", "--autopilot", "ardupilot",
           "--duration", "260", "--json", "--no-plot", "--instance", instance]
    env = {**os.environ, "ARDUPILOT_SITL": str(SITL)}
    summaries = []
    for out in outs:
        proc = subprocess.Popen([*cmd, "--out", str(out)], cwd=REPO, env=env, text=True,
                                stdout=subprocess.PIPE, stderr=subprocess.PIPE)
        try:
            if out.name == "gcs":   # a ground station on ArduRover's SERIAL1, as on any SITL
                port = announced_gcs_port(proc)
                gcs = mavutil.mavlink_connection(f"tcp:127.0.0.1:{port}", source_system=250, retries=20)
                try:
                    hb = gcs.wait_heartbeat(timeout=60)
                finally:
                    gcs.close()
                assert hb is not None and hb.type == mavutil.mavlink.MAV_TYPE_SURFACE_BOAT
                assert hb.autopilot == mavutil.mavlink.MAV_AUTOPILOT_ARDUPILOTMEGA
            stdout, stderr = proc.communicate(timeout=600)
        finally:
            if proc.poll() is None:
                proc.kill()
                proc.communicate()
        assert proc.returncode == 0, stderr[-2000:]
        summaries.append(json.loads(stdout))
        typed = read_summary(summaries[-1])    # its simulator section as the JSON back-end typed it
        setup = typed.ardurover()
        assert setup is not None and typed.simulator_counters() is None and setup["mission_items"] > 1
    s = summaries[0]
    assert s["outcome"] == "goal" and s["reached_goal"] and s["collisions"] == 0
    assert s["min_clearance_m"] > 1.0 and s["energy_J"] > 0 and s["actuators"] == "ardupilot"
    ap = s["simulator"]["ardupilot"]
    assert ap["auto_at_s"] is not None and ap["mission_items"] > 10
    assert ap["mission_time_s"] == pytest.approx(s["sim_time_s"] - ap["auto_at_s"], abs=1e-3)
    assert any("Reached waypoint" in t for t in ap["statustext"])
    tlogs = [(o / "run.tlog").read_bytes() for o in outs[:2]]
    assert len(tlogs[0]) > 100_000 and tlogs[0] == tlogs[1]
    judged = ("outcome", "reached_goal", "collisions", "min_clearance_m", "sim_time_s", "path_length_m", "energy_J")
    for other in summaries[1:]:
        assert {k: other[k] for k in judged} == {k: s[k] for k in judged}
    types = set()
    m = mavutil.mavlink_connection(str(outs[0] / "run.tlog"))
    while (msg := m.recv_msg()) is not None:
        types.add(msg.get_type())
    assert {"HIL_STATE_QUATERNION", "HEARTBEAT", "MISSION_ITEM_INT", "MISSION_ACK", "COMMAND_LONG"} <= types


def _download_fence(port: int, expected: int, timeout: float = 240.0) -> list:
    """A ground station on ArduRover's SERIAL1 asks for its fence (MISSION_REQUEST_LIST, mission_type
    FENCE) until it holds ``expected`` items, then reads each one; the MISSION_ITEM_INTs in order."""
    from pymavlink import mavutil

    fence = mavutil.mavlink.MAV_MISSION_TYPE_FENCE
    gcs = mavutil.mavlink_connection(f"tcp:127.0.0.1:{port}", source_system=250, retries=20)
    try:
        hb = gcs.wait_heartbeat(timeout=60)
        assert hb is not None
        target = hb.get_srcSystem()
        deadline = time.monotonic() + timeout
        count = 0
        while count != expected and time.monotonic() < deadline:
            gcs.mav.mission_request_list_send(target, 1, fence)
            msg = gcs.recv_match(type="MISSION_COUNT", blocking=True, timeout=2)
            if msg is not None and msg.mission_type == fence:
                count = msg.count
            if count != expected:
                time.sleep(0.5)
        assert count == expected, f"ArduRover holds {count} fence items, not {expected}"
        items = []
        for seq in range(count):
            got = None
            for _ in range(5):   # lockstep: ArduRover answers between physics steps
                gcs.mav.mission_request_int_send(target, 1, seq, fence)
                got = gcs.recv_match(type="MISSION_ITEM_INT", blocking=True, timeout=3)
                if got is not None and got.seq == seq and got.mission_type == fence:
                    break
            assert got is not None and got.seq == seq, f"fence item {seq} not sent"
            items.append(got)
        gcs.mav.mission_ack_send(target, 1, mavutil.mavlink.MAV_MISSION_ACCEPTED, fence)
        return items
    finally:
        gcs.close()


@needs_sitl
def test_the_chart_as_arduRovers_fence_takes_it_round_the_pier_the_route_crosses(tmp_path: Path) -> None:
    """`--ardupilot-fence`: the harbour's chart goes to ArduRover as exclusion polygons, and ArduRover
    reports back, to a ground station on its SERIAL1, each vertex we sent (MAV_CMD_NAV_FENCE_POLYGON_
    VERTEX_EXCLUSION, the polygon's vertex count, lat/lon to 1e-7 deg). Its mission is the route as
    given, whose second leg crosses pier 1; with its Dijkstra (OA_TYPE 2) ArduRover goes round the pier
    (reaching the waypoint beyond it) and is past it (x > 60 m) before anything ends the run. Where it
    ends (docs/ardupilot.md: a collision at the breakwater's end at this commit) is the bench's figure,
    not asserted here."""
    from pymavlink import mavutil

    from common.geodesy import LocalFrame
    from hil import scenario as scenarios
    from hil import settings
    from hil.ardupilot_fence import FENCE_VERTEX_EXCLUSION, chart_polygons, fence_items

    cfg = settings.load(None, [])
    geo = LocalFrame(cfg.geodesy.lat0, cfg.geodesy.lon0, cfg.geodesy.alt0)
    scen = scenarios.load("harbour")
    assert scen.waypoints is not None
    expected = fence_items(chart_polygons(scen.occ, scen.resolution), geo)
    out = tmp_path / "fence"
    cmd = [sys.executable, "-m", "hil", "run", "--scenario", "harbour", "--autopilot", "ardupilot", "--ardupilot-fence",
           "--duration", "300", "--json", "--no-plot", "--out", str(out)]
    proc = subprocess.Popen(cmd, cwd=REPO, env={**os.environ, "ARDUPILOT_SITL": str(SITL)}, text=True,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    assert proc.stderr is not None
    try:
        port = announced_gcs_port(proc)
        items = _download_fence(port, len(expected))
        stdout, stderr = proc.communicate(timeout=600)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.communicate()
    s = json.loads(stdout)
    assert proc.returncode == (0 if s["reached_goal"] else 1), stderr[-2000:]   # `hil run`: 1 without the goal
    for got, want in zip(items, expected, strict=True):
        assert got.command == FENCE_VERTEX_EXCLUSION and got.param1 == want.vertices
        assert (got.x, got.y) == (round(want.lat * 1e7), round(want.lon * 1e7))
    ap = s["simulator"]["ardupilot"]
    assert ap["params"]["OA_TYPE"] == 2 and ap["params"]["FENCE_ENABLE"] == 1
    assert ap["fence"]["vertices"] == len(expected) and ap["mission_items"] == len(scen.waypoints)
    assert any("fence of" in e and "accepted" in e for e in s["events"])
    log = mavutil.mavlink_connection(str(out / "run.tlog"))
    reached_2 = past_pier = False
    while (msg := log.recv_match(type=["STATUSTEXT", "HIL_STATE_QUATERNION"])) is not None:
        if msg.get_type() == "STATUSTEXT":
            reached_2 |= "Reached waypoint #2" in msg.text
        else:
            east = geo.geodetic_to_sea_level(msg.lat * 1e-7, msg.lon * 1e-7)[1]
            past_pier |= east > 60.0
    assert reached_2 and past_pier, s["outcome"]   # a collision at the pier would have ended the run there


@needs_sitl
def test_arduRover_ends_with_a_hil_killed_outright(tmp_path: Path) -> None:
    """`hil run` killed with SIGKILL cannot end ArduRover itself; ArduRover, waiting in lockstep for the
    physics' answer, would wait for good. The kernel ends it (its parent-death signal)."""
    import signal

    cmd = [sys.executable, "-m", "hil", "run", "--scenario", "harbour", "--autopilot", "ardupilot", "--no-plot",
           "--out", str(tmp_path / "r")]
    proc = subprocess.Popen(cmd, cwd=REPO, env={**os.environ, "ARDUPILOT_SITL": str(SITL)}, text=True,
                            stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
    assert proc.stderr is not None
    pid = None
    try:
        deadline = time.monotonic() + 120
        while pid is None and time.monotonic() < deadline:
            line = proc.stderr.readline()
            if not line:
                break
            if "ArduRover pid" in line:
                pid = int(line.split("ArduRover pid ", 1)[1].split(",", 1)[0])
        assert pid is not None, "no ArduRover pid announced"
        assert Path(f"/proc/{pid}").exists()
    finally:
        proc.send_signal(signal.SIGKILL)
        proc.wait()
    deadline = time.monotonic() + 20
    while Path(f"/proc/{pid}").exists() and "Z" not in _state(pid) and time.monotonic() < deadline:
        time.sleep(0.1)
    assert not Path(f"/proc/{pid}").exists() or "Z" in _state(pid), f"ArduRover {pid} outlived hil"


def _state(pid: int) -> str:
    try:
        return Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[0]
    except (OSError, IndexError):
        return "Z"
