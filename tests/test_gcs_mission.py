"""The mission microservice state machine (pure) and the vehicle's modes and mission progress."""

from __future__ import annotations

import math

import pytest

from autopilot_bridge.gcs.mission import MissionServer, same_items
from autopilot_bridge.vehicle import Mode, Vehicle, Waypoint
from common.mavlink import MAV_TYPE as M
from common.mavlink import mavlink2

GCS, OTHER = (255, 190), (254, 1)
LAT, LON = 389200000, 1216500000


def msg(name: str, *args, src=GCS):
    """A real pymavlink message as the boat receives it (packed and parsed, with the sender's header)."""
    mav = mavlink2.MAVLink(None, *src)
    buf = getattr(mav, f"{name}_encode")(*args).pack(mav)
    return mavlink2.MAVLink(None, 1, 1).decode(bytearray(buf))


def item(seq: int, *, frame=M.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT, command=M.MAV_CMD_NAV_WAYPOINT, lat=None, lon=None,
         radius=2.0, src=GCS):
    return msg("mission_item_int", 1, 1, seq, frame, command, 0, 1, 0.0, radius, 0.0, math.nan,
               LAT + 1000 * seq if lat is None else lat, LON + 1000 * seq if lon is None else lon, 0.0, 0, src=src)


def upload(ms: MissionServer, n: int, now: float = 0.0, src=GCS):
    outs = ms.handle(msg("mission_count", 1, 1, n, 0, src=src), now)
    for seq in range(n):
        assert outs[-1].name == "mission_request_int" and outs[-1].args[:3] == (src[0], src[1], seq)
        outs = ms.handle(item(seq, src=src), now)
    return outs


def test_upload_then_download_returns_the_same_items_addressed_to_the_gcs():
    ms = MissionServer()
    outs = upload(ms, 6)
    assert [o.name for o in outs] == ["mission_ack"] and outs[0].args == (255, 190, M.MAV_MISSION_ACCEPTED, 0)
    assert [e.kind for e in ms.take_events()] == ["replaced"]
    (count,) = ms.handle(msg("mission_request_list", 1, 1, 0), 1.0)
    assert count.name == "mission_count" and count.args[2] == 6
    for seq in range(6):
        (o,) = ms.handle(msg("mission_request_int", 1, 1, seq, 0), 1.0)
        assert o.name == "mission_item_int" and o.args[2] == seq and o.args[11:13] == (LAT + 1000 * seq,
                                                                                       LON + 1000 * seq)
        assert math.isnan(o.args[10]) and o.args[8] == 2.0


def test_legacy_mission_item_is_accepted_and_mission_request_answered_with_mission_item():
    ms = MissionServer()
    ms.handle(msg("mission_count", 1, 1, 2, 0), 0.0)
    outs = ms.handle(msg("mission_item", 1, 1, 0, M.MAV_FRAME_GLOBAL_RELATIVE_ALT, M.MAV_CMD_NAV_WAYPOINT, 0, 1,
                         0.0, 0.0, 0.0, 0.0, 38.92, 121.65, 0.0), 0.0)
    assert outs[0].name == "mission_request"  # it spoke legacy: asked in legacy from now on
    ms.handle(msg("mission_item", 1, 1, 1, M.MAV_FRAME_GLOBAL_RELATIVE_ALT, M.MAV_CMD_NAV_WAYPOINT, 0, 1,
                  0.0, 0.0, 0.0, 0.0, 38.921, 121.651, 0.0), 0.0)
    # float32 degrees: ~0.4 m steps at this latitude (why MISSION_ITEM is deprecated)
    assert len(ms.items) == 2 and abs(ms.items[1].x - 389210000) <= 40
    (o,) = ms.handle(msg("mission_request", 1, 1, 1, 0), 0.0)
    assert o.name == "mission_item" and abs(o.args[11] - 38.921) < 4e-6


def test_out_of_sequence_item_is_re_requested_and_beyond_count_is_invalid_sequence():
    ms = MissionServer()
    upload(ms, 2)
    old = ms.items
    ms.handle(msg("mission_count", 1, 1, 3, 0), 0.0)
    (o,) = ms.handle(item(1), 0.0)  # expected 0
    assert o.name == "mission_request_int" and o.args[2] == 0
    (o,) = ms.handle(item(5), 0.0)
    assert o.name == "mission_ack" and o.args[2] == M.MAV_MISSION_INVALID_SEQUENCE
    assert ms.items == old and ms.upload is None


@pytest.mark.parametrize("kwargs, code", [
    ({"frame": M.MAV_FRAME_LOCAL_NED}, M.MAV_MISSION_UNSUPPORTED_FRAME),
    ({"command": M.MAV_CMD_NAV_LAND}, M.MAV_MISSION_UNSUPPORTED),
    ({"lat": 950000000}, M.MAV_MISSION_INVALID_PARAM5_X),
    ({"lon": -1850000000}, M.MAV_MISSION_INVALID_PARAM6_Y),
    ({"radius": -1.0}, M.MAV_MISSION_INVALID_PARAM2),
    ({"radius": math.inf}, M.MAV_MISSION_INVALID_PARAM2),
])
def test_a_bad_item_is_refused_with_its_code_and_the_old_mission_stays(kwargs, code):
    ms = MissionServer()
    upload(ms, 3)
    old = ms.items
    ms.take_events()
    ms.handle(msg("mission_count", 1, 1, 2, 0), 0.0)
    ms.handle(item(0), 0.0)
    (o,) = ms.handle(item(1, **kwargs), 0.0)
    assert o.name == "mission_ack" and o.args[2] == code
    assert ms.items is old and [e.kind for e in ms.take_events()] == ["rejected"]


def test_off_chart_items_are_refused_by_the_position_check():
    ms = MissionServer(position_check=lambda lat, lon: (M.MAV_MISSION_INVALID_PARAM5_X, "off") if lat > 38.93 else None)
    ms.handle(msg("mission_count", 1, 1, 1, 0), 0.0)
    (o,) = ms.handle(item(0, lat=389400000), 0.0)
    assert o.args[2] == M.MAV_MISSION_INVALID_PARAM5_X and ms.items == ()


def test_timeout_re_requests_then_cancels_keeping_the_old_mission():
    ms = MissionServer(item_timeout=0.25, retries=5)
    upload(ms, 2)
    old = ms.items
    ms.handle(msg("mission_count", 1, 1, 3, 0), 10.0)
    ms.handle(item(0), 10.0)
    assert ms.tick(10.2) == []
    re = []
    t = 10.0
    for _ in range(20):
        t += 0.26
        re += ms.tick(t)
        if re and re[-1].name == "mission_ack":
            break
    assert [o.name for o in re] == ["mission_request_int"] * 5 + ["mission_ack"]
    assert all(o.args[2] == 1 for o in re[:5]) and re[-1].args[2] == M.MAV_MISSION_OPERATION_CANCELLED
    assert ms.items is old and ms.stats["upload_timeouts"] == 1


def test_count_limits_busy_clear_and_plan_types():
    ms = MissionServer(max_items=10)
    (o,) = ms.handle(msg("mission_count", 1, 1, 11, 0), 0.0)
    assert o.args[2] == M.MAV_MISSION_NO_SPACE
    ms.handle(msg("mission_count", 1, 1, 2, 0), 0.0)
    (o,) = ms.handle(msg("mission_count", 1, 1, 2, 0, src=OTHER), 0.0)
    assert o.args[:3] == (254, 1, M.MAV_MISSION_DENIED)  # one upload at a time
    ms.handle(item(0), 0.0)
    ms.handle(item(1), 0.0)
    assert len(ms.items) == 2
    (o,) = ms.handle(msg("mission_count", 1, 1, 3, 7), 0.0)            # no such plan type
    assert o.args[2:] == (M.MAV_MISSION_UNSUPPORTED, 7)
    # The refused GCS (OTHER) has the next turn for 5 s (gcs/upload_claim.py): later, a fence upload begins.
    (o,) = ms.handle(msg("mission_count", 1, 1, 3, M.MAV_MISSION_TYPE_FENCE), 6.0)
    assert o.name == "mission_request_int" and o.args[2:] == (0, M.MAV_MISSION_TYPE_FENCE)
    (o,) = ms.handle(msg("mission_request_list", 1, 1, M.MAV_MISSION_TYPE_RALLY), 6.0)
    assert o.name == "mission_count" and o.args[2:] == (0, M.MAV_MISSION_TYPE_RALLY)
    (o,) = ms.handle(msg("mission_clear_all", 1, 1, 0), 6.0)
    assert o.args[2] == M.MAV_MISSION_ACCEPTED and ms.items == ()
    assert ms.handle(msg("mission_count", 1, 1, 2, 0, src=OTHER), 6.0)[0].name == "mission_request_int"
    assert ms.handle(msg("mission_count", 1, 1, 0, 0, src=OTHER), 6.0)[0].args[2] == M.MAV_MISSION_ACCEPTED


def test_messages_for_another_vehicle_are_ignored_and_a_lost_final_ack_is_repeated():
    ms = MissionServer()
    assert ms.handle(msg("mission_count", 7, 1, 2, 0), 0.0) == []
    upload(ms, 2, now=1.0)
    (o,) = ms.handle(item(1), 2.0)  # the GCS did not get our ACK and sends its last item again
    assert o.args[2] == M.MAV_MISSION_ACCEPTED and len(ms.items) == 2
    (o,) = ms.handle(item(0), 2.0)
    assert o.args[2] == M.MAV_MISSION_INVALID_SEQUENCE
    assert same_items(ms.items[0], ms.items[0])


def _vehicle(**kw) -> Vehicle:
    wps = [Waypoint(0.0, 10.0 * i, 2.0) for i in range(1, 5)]
    return Vehicle(wps, armed=kw.get("armed", False), mode=kw.get("mode", Mode.HOLD))


def test_vehicle_modes_need_what_they_need_and_disarmed_means_no_thrust():
    v = _vehicle()
    assert not v.wants_thrust()
    assert v.set_mode(Mode.AUTO, None)[0] is False          # no position yet
    v.update(0.0, 0.0)                                       # home from the first fix
    assert v.set_mode(Mode.AUTO, (0.0, 0.0))[0] and not v.wants_thrust()  # still disarmed
    v.arm(True)
    assert v.wants_thrust() and v.route.path.tolist()[0] == [0.0, 0.0] and len(v.route.path) == 5
    assert v.set_mode(Mode.HOLD, (0.0, 0.0))[0] and not v.wants_thrust()
    assert v.set_mode(Mode.RTL, (0.0, 30.0))[0] and v.route.path.tolist() == [[0.0, 30.0], [0.0, 0.0]]
    assert v.set_mode(Mode.GUIDED, (0.0, 30.0))[0] and v.wants_thrust() and v.route.loiter  # no target: station
    assert v.reposition((5.0, 5.0), (0.0, 30.0))[0] and v.wants_thrust()
    empty = Vehicle([], armed=True, mode=Mode.HOLD)
    assert empty.set_mode(Mode.AUTO, (0.0, 0.0)) == (False, "AUTO: no mission")


def test_mission_progress_by_radius_or_passing_and_a_new_mission_restarts():
    v = _vehicle(armed=True)
    v.update(0.0, 0.0)
    v.set_mode(Mode.AUTO, (0.0, 0.0))
    v.update(0.0, 9.0)                        # within 2 m of item 0
    assert v.take_reached() == [0] and v.current == 1
    v.update(5.0, 21.0)                       # 5 m off item 1 but past the line through it
    assert v.take_reached() == [1] and v.current == 2
    v.update(3.0, 41.0)                       # the last item needs its radius, passing is not enough
    assert v.take_reached() == [2] and v.current == 3 and not v.complete
    v.update(0.0, 41.0)
    assert v.take_reached() == [3] and v.complete
    version = v.route.version
    v.replace_mission([Waypoint(20.0, 0.0, 3.0)], (0.0, 41.0))
    assert v.current == 0 and v.route.version == version + 1 and v.route.path.tolist() == [[0.0, 41.0], [20.0, 0.0]]
    assert not v.complete


# -- geofence and rally plans (issue 33) ---------------------------------------------------------------
FENCE, RALLY = M.MAV_MISSION_TYPE_FENCE, M.MAV_MISSION_TYPE_RALLY
INC, EXC = M.MAV_CMD_NAV_FENCE_POLYGON_VERTEX_INCLUSION, M.MAV_CMD_NAV_FENCE_POLYGON_VERTEX_EXCLUSION
CIRCLE_EXC = M.MAV_CMD_NAV_FENCE_CIRCLE_EXCLUSION


def plan_item(seq: int, command: int, p1: float, lat: int, lon: int, mtype: int, src=GCS):
    return msg("mission_item_int", 1, 1, seq, M.MAV_FRAME_GLOBAL, command, 0, 1, p1, 0.0, 0.0, 0.0, lat, lon, 0.0,
               mtype, src=src)


def upload_plan(ms: MissionServer, items: list[tuple[int, float, int, int]], mtype: int):
    outs = ms.handle(msg("mission_count", 1, 1, len(items), mtype), 0.0)
    for seq, (command, p1, lat, lon) in enumerate(items):
        if outs[-1].name == "mission_ack":      # refused before the end
            return outs
        assert outs[-1].name == "mission_request_int" and outs[-1].args[2:] == (seq, mtype), outs
        outs = ms.handle(plan_item(seq, command, p1, lat, lon, mtype), 0.0)
    return outs


SQUARE = [(INC, 4, LAT, LON), (INC, 4, LAT + 2000, LON), (INC, 4, LAT + 2000, LON + 2000), (INC, 4, LAT, LON + 2000)]


def test_fence_and_rally_plans_are_stored_read_back_exactly_and_cleared_apart_from_the_mission():
    ms = MissionServer()
    upload(ms, 2)
    fence = [*SQUARE, (CIRCLE_EXC, 5.0, LAT + 1000, LON + 1000)]
    (ack,) = upload_plan(ms, fence, FENCE)
    assert ack.name == "mission_ack" and ack.args[2:] == (M.MAV_MISSION_ACCEPTED, FENCE)
    (ack,) = upload_plan(ms, [(M.MAV_CMD_NAV_RALLY_POINT, 0.0, LAT + 500, LON + 500)], RALLY)
    assert ack.args[2:] == (M.MAV_MISSION_ACCEPTED, RALLY)
    assert [e.mission_type for e in ms.take_events()] == [0, FENCE, RALLY]
    (c,) = ms.handle(msg("mission_request_list", 1, 1, FENCE), 0.0)
    assert c.args[2:] == (5, FENCE)
    for seq, (command, p1, lat, lon) in enumerate(fence):
        (it,) = ms.handle(msg("mission_request_int", 1, 1, seq, FENCE), 0.0)
        assert it.name == "mission_item_int" and it.args[4] == command and it.args[7] == p1
        assert it.args[11:13] == (lat, lon) and it.args[-1] == FENCE
    assert len(ms.items) == 2                                   # the mission untouched
    (ack,) = ms.handle(msg("mission_clear_all", 1, 1, FENCE), 0.0)
    assert ack.args[2:] == (M.MAV_MISSION_ACCEPTED, FENCE) and ms.plans[FENCE] == () and len(ms.plans[RALLY]) == 1
    ms.handle(msg("mission_clear_all", 1, 1, M.MAV_MISSION_TYPE_ALL), 0.0)
    assert ms.plans[RALLY] == () and ms.items == ()


def test_bad_fence_and_rally_items_are_refused_with_their_reason():
    ms = MissionServer()
    # A polygon announced with 4 vertices but given 3, then an exclusion vertex.
    (ack,) = upload_plan(ms, [*SQUARE[:3], (EXC, 4, LAT, LON)], FENCE)
    assert ack.args[2:] == (M.MAV_MISSION_INVALID_PARAM1, FENCE) and ms.plans[FENCE] == ()
    (ack,) = upload_plan(ms, [(INC, 2, LAT, LON), (INC, 2, LAT + 1, LON)], FENCE)      # 2 vertices
    assert ack.args[2] == M.MAV_MISSION_INVALID_PARAM1
    (ack,) = upload_plan(ms, [(CIRCLE_EXC, -1.0, LAT, LON)], FENCE)                   # negative radius
    assert ack.args[2] == M.MAV_MISSION_INVALID_PARAM1
    (ack,) = upload_plan(ms, [(M.MAV_CMD_NAV_WAYPOINT, 0.0, LAT, LON)], RALLY)        # not a rally point
    assert ack.args[2] == M.MAV_MISSION_UNSUPPORTED
    # The vehicle's own check (a rally point outside the fence, in an obstacle): its code and reason.
    ms = MissionServer(plan_checks={RALLY: lambda items: (0, M.MAV_MISSION_INVALID, "outside the geofence")})
    (ack,) = upload_plan(ms, [(M.MAV_CMD_NAV_RALLY_POINT, 0.0, LAT, LON)], RALLY)
    assert ack.args[2:] == (M.MAV_MISSION_INVALID, RALLY) and ms.last_reject == (0, "outside the geofence")
