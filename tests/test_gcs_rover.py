"""The boat as an ArduPilot Rover user meets it (issue 36), with third-party clients only.

A live `hil run --wait-for-arm` in its default identity (``[gcs] identity = "ardupilot"``) against MAVSDK
(4.x: the C++ MAVSDK in-process) and pymavlink:

* identity: MAVSDK sees an ArduPilot autopilot, so its Action, MissionRaw and Telemetry plugins use Rover's
  modes (HOLD, AUTO, RTL, GUIDED) and ArduPilot's mission convention (item 0 is home);
* a QGroundControl ``.plan`` written here as QGC writes one, imported with
  ``MissionRaw.import_qgroundcontrol_mission`` (MAVSDK adds the planned home as item 0 for ArduPilot), uploaded
  and flown: DO_CHANGE_SPEED as the first item and again after a waypoint, waypoints passed item by item
  (MISSION_CURRENT and MISSION_ITEM_REACHED, each item once, in mission order), pause and resume, RTL;
* GUIDED (``Action.goto_location``), HOLD and RTL through Action; a target inside the breakwater refused.

Every wait is bounded and waits on a condition. Skipped, with the reason, where mavsdk cannot be imported.
"""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest
from support.gcs_client import HOME_MAP, Gcs, start_run, stop_run
from support.watch import Watch

from common.geodesy import LocalFrame
from common.mavlink import MAV_TYPE as M
from hil.hilrun import free_udp_port

try:
    from mavsdk import Autopilot, ComponentType, Configuration, ConnectionResult, Mavsdk
    from mavsdk.plugins.action import Action, ActionError
    from mavsdk.plugins.mavlink_direct import MavlinkDirect
    from mavsdk.plugins.mission_raw import MissionRaw
    from mavsdk.plugins.telemetry import FlightMode, Telemetry
except (ImportError, OSError) as exc:  # OSError: the bundled libcmavsdk.so does not load on this machine
    pytest.skip(f"mavsdk is not importable (pip install mavsdk): {exc}", allow_module_level=True)

GEO = LocalFrame(38.92, 121.65, 0.0)  # [geodesy] of configs/default.toml
REPO = Path(__file__).resolve().parents[1]
ROVER_HOLD, ROVER_AUTO, ROVER_RTL, ROVER_GUIDED = 4, 10, 11, 15
# Open water north-east of the harbour's start (map x east, y north, m): legs of 10-12 m.
A, B, C = (28.0, 50.0), (30.0, 60.0), (26.0, 68.0)
SPEED_1, SPEED_2 = 1.0, 0.6       # m/s: the plan's first and second DO_CHANGE_SPEED


def _latlon(p: tuple[float, float]) -> tuple[float, float]:
    return GEO.sea_level_to_geodetic(p[1], p[0])


def qgc_plan(path: Path) -> None:
    """A QGroundControl 4.x .plan: DO_CHANGE_SPEED 1.0, A, B, DO_CHANGE_SPEED 0.6, C, RTL (SimpleItems)."""
    def item(seq: int, cmd: int, params: list[float], frame: int = M.MAV_FRAME_GLOBAL_RELATIVE_ALT) -> dict:
        return {"AMSLAltAboveTerrain": None, "Altitude": 0, "AltitudeMode": 1, "autoContinue": True,
                "command": cmd, "doJumpId": seq, "frame": frame, "params": params, "type": "SimpleItem"}

    def wp(seq: int, p: tuple[float, float]) -> dict:
        lat, lon = _latlon(p)
        return item(seq, M.MAV_CMD_NAV_WAYPOINT, [0, 0, 0, None, lat, lon, 0])

    speed = M.MAV_CMD_DO_CHANGE_SPEED
    items = [item(1, speed, [1, SPEED_1, -1, 0, 0, 0, 0], M.MAV_FRAME_MISSION), wp(2, A), wp(3, B),
             item(4, speed, [1, SPEED_2, -1, 0, 0, 0, 0], M.MAV_FRAME_MISSION), wp(5, C),
             item(6, M.MAV_CMD_NAV_RETURN_TO_LAUNCH, [0, 0, 0, 0, 0, 0, 0], M.MAV_FRAME_MISSION)]
    home = _latlon(HOME_MAP)
    plan = {"fileType": "Plan", "groundStation": "QGroundControl", "version": 1,
            "geoFence": {"circles": [], "polygons": [], "version": 2},
            "rallyPoints": {"points": [], "version": 2},
            "mission": {"cruiseSpeed": 1.5, "firmwareType": 3, "globalPlanAltitudeMode": 1, "hoverSpeed": 1.5,
                        "items": items, "plannedHomePosition": [home[0], home[1], 0], "vehicleType": 10,
                        "version": 2}}
    path.write_text(json.dumps(plan, indent=4))


def _deep_in_obstacle() -> tuple[float, float]:
    """A point (map x east, y north, m) of the harbour chart at least 4 m inside an obstacle."""
    from scipy.ndimage import distance_transform_edt

    occ = np.load(REPO / "configs" / "maps" / "harbour.npy")
    depth = distance_transform_edt(occ) * 0.5
    row, col = np.argwhere(depth >= 4.0)[0]
    return (col + 0.5) * 0.5, (row + 0.5) * 0.5


def test_mavsdk_flies_a_qgc_plan_as_ardurover_with_modes_progress_and_guarded_targets(tmp_path):
    port = free_udp_port()
    sdk = Mavsdk(Configuration.create_with_component_type(ComponentType.GROUND_STATION))
    out = tmp_path / "run"
    proc = None
    try:
        assert sdk.add_any_connection(f"udpin://127.0.0.1:{port}") == ConnectionResult.SUCCESS
        proc = start_run(out, "--scenario", "harbour", "--duration", "5000", "--wait-for-arm", "--speedup", "6",
                         "--gcs", f"udpout:127.0.0.1:{port}", identity="ardupilot")
        boat = sdk.first_autopilot(240.0)
        assert boat is not None, "MAVSDK discovered no autopilot"
        assert boat.autopilot_type() == Autopilot.ARDUPILOT
        direct, telemetry, mission, action = MavlinkDirect(boat), Telemetry(boat), MissionRaw(boat), Action(boat)
        modes, positions, current, reached, heartbeats = Watch(), Watch(), Watch(), Watch(), Watch()
        telemetry.subscribe_flight_mode(modes)
        telemetry.subscribe_position(positions)
        direct.subscribe_message("MISSION_CURRENT", lambda m, ud: current(json.loads(m.fields_json)["seq"]))
        direct.subscribe_message("MISSION_ITEM_REACHED", lambda m, ud: reached(json.loads(m.fields_json)["seq"]))
        direct.subscribe_message("HEARTBEAT", lambda m, ud: heartbeats(json.loads(m.fields_json)))
        hb = heartbeats.wait(lambda h: True, 30)
        assert hb["autopilot"] == M.MAV_AUTOPILOT_ARDUPILOTMEGA and hb["type"] == M.MAV_TYPE_SURFACE_BOAT
        assert modes.wait(lambda m: m == FlightMode.HOLD, 30) is not None, modes.values

        # The QGC plan, imported by MAVSDK: item 0 is the planned home (ArduPilot's convention).
        plan_file = tmp_path / "harbour.plan"
        qgc_plan(plan_file)
        imported = mission.import_qgroundcontrol_mission(str(plan_file)).mission_items
        assert len(imported) == 7 and imported[0].command == M.MAV_CMD_NAV_WAYPOINT
        mission.upload_mission(imported)
        back = mission.download_mission()
        assert [(it.command, it.x, it.y, it.param2) for it in back[1:]] == \
            [(it.command, it.x, it.y, it.param2) for it in imported[1:]]

        assert positions.wait(lambda p: True, 60) is not None
        action.arm()
        mission.start_mission()                                   # MAVSDK: Rover AUTO
        assert modes.wait(lambda m: m == FlightMode.MISSION, 15) is not None, modes.values
        # Pause on the way to B, resume: the mission goes on from B.
        assert current.wait(lambda s: s == 3, 120) is not None, current.values
        mission.pause_mission()                                   # MAVSDK: Rover HOLD
        assert heartbeats.wait(lambda h: h["custom_mode"] == ROVER_HOLD, 15) is not None
        mission.start_mission()
        assert heartbeats.wait(lambda h: h["custom_mode"] == ROVER_AUTO, 15) is not None
        assert reached.wait(lambda s: s == 6, 300) is not None, reached.values   # RTL: home
        # Each item once, in mission order; MISSION_CURRENT went item by item through the waypoints.
        assert reached.values[:6] == [1, 2, 3, 4, 5, 6], reached.values
        seen = [s for i, s in enumerate(current.values) if i == 0 or s != current.values[i - 1]]
        assert {2, 3, 5, 6} <= set(seen) and seen == sorted(seen), seen

        # Action: HOLD, GUIDED to open water, a target in the breakwater refused, RTL.
        action.hold()
        assert heartbeats.wait(lambda h: h["custom_mode"] == ROVER_HOLD, 15) is not None
        lat, lon = _latlon(A)
        action.goto_location(lat, lon, 0.0, float("nan"))
        assert heartbeats.wait(lambda h: h["custom_mode"] == ROVER_GUIDED, 15) is not None
        rock = _latlon(_deep_in_obstacle())
        with pytest.raises(ActionError):
            action.goto_location(rock[0], rock[1], 0.0, float("nan"))
        action.return_to_launch()
        assert modes.wait(lambda m: m == FlightMode.RETURN_TO_LAUNCH, 15) is not None, modes.values
        assert proc.poll() is None
    finally:
        sdk.destroy()
        if proc is not None:
            stop_run(proc)

    # The run's own record (the tlog the tap wrote): the speeds the plan asked for, over ground.
    from pymavlink import mavutil

    log = mavutil.mavlink_connection(str(out / "run.tlog"), dialect="ardupilotmega")
    cur, speeds = None, {}
    while (m := log.recv_match()) is not None:
        if m.get_srcSystem() != 1:
            continue
        if m.get_type() == "MISSION_CURRENT":
            cur = m.seq
        elif m.get_type() == "VFR_HUD" and cur is not None:
            speeds.setdefault(cur, []).append(m.groundspeed)
    to_b = sorted(speeds.get(3, []))[len(speeds.get(3, [])) // 2:]   # settled part of the leg A -> B
    home = speeds.get(6, [])                                         # C -> home (RTL item): the second speed
    assert to_b and abs(np.median(to_b) - SPEED_1) <= 0.2, speeds.get(3)
    assert len(home) >= 8 and abs(np.median(home[len(home) // 2:]) - SPEED_2) <= 0.15, home


def test_pymavlink_guided_home_and_speed_targets_are_checked_like_mission_items(tmp_path):
    """DO_REPOSITION, SET_POSITION_TARGET_GLOBAL_INT, DO_SET_HOME and SET_HOME_POSITION into the breakwater
    are refused (COMMAND_ACK DENIED and a STATUSTEXT saying why); DO_CHANGE_SPEED -50 and inf likewise."""
    port = free_udp_port()
    proc = start_run(tmp_path / "run", "--scenario", "harbour", "--duration", "5000", "--wait-for-arm",
                     "--gcs", f"udpin:127.0.0.1:{port}", identity="ardupilot")
    gcs = Gcs(f"udpout:127.0.0.1:{port}")
    try:
        hb = gcs.connect()
        assert hb is not None and hb.autopilot == M.MAV_AUTOPILOT_ARDUPILOTMEGA
        assert gcs.recv("GLOBAL_POSITION_INT", 60) is not None
        rock = _latlon(_deep_in_obstacle())
        water = _latlon(A)
        lat_e7, lon_e7 = int(round(rock[0] * 1e7)), int(round(rock[1] * 1e7))
        ack = gcs.command(M.MAV_CMD_DO_REPOSITION, -1, 0, 0, float("nan"), rock[0], rock[1], 0)
        assert ack is not None and ack.result == M.MAV_RESULT_DENIED
        assert gcs.recv("STATUSTEXT", 5, lambda t: "GUIDED target" in t.text) is not None
        ack = gcs.command(M.MAV_CMD_DO_SET_HOME, 0, 0, 0, 0, rock[0], rock[1], 0)
        assert ack is not None and ack.result == M.MAV_RESULT_DENIED
        ack = gcs.command(M.MAV_CMD_DO_SET_HOME, 0, 0, 0, 0, water[0], water[1], 0)
        assert ack is not None and ack.result == M.MAV_RESULT_ACCEPTED
        for bad in (-50.0, float("inf")):
            ack = gcs.command(M.MAV_CMD_DO_CHANGE_SPEED, 1, bad, -1)
            assert ack is not None and ack.result == M.MAV_RESULT_DENIED, bad
        gcs.drain()
        gcs.mav.set_position_target_global_int_send(0, 1, 1, M.MAV_FRAME_GLOBAL_INT, 0b110111111000, lat_e7, lon_e7,
                                                    0, 0, 0, 0, 0, 0, 0, 0, 0)
        assert gcs.recv("STATUSTEXT", 5, lambda t: "GUIDED target" in t.text) is not None
        gcs.mav.set_home_position_send(1, lat_e7, lon_e7, 0, 0, 0, 0, [1, 0, 0, 0], 0, 0, 0)
        assert gcs.recv("STATUSTEXT", 5, lambda t: t.text.startswith("home:")) is not None
        home = gcs.recv("HOME_POSITION", 10)
        # COMMAND_LONG carries latitude as float32 (~0.4 m here): compare to that precision.
        assert home is not None and math.isclose(home.latitude * 1e-7, water[0], abs_tol=5e-6), home
        # The boat never left HOLD for any of them.
        hb = gcs.recv("HEARTBEAT", 5)
        assert hb is not None and hb.custom_mode == ROVER_HOLD
    finally:
        gcs.close()
        stop_run(proc)
