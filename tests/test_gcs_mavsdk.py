"""The GCS session with MAVSDK-Python (`pip install mavsdk`, 4.x: the C++ MAVSDK in-process through ctypes,
no mavsdk_server) against a live `hil run --wait-for-arm`.

MAVSDK listens (``udpin://127.0.0.1:PORT``) and the boat sends there (``--gcs udpout:127.0.0.1:PORT``),
as with a ground station on 14550. What MAVSDK does against this boat, plugin by plugin:

* discovery, telemetry (position, armed), Mission and MissionRaw (upload, download, progress), Param
  (list, get, set) and Action.arm/disarm are generic MAVLink and work;
* MAVSDK is PX4-first: for any autopilot that is not ArduPilot (ours says MAV_AUTOPILOT_GENERIC) it sets
  modes the PX4 way, DO_SET_MODE with param2 = PX4 main mode and param3 = sub mode (MissionRaw.start_mission
  is AUTO.MISSION = (4, 4), Action.hold (4, 3), Action.return_to_launch (4, 5)), and decodes custom_mode as
  PX4's (Telemetry.flight_mode is UNKNOWN). The boat has ArduPilot Rover's modes and no sub-modes, so it
  refuses those (DENIED; read as Rover mode 4 they would have meant HOLD). The mode is set with MAVSDK's
  MavlinkDirect plugin instead: DO_SET_MODE with the Rover number, and the mode read from HEARTBEAT.
* Param.set_param_float out of range: the boat keeps the value and answers PARAM_VALUE with it (the
  parameter protocol's answer); MAVSDK waits for the value it asked for, retries, then reports TIMEOUT.

Skipped, with the reason, where mavsdk cannot be imported. Every wait is bounded and waits on a condition.
"""

from __future__ import annotations

import json
import math
from typing import Any

import pytest
from support.gcs_client import HOME_MAP, check_mission_session, qgc_mission, start_run, stop_run
from support.watch import Watch

from common.geodesy import LocalFrame
from common.mavlink import MAV_TYPE as M
from hil.hilrun import free_udp_port

try:
    from mavsdk import Autopilot, ComponentType, Configuration, ConnectionResult, Mavsdk, log_subscribe, log_unsubscribe
    from mavsdk.plugins.action import Action
    from mavsdk.plugins.mavlink_direct import MavlinkDirect, MavlinkMessage
    from mavsdk.plugins.mission import Mission, MissionPlan
    from mavsdk.plugins.mission import MissionItem as PlanItem
    from mavsdk.plugins.mission_raw import MissionItem, MissionRaw, MissionRawError, MissionRawResult
    from mavsdk.plugins.param import Param, ParamError, ParamResult
    from mavsdk.plugins.telemetry import Telemetry
except (ImportError, OSError) as exc:  # OSError: the bundled libcmavsdk.so does not load on this machine
    pytest.skip(f"mavsdk is not importable (pip install mavsdk): {exc}", allow_module_level=True)

GEO = LocalFrame(38.92, 121.65, 0.0)  # [geodesy] of configs/default.toml
WAYPOINTS_MAP = [(28.3, 47.5), (31.0, 51.0), (30.0, 58.0), (47.3, 70.0), (53.7, 77.5), (60.0, 85.0)]
ROVER_AUTO, ROVER_HOLD = 10, 4


def _item(seq: int, x: float, y: float, command: int = M.MAV_CMD_NAV_WAYPOINT) -> MissionItem:
    lat, lon = GEO.sea_level_to_geodetic(y, x)
    return MissionItem(seq=seq, frame=M.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT, command=command, current=int(seq == 0),
                       autocontinue=1, param1=0.0, param2=3.0, param3=0.0, param4=float("nan"),
                       x=int(round(lat * 1e7)), y=int(round(lon * 1e7)), z=0.0, mission_type=0)


def _same(a: MissionItem, b: MissionItem) -> bool:
    def same(u, v):
        return (math.isnan(u) and math.isnan(v)) or u == v
    return (a.seq, a.frame, a.command, a.x, a.y, a.mission_type) == (b.seq, b.frame, b.command, b.x, b.y,
                                                                      b.mission_type) and all(
        same(u, v) for u, v in ((a.param1, b.param1), (a.param2, b.param2), (a.param3, b.param3),
                                (a.param4, b.param4), (a.z, b.z)))


def _ned(p: Any) -> tuple[float, float]:
    return GEO.geodetic_to_sea_level(p.latitude_deg, p.longitude_deg)


def _set_rover_mode(direct: MavlinkDirect, mode: int) -> dict:
    """DO_SET_MODE with ArduPilot Rover's custom mode number through MAVSDK's MavlinkDirect; the ack's fields."""
    fields = {"target_system": 1, "target_component": 1, "command": M.MAV_CMD_DO_SET_MODE, "confirmation": 0,
              "param1": M.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED, "param2": mode, "param3": 0, "param4": 0,
              "param5": 0, "param6": 0, "param7": 0}
    ack = direct.send_command(MavlinkMessage("COMMAND_LONG", 0, 0, 1, 1, json.dumps(fields)))
    return json.loads(ack.fields_json)


def test_mavsdk_session(tmp_path):
    logs: list[str] = []
    log_subscribe(lambda level, text, _f, _l: (logs.append(f"{level.name} {text}"), True)[1])
    port = free_udp_port()
    sdk = Mavsdk(Configuration.create_with_component_type(ComponentType.GROUND_STATION))
    proc = None
    try:
        assert sdk.add_any_connection(f"udpin://127.0.0.1:{port}") == ConnectionResult.SUCCESS
        out = tmp_path / "run"
        proc = start_run(out, "--scenario", "harbour", "--duration", "5000", "--wait-for-arm",
                         "--gcs", f"udpout:127.0.0.1:{port}")
        boat = sdk.first_autopilot(240.0)
        assert boat is not None, "MAVSDK discovered no autopilot; its log:\n" + "\n".join(logs[-30:])
        assert boat.get_system_id() == 1 and boat.autopilot_type() == Autopilot.GENERIC
        direct, telemetry, mission, param, action = (MavlinkDirect(boat), Telemetry(boat), MissionRaw(boat),
                                                     Param(boat), Action(boat))
        heartbeats, positions, progress, armed = Watch(), Watch(), Watch(), Watch()
        direct.subscribe_message("HEARTBEAT", lambda m, ud: heartbeats(json.loads(m.fields_json)))
        telemetry.subscribe_position(positions)
        telemetry.subscribe_armed(armed)
        mission.subscribe_mission_progress(progress)
        hb = heartbeats.wait(lambda h: True, 30)
        assert hb is not None and hb["type"] == M.MAV_TYPE_SURFACE_BOAT and hb["custom_mode"] == ROVER_HOLD
        assert not hb["base_mode"] & M.MAV_MODE_FLAG_SAFETY_ARMED

        # The Mission plugin (MAVSDK's waypoint abstraction) uploads and downloads the 6 waypoints ...
        items = [_item(i, x, y) for i, (x, y) in enumerate(WAYPOINTS_MAP)]
        plan = MissionPlan([PlanItem(latitude_deg=it.x * 1e-7, longitude_deg=it.y * 1e-7, relative_altitude_m=0.0,
                                     is_fly_through=True, acceptance_radius_m=3.0) for it in items])
        waypoints = Mission(boat)
        waypoints.upload_mission(plan)
        back = waypoints.download_mission().mission_items
        assert [(round(p.latitude_deg * 1e7), round(p.longitude_deg * 1e7), p.acceptance_radius_m) for p in back] \
            == [(it.x, it.y, 3.0) for it in items]
        # ... and MissionRaw, item by item as MAVLink has them: upload, download, compare exactly.
        assert mission.upload_mission(items) == MissionRawResult.SUCCESS
        got = mission.download_mission()
        assert len(got) == 6 and all(_same(a, b) for a, b in zip(items, got, strict=False)), [str(g) for g in got]
        # A rejected upload (NAV_TAKEOFF in item 2) leaves it as it was.
        bad = list(items)
        bad[2] = _item(2, *WAYPOINTS_MAP[2], command=M.MAV_CMD_NAV_TAKEOFF)
        with pytest.raises(MissionRawError) as rejected:
            mission.upload_mission(bad)
        assert rejected.value.result == MissionRawResult.UNSUPPORTED
        got = mission.download_mission()
        assert len(got) == 6 and all(_same(a, b) for a, b in zip(items, got, strict=False))

        # Parameters: the list, a change in range, a refused one out of range.
        names = {p.name for p in param.get_all_params().float_params}
        assert {"WP_SPEED", "PLN_DEADLINE", "PLN_PERCEPT_RAD", "FS_GCS_TIMEOUT"} <= names, names
        assert param.set_param_float("WP_SPEED", 1.2) == ParamResult.SUCCESS
        assert param.get_param_float("WP_SPEED") == pytest.approx(1.2, abs=1e-6)
        with pytest.raises(ParamError) as refused:
            param.set_param_float("WP_SPEED", 9.0)
        assert refused.value.result == ParamResult.TIMEOUT  # the boat kept 1.2 and said so; MAVSDK waited for 9
        assert param.get_param_float("WP_SPEED") == pytest.approx(1.2, abs=1e-6)

        # Arm once the navigation has a fix (the boat refuses before).
        start = positions.wait(lambda p: True, 60)
        assert start is not None, "no position from the boat"
        assert action.arm() is not None
        assert armed.wait(lambda a: a, 10) is not None
        # MAVSDK's PX4-style mode change is refused, and the boat stays in HOLD ...
        with pytest.raises(MissionRawError) as denied:
            mission.start_mission()
        assert denied.value.result == MissionRawResult.DENIED
        assert heartbeats.last()["custom_mode"] == ROVER_HOLD
        # ... the Rover mode number through MavlinkDirect starts the mission.
        ack = _set_rover_mode(direct, ROVER_AUTO)
        assert ack["result"] == M.MAV_RESULT_ACCEPTED and (ack["target_system"], ack["target_component"]) == (245, 190)
        assert heartbeats.wait(lambda h: h["custom_mode"] == ROVER_AUTO
                               and h["base_mode"] & M.MAV_MODE_FLAG_SAFETY_ARMED, 10) is not None
        assert progress.wait(lambda p: p.total == 6 and p.current >= 3, 120) is not None, progress.last()
        moved = math.dist(_ned(start), _ned(positions.last()))
        assert moved > 10.0, moved

        assert action.disarm() is not None
        assert armed.wait(lambda a: not a, 10) is not None
        assert heartbeats.wait(lambda h: not h["base_mode"] & M.MAV_MODE_FLAG_SAFETY_ARMED, 10) is not None
    finally:
        sdk.destroy()
        log_unsubscribe()
        if proc is not None:
            stop_run(proc)

    g = json.loads((out / "autopilot.json").read_text())["gcs"]
    assert g["mission"]["uploads_accepted"] == 2 and g["mission"]["rejected_item"] == 1
    assert g["received"].get("PING", 0) >= 1
    # MAVSDK's side of the conversation is in the run's tlog, and the boat answered its pings.
    from pymavlink import mavutil

    log = mavutil.mavlink_connection(str(out / "run.tlog"), dialect="ardupilotmega")
    from_mavsdk, pongs = set(), 0
    while (m := log.recv_match()) is not None:
        if m.get_srcSystem() == 245:
            from_mavsdk.add(m.get_type())
        elif m.get_type() == "PING" and m.get_srcSystem() == 1 and m.target_system == 245:
            pongs += 1
    assert {"HEARTBEAT", "MISSION_COUNT", "MISSION_ITEM_INT", "MISSION_REQUEST_LIST", "PARAM_SET",
            "COMMAND_LONG"} <= from_mavsdk, from_mavsdk
    assert pongs >= 1


def test_mavsdk_mission_with_speed_loiter_and_return_to_launch(tmp_path):
    """Issue 12: the same QGroundControl-style mission (DO_CHANGE_SPEED, NAV_LOITER_TIME, NAV_RETURN_TO_LAUNCH)
    uploaded with MissionRaw, read back exactly, flown in AUTO: every item reached, the boat home and still
    connected afterwards."""
    port = free_udp_port()
    sdk = Mavsdk(Configuration.create_with_component_type(ComponentType.GROUND_STATION))
    proc = None
    out = tmp_path / "run"
    try:
        assert sdk.add_any_connection(f"udpin://127.0.0.1:{port}") == ConnectionResult.SUCCESS
        proc = start_run(out, "--scenario", "harbour", "--duration", "5000", "--wait-for-arm", "--speedup", "4",
                         "--gcs", f"udpout:127.0.0.1:{port}")
        boat = sdk.first_autopilot(240.0)
        assert boat is not None
        direct, telemetry, mission, action = MavlinkDirect(boat), Telemetry(boat), MissionRaw(boat), Action(boat)
        heartbeats, positions, reached = Watch(), Watch(), Watch()
        direct.subscribe_message("HEARTBEAT", lambda m, ud: heartbeats(json.loads(m.fields_json)))
        direct.subscribe_message("MISSION_ITEM_REACHED", lambda m, ud: reached(json.loads(m.fields_json)["seq"]))
        telemetry.subscribe_position(positions)
        items = [MissionItem(seq=i, frame=fr, command=cmd, current=int(i == 0), autocontinue=1, param1=float(p1),
                             param2=float(p2), param3=float(p3), param4=float(p4), x=int(round(lat * 1e7)),
                             y=int(round(lon * 1e7)), z=float(alt), mission_type=0)
                 for i, (fr, cmd, p1, p2, p3, p4, lat, lon, alt) in enumerate(qgc_mission(GEO))]
        assert mission.upload_mission(items) == MissionRawResult.SUCCESS
        got = mission.download_mission()
        assert len(got) == 6
        differ = [(str(a), str(b)) for a, b in zip(items, got, strict=False) if not _same(a, b)]
        assert not differ, differ
        assert positions.wait(lambda p: True, 60) is not None
        assert action.arm() is not None
        ack = _set_rover_mode(direct, ROVER_AUTO)
        assert ack["result"] == M.MAV_RESULT_ACCEPTED
        assert reached.wait(lambda seq: seq == 5, 300) is not None, reached.values
        assert set(range(6)) <= set(reached.values)
        home = positions.last()
        n, e = _ned(home)
        assert math.hypot(n - HOME_MAP[1], e - HOME_MAP[0]) <= 4.0, (n, e)
        # Still connected and up: heartbeats go on in AUTO, armed, and a mode change is acknowledged.
        seen = len(heartbeats.values)
        assert heartbeats.wait(lambda h: len(heartbeats.values) >= seen + 2, 10) is not None
        last = heartbeats.last()
        assert last["custom_mode"] == ROVER_AUTO and last["base_mode"] & M.MAV_MODE_FLAG_SAFETY_ARMED, last
        assert _set_rover_mode(direct, ROVER_HOLD)["result"] == M.MAV_RESULT_ACCEPTED
        assert proc.poll() is None
    finally:
        sdk.destroy()
        if proc is not None:
            stop_run(proc)
    check_mission_session(out / "run.tlog", GEO)


def test_mavsdk_disarm_beside_the_breakwater_is_refused_and_kill_forces_it(tmp_path):
    """Issue 31: MAVSDK's Action sends the boat (goto_location: DO_REPOSITION) to a target 4 m south of the
    breakwater, the harbour's current (0.5 m/s) setting onto it, where it keeps station. Action.disarm there
    is refused, the boat stays armed (drifting, it would be set onto the breakwater within 10 s); Action.kill
    (MAVLink's forced disarm, param2 = 21196) is taken. The reason reaches MAVSDK as a STATUSTEXT."""
    from mavsdk.plugins.action import ActionError

    target = (104.0, 92.0)                  # NED m, as tests/test_holding_ground.py's GUIDED target
    port = free_udp_port()
    sdk = Mavsdk(Configuration.create_with_component_type(ComponentType.GROUND_STATION))
    proc = None
    try:
        assert sdk.add_any_connection(f"udpin://127.0.0.1:{port}") == ConnectionResult.SUCCESS
        proc = start_run(tmp_path / "run", "--scenario", "harbour", "--duration", "5000", "--wait-for-arm",
                         "--speedup", "4", "--gcs", f"udpout:127.0.0.1:{port}")
        boat = sdk.first_autopilot(240.0)
        assert boat is not None
        direct, telemetry, action = MavlinkDirect(boat), Telemetry(boat), Action(boat)
        positions, armed, texts = Watch(), Watch(), Watch()
        telemetry.subscribe_position(positions)
        telemetry.subscribe_armed(armed)
        direct.subscribe_message("STATUSTEXT", lambda m, ud: texts(json.loads(m.fields_json)["text"]))
        assert positions.wait(lambda p: True, 60) is not None
        action.arm()
        lat, lon = GEO.sea_level_to_geodetic(*target)
        action.goto_location(lat, lon, 0.0, float("nan"))
        there = positions.wait(lambda p: math.dist(_ned(p), target) <= 1.0, 240)
        assert there is not None, _ned(positions.last())
        with pytest.raises(ActionError):
            action.disarm()
        assert texts.wait(lambda t: "disarm refused" in t, 10) is not None, texts.values
        assert armed.last() is True and proc.poll() is None
        seen = len(armed.values)
        action.kill()
        assert armed.wait(lambda a: len(armed.values) > seen and armed.last() is False, 10) is not None
        assert armed.last() is False
    finally:
        sdk.destroy()
        if proc is not None:
            stop_run(proc)
