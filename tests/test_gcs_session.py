"""A ground station (pymavlink) against a live `hil run`: the whole GCS session of issue 6.

The run is lockstep and starts disarmed in HOLD (--wait-for-arm), so it waits for the GCS; its
--duration bounds it, and the test stops it with SIGINT when done (then SIGKILL if it hangs).
"""

from __future__ import annotations

import json
import math
import time

import pytest
from support.gcs_client import Gcs, M, start_run, stop_run

from common.geodesy import LocalFrame
from hil.hilrun import free_udp_port

GEO = LocalFrame(38.92, 121.65, 0.0)  # [geodesy] of configs/default.toml
# Six waypoints in the harbour's open water north-east of the start (map x east, y north; m).
WAYPOINTS_MAP = [(28.3, 47.5), (31.0, 51.0), (30.0, 58.0), (47.3, 70.0), (53.7, 77.5), (60.0, 85.0)]


def _item(x: float, y: float, radius: float = 3.0) -> tuple:
    lat, lon = GEO.sea_level_to_geodetic(y, x)
    return (M.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT, M.MAV_CMD_NAV_WAYPOINT, 0.0, radius, 0.0, float("nan"),
            int(round(lat * 1e7)), int(round(lon * 1e7)), 0.0)


def _same(sent: tuple, got) -> bool:
    fr, cmd, p1, p2, p3, p4, x, y, z = sent
    def fl(a, b):
        return (math.isnan(a) and math.isnan(b)) or a == b
    return (got.frame, got.command, got.x, got.y) == (fr, cmd, x, y) and all(
        fl(a, b) for a, b in ((p1, got.param1), (p2, got.param2), (p3, got.param3), (p4, got.param4), (z, got.z)))


def _ned(msg) -> tuple[float, float]:
    return GEO.geodetic_to_sea_level(msg.lat * 1e-7, msg.lon * 1e-7)


@pytest.fixture
def live_run(tmp_path):
    runs = []

    def start(*extra: str, name: str = "run"):
        port = free_udp_port()
        out = tmp_path / name
        proc = start_run(out, "--scenario", "harbour", "--duration", "5000", "--wait-for-arm",
                         "--gcs", f"udpin:127.0.0.1:{port}", *extra)
        gcs = Gcs(f"udpout:127.0.0.1:{port}")
        runs.append((proc, gcs))
        return proc, gcs, out

    yield start
    for proc, gcs in runs:
        gcs.close()
        stop_run(proc)


def test_gcs_session_mission_commands_params_failsafe(live_run):
    proc, gcs, out = live_run("--set", "gcs.failsafe_timeout=2.0")
    hb = gcs.connect()
    assert hb is not None, "no HEARTBEAT from the boat"
    assert hb.type == M.MAV_TYPE_SURFACE_BOAT and hb.custom_mode == 4  # HOLD
    assert not hb.base_mode & M.MAV_MODE_FLAG_SAFETY_ARMED

    # The telemetry set is there.
    for kind in ("SYS_STATUS", "GLOBAL_POSITION_INT", "GPS_RAW_INT", "ATTITUDE", "VFR_HUD", "MISSION_CURRENT",
                 "ACTUATOR_OUTPUT_STATUS"):
        assert gcs.recv(kind, 30) is not None, kind

    # Upload 6 waypoints, download them, compare exactly.
    items = [_item(x, y) for x, y in WAYPOINTS_MAP]
    ack = gcs.upload(items)
    assert ack is not None and ack.type == M.MAV_MISSION_ACCEPTED, ack
    assert gcs.requests == list(range(6))
    got = gcs.download()
    assert got is not None and len(got) == 6
    assert all(_same(s, g) for s, g in zip(items, got, strict=False))

    # A rejected upload (an unsupported command in item 2) leaves the mission as it was.
    bad = list(items)
    bad[2] = (M.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT, M.MAV_CMD_NAV_TAKEOFF) + items[2][2:]
    ack = gcs.upload(bad)
    assert ack is not None and ack.type == M.MAV_MISSION_UNSUPPORTED
    off_chart = list(items)
    off_chart[4] = _item(5000.0, 77.5)
    ack = gcs.upload(off_chart)
    assert ack is not None and ack.type == M.MAV_MISSION_INVALID_PARAM6_Y
    ack = gcs.upload(items * 40)  # 240 > gcs.max_mission_items
    assert ack is not None and ack.type == M.MAV_MISSION_NO_SPACE
    # An interrupted upload: the boat re-requests, then cancels, and keeps the old mission.
    ack = gcs.upload([_item(30.0, 50.0)] * 3, stop_after=1, timeout=15)
    assert ack is not None and ack.type == M.MAV_MISSION_OPERATION_CANCELLED
    assert gcs.requests.count(1) >= 2  # item 1 was asked for again before giving up
    got = gcs.download()
    assert got is not None and len(got) == 6 and all(_same(s, g) for s, g in zip(items, got, strict=False))

    # Arm, AUTO: the mission's current item advances and the boat moves.
    start = gcs.recv("GLOBAL_POSITION_INT", 10)
    ack = gcs.arm(True)
    assert ack is not None and ack.result == M.MAV_RESULT_ACCEPTED
    ack = gcs.set_mode(10)
    assert ack is not None and ack.result == M.MAV_RESULT_ACCEPTED
    hb = gcs.recv("HEARTBEAT", 10, lambda h: h.custom_mode == 10 and h.base_mode & M.MAV_MODE_FLAG_SAFETY_ARMED)
    assert hb is not None
    cur = gcs.recv("MISSION_CURRENT", 120, lambda m: m.seq >= 3)
    assert cur is not None and cur.total == 6, "MISSION_CURRENT did not advance"
    now = gcs.recv("GLOBAL_POSITION_INT", 10)
    moved = math.dist(_ned(start), _ned(now))
    assert moved > 10.0, moved
    assert gcs.recv("TRAJECTORY_REPRESENTATION_WAYPOINTS", 20) is not None

    # A parameter: in range it changes, out of range it does not.
    pv = gcs.param_set("WP_SPEED", 1.2)
    assert pv is not None and abs(pv.param_value - 1.2) < 1e-6
    pv = gcs.param_set("WP_SPEED", 99.0)
    assert pv is not None and abs(pv.param_value - 1.2) < 1e-6

    # Disarm: zero thrust.
    ack = gcs.arm(False)
    assert ack is not None and ack.result == M.MAV_RESULT_ACCEPTED
    out_status = gcs.recv("ACTUATOR_OUTPUT_STATUS", 10, lambda m: m.actuator[0] == 0.0 and m.actuator[1] == 0.0)
    assert out_status is not None

    # Link loss: armed in AUTO, the GCS goes quiet; after 2 s the boat holds station (LOITER) and says so.
    assert gcs.arm(True).result == M.MAV_RESULT_ACCEPTED
    assert gcs.set_mode(10).result == M.MAV_RESULT_ACCEPTED
    gcs.heartbeats_on = False
    text = gcs.recv("STATUSTEXT", 30, lambda m: "failsafe" in m.text)
    assert text is not None
    hb = gcs.recv("HEARTBEAT", 10, lambda h: h.custom_mode == 5)
    assert hb is not None and hb.system_status == M.MAV_STATE_CRITICAL
    gcs.heartbeats_on = True
    gcs.close()
    stop_run(proc)

    ap = json.loads((out / "autopilot.json").read_text())
    g = ap["gcs"]
    assert g["mission"]["uploads_accepted"] == 1
    assert g["mission"]["upload_timeouts"] == 1 and g["mission"]["rejected_item"] == 2
    assert g["mission"]["rejected_no_space"] == 1
    assert any("GCS failsafe" in e for e in ap["events"])

    # Ctrl-C (SIGINT) ended the run: exit 130, and the run's summary.json carries the link's counters.
    assert proc.returncode == 130
    summary = json.loads((out / "summary.json").read_text())
    assert summary["outcome"] == "interrupted" and not summary["reached_goal"]
    s = summary["gcs"]
    assert s == g
    assert s["datagrams_in"] > 0 and s["datagrams_out"] > 0 and s["frames_in"] > 0 and not s["signing"]
    assert s["missions_accepted"] == 1 and s["missions_rejected"] >= 4
    for result in ("MAV_MISSION_UNSUPPORTED", "MAV_MISSION_INVALID_PARAM6_Y", "MAV_MISSION_NO_SPACE",
                   "MAV_MISSION_OPERATION_CANCELLED"):
        assert s["mission_acks"].get(result, 0) >= 1, (result, s["mission_acks"])
    assert s["command_acks"]["MAV_RESULT_ACCEPTED"] >= 5
    assert s["commands"]["MAV_CMD_COMPONENT_ARM_DISARM:MAV_RESULT_ACCEPTED"] >= 3
    assert s["failsafe_events"] == 1

    # The GCS traffic both ways is in the run's tlog.
    from pymavlink import mavutil

    log = mavutil.mavlink_connection(str(out / "run.tlog"), dialect="ardupilotmega")
    from_gcs, to_gcs, reached = set(), set(), set()
    while (m := log.recv_match()) is not None:
        if m.get_type() == "MISSION_ITEM_REACHED":
            reached.add(m.seq)
        if m.get_srcSystem() == 255:
            from_gcs.add(m.get_type())
        elif m.get_type() in ("COMMAND_ACK", "MISSION_ACK", "MISSION_REQUEST_INT", "PARAM_VALUE"):
            to_gcs.add(m.get_type())
    assert {"HEARTBEAT", "MISSION_COUNT", "MISSION_ITEM_INT", "COMMAND_LONG", "PARAM_SET"} <= from_gcs
    assert {"COMMAND_ACK", "MISSION_ACK", "MISSION_REQUEST_INT", "PARAM_VALUE"} <= to_gcs
    assert {0, 1, 2} <= reached  # each item reached was announced


def test_signing_rejects_unsigned_and_forged_writes_and_the_allow_list_holds(live_run, tmp_path):
    key = bytes(range(32))
    key_file = tmp_path / "gcs.key"
    key_file.write_text(key.hex())
    proc, gcs, out = live_run("--set", f"gcs.signing_key_file={json.dumps(str(key_file))}",
                              "--set", "gcs.allowed_sysids=[255]")
    # Telemetry stays readable without the key.
    hb = gcs.connect()
    assert hb is not None and hb.custom_mode == 4
    assert gcs.recv("GLOBAL_POSITION_INT", 30) is not None
    # Unsigned arm: denied, still disarmed.
    ack = gcs.arm(True)
    assert ack is not None and ack.result == M.MAV_RESULT_DENIED
    assert gcs.recv("HEARTBEAT", 5, lambda h: not h.base_mode & M.MAV_MODE_FLAG_SAFETY_ARMED) is not None
    # Signed with the wrong key (a second GCS, same ids, a later timestamp): denied too.
    port = gcs.conn.destination_addr[1]
    forger = Gcs(f"udpout:127.0.0.1:{port}")
    # (it reads the boat's frames although their signatures do not match its key)
    # Its timestamps are an hour ahead: were they recorded, the real GCS would fail the replay check.
    ahead = int((time.time() - 1420070400 + 3600) * 1e5)
    forger.conn.setup_signing(bytes(32 * [7]), sign_outgoing=True, allow_unsigned_callback=lambda *_: True,
                              initial_timestamp=ahead, link_id=0)
    assert forger.connect(30) is not None
    ack = forger.arm(True)
    assert ack is not None and ack.result == M.MAV_RESULT_DENIED
    # Signed with the key: accepted (the forged frame did not poison the replay check).
    gcs.conn.setup_signing(key, sign_outgoing=True, link_id=0)
    ack = gcs.arm(True)
    assert ack is not None and ack.result == M.MAV_RESULT_ACCEPTED
    assert gcs.recv("HEARTBEAT", 10, lambda h: h.base_mode & M.MAV_MODE_FLAG_SAFETY_ARMED) is not None
    # Signed, but not on the allow-list: denied.
    other = Gcs(f"udpout:127.0.0.1:{port}", sysid=200)
    other.conn.setup_signing(key, sign_outgoing=True)
    assert other.connect(30) is not None
    ack = other.arm(False)
    assert ack is not None and ack.result == M.MAV_RESULT_DENIED
    for c in (forger, other):
        c.close()
    gcs.close()
    stop_run(proc)
    sec = json.loads((out / "autopilot.json").read_text())["gcs"]["security_rejects"]
    assert sec.get("unsigned", 0) >= 1 and sec.get("bad_signature", 0) >= 1 and sec.get("not_allowed_sysid", 0) >= 1
    s = json.loads((out / "summary.json").read_text())["gcs"]
    assert s["signing"] and s["security_rejects"] == sec
    assert s["command_acks"].get("MAV_RESULT_DENIED", 0) >= 3 and s["command_acks"]["MAV_RESULT_ACCEPTED"] >= 1
    assert s["failsafe_events"] == 0
    # With a key the run folder's signed traffic and summaries are owner-only.
    for name in ("run.tlog", "summary.json", "autopilot.json"):
        assert (out / name).stat().st_mode & 0o077 == 0, name
