"""Missions through the chart over real UDP (issue 12): bad items refused whole, long legs sailed.

A live `hil run --wait-for-arm` (lockstep, real processes) on a chart the repository does not
hold: a wall from the south edge and a walled pond. A pymavlink ground station uploads missions:
an item inside the wall, one in the pond (not reachable by water) and one off the chart are
refused with their MAV_MISSION_RESULT and a STATUSTEXT naming the item, and the mission on board
stays as it was. Then a one-waypoint mission 80 m away, behind the wall, is flown to the end.
"""

from __future__ import annotations

import math

import pytest
from support.gcs_client import Gcs, M, start_run, stop_run
from test_sparse_routes import pond_scenario

from common.geodesy import LocalFrame
from hil.hilrun import free_udp_port

GEO = LocalFrame(38.92, 121.65, 0.0)  # [geodesy] of configs/default.toml


def _item(x: float, y: float, radius: float = 3.0) -> tuple:
    lat, lon = GEO.sea_level_to_geodetic(y, x)
    return (M.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT, M.MAV_CMD_NAV_WAYPOINT, 0.0, radius, 0.0, float("nan"),
            int(round(lat * 1e7)), int(round(lon * 1e7)), 0.0)


def _refused(gcs: Gcs, items: list[tuple], code: int, seq: int, words: str) -> None:
    ack = gcs.upload(items)
    assert ack is not None and ack.type == code, ack
    text = gcs.recv("STATUSTEXT", 10, lambda m: "rejected" in m.text)
    assert text is not None, "no STATUSTEXT for the refused item"
    assert f"mission item {seq} rejected" in text.text and words in text.text, text.text


@pytest.mark.slow
def test_bad_items_are_refused_and_a_long_leg_round_the_wall_is_sailed(tmp_path):
    scen = pond_scenario(tmp_path, [], goal=(10.0, 70.0))
    port = free_udp_port()
    proc = start_run(tmp_path / "run", "--scenario", str(scen), "--lockstep", "--duration", "600", "--wait-for-arm",
                     "--gcs", f"udpin:127.0.0.1:{port}")
    gcs = Gcs(f"udpout:127.0.0.1:{port}")
    try:
        assert gcs.connect() is not None, "no HEARTBEAT from the boat"
        assert gcs.recv("GLOBAL_POSITION_INT", 60) is not None       # a navigation fix: arming needs one
        good = [_item(30.0, 20.0), _item(90.0, 20.0)]        # the second leg crosses the wall: routed round it
        ack = gcs.upload(good)
        assert ack is not None and ack.type == M.MAV_MISSION_ACCEPTED, ack

        _refused(gcs, [_item(30.0, 20.0), _item(51.0, 30.0), _item(90.0, 20.0)], M.MAV_MISSION_INVALID, 1,
                 "in obstacle or 2 m margin")
        _refused(gcs, [_item(30.0, 20.0), _item(90.0, 20.0), _item(80.0, 60.0)], M.MAV_MISSION_INVALID, 2,
                 "unreachable by water")
        _refused(gcs, [_item(30.0, 20.0), _item(30.0, 95.0)], M.MAV_MISSION_INVALID_PARAM5_X, 1, "95 m north")
        got = gcs.download()
        assert got is not None and [(g.x, g.y) for g in got] == [(i[6], i[7]) for i in good]   # nothing changed

        # One waypoint 80 m east, behind the wall: the leg is routed round the wall's end and sailed.
        target = _item(90.0, 20.0)
        ack = gcs.upload([target])
        assert ack is not None and ack.type == M.MAV_MISSION_ACCEPTED, ack
        assert gcs.arm().result == M.MAV_RESULT_ACCEPTED
        assert gcs.set_mode(10).result == M.MAV_RESULT_ACCEPTED          # AUTO
        reached = gcs.recv("MISSION_ITEM_REACHED", 900, lambda m: m.seq == 0)
        assert reached is not None, "the waypoint behind the wall was never reached"
        pos = gcs.recv("GLOBAL_POSITION_INT", 10)
        north, east = GEO.geodetic_to_sea_level(pos.lat * 1e-7, pos.lon * 1e-7)
        assert math.hypot(east - 90.0, north - 20.0) < 6.0
    finally:
        gcs.close()
        out, err = stop_run(proc)
    assert "Traceback" not in err, err[-3000:]
