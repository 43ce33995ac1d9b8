"""Ship traffic in the simulator, AIS_VESSEL on the HIL link, and the per-MMSI tracker."""

from __future__ import annotations

import math

import numpy as np
import pytest

from autopilot_bridge.ais_tracking import AisReport, AisTracker, TrackerParams
from autopilot_bridge.hil_link import HilLink
from common.geodesy import LocalFrame
from common.mavlink import Codec
from common.udp import UdpEndpoint
from hil import settings
from hil.assembly.simulator import simulator_settings
from simulator.core import SimulatorCore
from simulator.traffic import KNOT, AisParams, Ship, ShipSpec, report_interval

GEO = LocalFrame(38.92, 121.65, 0.0)


def ship(**kw) -> ShipSpec:
    base = dict(mmsi=412000001, start=(0.0, 100.0), speed=2.0, course=180.0)
    base.update(kw)
    return ShipSpec(**base)


def test_constant_velocity_and_waypoint_ships_in_ned():
    s = Ship(ship())                           # map (x east 0, y north 100), heading south at 2 m/s
    st = s.state(10.0)
    assert (st.north, st.east, math.degrees(st.course), st.speed) == pytest.approx((80.0, 0.0, 180.0, 2.0))
    # Waypoints with a speed change: 40 m north at 2 m/s (20 s), then 30 m east at 1 m/s.
    w = Ship(ship(start=(0.0, 0.0), waypoints=((0.0, 40.0), (30.0, 40.0)), speeds=(2.0, 1.0)))
    assert (w.state(10.0).north, w.state(10.0).east) == pytest.approx((20.0, 0.0))
    st = w.state(30.0)
    assert (st.north, st.east, st.speed, math.degrees(st.course)) == pytest.approx((40.0, 10.0, 1.0, 90.0))
    assert w.state(21.0).turning and not w.state(40.0).turning
    assert (w.state(60.0).north, w.state(60.0).east) == pytest.approx((40.0, 40.0))  # keeps going after the last


def test_class_a_reporting_intervals():
    p = AisParams()
    assert report_interval(5 * KNOT, False, p) == 10.0
    assert report_interval(5 * KNOT, True, p) == 3.33
    assert report_interval(15 * KNOT, False, p) == 6.0
    assert report_interval(30 * KNOT, False, p) == 2.0


def _core(*ships: ShipSpec, overrides=()):
    cfg = settings.load(None, ["sensors.gps.glitch_probability=0.0", *overrides])
    return SimulatorCore(simulator_settings(cfg), traffic=ships), cfg


def _link(cfg) -> HilLink:
    return HilLink.open("127.0.0.1:0", ("127.0.0.1:9",), GEO, truth_component_id=cfg.traffic.truth_component_id)


def test_ais_reports_reach_the_link_over_udp_noisy_at_class_a_rates_truth_dropped():
    core, cfg = _core(ship(), ship(mmsi=412000002, start=(50.0, 0.0), speed=8.0, course=270.0))
    link = _link(cfg)
    tx = UdpEndpoint("127.0.0.1:0", [f"127.0.0.1:{link.address[1]}"])
    try:
        reports = []
        for _ in range(int(31.0 / core.frame_dt)):
            tx.send(core.frame())
            for _frame in link.receive(timeout=2.0):
                pass
            reports += link.take_ais()
            core.step()
        by = {m: [r for r in reports if r.mmsi == m] for m in (412000001, 412000002)}
        # 31 s: the 2 m/s ship (3.9 kn) every 10 s -> 3-4 reports; 8 m/s (15.6 kn) every 6 s -> 5-6.
        assert 3 <= len(by[412000001]) <= 4 and 5 <= len(by[412000002]) <= 6
        gaps = np.diff([r.t for r in by[412000002]])
        assert gaps == pytest.approx(6.0, abs=0.011)
        for r in by[412000001]:
            n, e = GEO.geodetic_to_sea_level(r.lat, r.lon)
            assert math.hypot(n - (100.0 - 2.0 * r.t), e) < 4 * 2.0 * math.sqrt(2)   # pos_std 2 m per axis
            assert r.speed == pytest.approx(2.0, abs=0.3) and math.degrees(r.course) == pytest.approx(180.0, abs=5)
            assert (r.bow, r.stern, r.port, r.starboard) == (4.0, 4.0, 2.0, 2.0)
        assert link.truth_ignored > 1000  # HIL_STATE_QUATERNION + 2 truth AIS_VESSEL at 50 Hz
        assert not link.rejects
        assert core.messages_sent["AIS_VESSEL"] == len(reports)
    finally:
        link.close()
        tx.close()


def test_same_seed_same_reports_and_loss_is_counted():
    def run(seed, loss):
        core, _ = _core(ship(), overrides=[f"sim.seed={seed}", f"traffic.loss={loss}"])
        out = []
        for _ in range(int(120.0 / core.frame_dt)):
            out.append(core.frame())
            core.step()
        return b"".join(out), core.traffic
    a, ta = run(3, 0.0)
    b, _ = run(3, 0.0)
    c, tc = run(4, 0.0)
    assert a == b and a != c
    _, tl = run(3, 0.5)
    assert tl.reports_lost > 0 and tl.reports_lost + tl.reports_sent == ta.reports_sent


def _report(t, mmsi, north, east, course_deg=0.0, speed=2.0, **kw) -> AisReport:
    lat, lon = GEO.sea_level_to_geodetic(north, east)
    d = dict(lat=lat, lon=lon)
    d.update(kw)
    return AisReport(t, mmsi, d["lat"], d["lon"], None if course_deg is None else math.radians(course_deg), speed,
                     4.0, 4.0, 1.5, 1.5)


def test_tracker_predicts_between_reports_and_forgets():
    p = TrackerParams()
    tr = AisTracker(p, GEO)
    rng = np.random.default_rng(0)
    for k in range(6):                      # every 10 s, target at 1.5 m/s course 90 (east), noise 2 m
        t = 10.0 * k
        assert tr.update(_report(t, 412000001, 20.0 + rng.normal(0, 2), 1.5 * t + rng.normal(0, 2), 90.0, 1.5))
    (tg,) = tr.targets(55.0)
    assert math.hypot(tg.north - 20.0, tg.east - 1.5 * 55.0) < 3.0
    assert (tg.vn, tg.ve) == pytest.approx((0.0, 1.5), abs=0.2)
    assert tg.hull_radius == pytest.approx(math.hypot(4.0, 1.5))
    # A single report is tentative (confirm_reports = 2): not a target yet.
    tr.update(_report(50.0, 412000002, 0.0, 0.0))
    assert [t.mmsi for t in tr.targets(50.0)] == [412000001]
    assert tr.forget(50.0 + p.forget_after + 1.0) == 2 and not tr.tracks


@pytest.mark.parametrize("kw, reason", [
    (dict(lat=91.0), "bad_position"),
    (dict(lon=181.0), "bad_position"),
    (dict(speed=500 * KNOT), "impossible_speed"),
    (dict(mmsi=12345), "bad_mmsi"),
])
def test_impossible_reports_are_rejected_and_counted(kw, reason):
    tr = AisTracker(TrackerParams(), GEO)
    mmsi = kw.pop("mmsi", 412000001)
    r = _report(0.0, mmsi, 10.0, 10.0, **{k: v for k, v in kw.items() if k in ("lat", "lon")})
    if "speed" in kw:
        r = _report(0.0, mmsi, 10.0, 10.0, speed=kw["speed"])
    assert not tr.update(r)
    assert tr.rejected == {reason: 1} and not tr.tracks


def test_impossible_ais_over_the_wire_and_an_mmsi_flood():
    """Real AIS_VESSEL bytes on the link: lat 91 deg, 500 kn, a jump, a flood of unknown MMSIs."""
    cfg = settings.load(None, [])
    link = _link(cfg)
    codec = Codec(1, 51)
    tr = AisTracker(TrackerParams(max_targets=8), GEO)
    lat0, lon0 = GEO.sea_level_to_geodetic(50.0, 0.0)

    def ais(mmsi, lat=lat0, lon=lon0, cog=18000, sog=200):
        return codec.encode("ais_vessel", mmsi, int(lat * 1e7), int(lon * 1e7), cog, cog, sog, 0, 0, 70, 4, 4, 2, 2,
                            b"", b"", 0, 0)

    try:
        good = 412000001
        for d in [ais(good), ais(good, lat=91.0), ais(good, sog=int(500 * KNOT * 100)),
                  ais(good, lat=lat0 + 0.01)] + [ais(500000000 + i) for i in range(40)] + [ais(good)]:
            link.decode(d)
        for r in link.take_ais():
            tr.update(r)
        assert tr.rejected["bad_position"] == 1 and tr.rejected["impossible_speed"] == 1
        assert tr.rejected["implausible_jump"] == 1          # 1.1 km in no time
        assert tr.rejected["track_table_full"] == 40 - 7     # 8 tracks: the real one and 7 of the flood
        assert good in tr.tracks and tr.tracks[good].reports == 2
        assert [t.mmsi for t in tr.targets(0.0)] == [good]   # the flood's single reports stay tentative
    finally:
        link.close()
