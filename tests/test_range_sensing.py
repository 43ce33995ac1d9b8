"""Obstacles the chart lacks: the simulator's range sensor (OBSTACLE_DISTANCE) and the autopilot's
sensed-obstacle map, through real MAVLink bytes, and the planner worker planning around them."""

from __future__ import annotations

import math

import numpy as np
import pytest

from autopilot_bridge.hil_link import HilLink
from autopilot_bridge.obstacle_map import SensedObstacles, arc_cells, path_blocked
from common.geodesy import LocalFrame
from common.mavlink import Codec
from hil.assembly.simulator import simulator_settings
from hil.settings import load
from simulator.core import Command, SimulatorCore
from simulator.rangefinder import Rangefinder, WorldMap

QUIET = ["waves.enabled=false", "current.enabled=false", "sensors.gps.glitch_probability=0.0"]
RES = 0.5


def wall_world(rows=200, cols=200, wall_north=20.0):
    """Open water with an east-west wall whose south face is at ``wall_north`` m."""
    occ = np.zeros((rows, cols), dtype=bool)
    occ[int(wall_north / RES):int(wall_north / RES) + 4, :] = True
    return occ


def quiet_rangefinder(occ, **kw):
    cfg = load(None, QUIET + [f"sensors.rangefinder.{k}={v}" for k, v in
                              {"range_std": 0.0, "miss_probability": 0.0, **kw}.items()])
    return Rangefinder(cfg.sensors.rangefinder, WorldMap(occ, RES), np.random.default_rng(0))


def test_ranges_match_hand_geometry_in_the_body_frame():
    rf = quiet_rangefinder(wall_world(), rays_per_sector=1)
    # 10 m south of the wall's face, heading north: the bow (sector 0) sees it at 10 m.
    d = rf.true_ranges(10.0, 50.0, 0.0)
    assert d[0] == pytest.approx(10.0, abs=RES / 2)
    # Sectors go clockwise from the bow: heading east, the wall is on the port beam (270 deg).
    d = rf.true_ranges(10.0, 50.0, math.pi / 2)
    k = round(270 / rf.increment_deg)
    assert d[k] == pytest.approx(10.0, abs=RES / 2)
    assert math.isinf(d[round(90 / rf.increment_deg)])   # open water to starboard: no return
    # 45 deg off the bow the wall is sqrt(2) x farther.
    d = rf.true_ranges(10.0, 50.0, 0.0)
    assert d[round(45 / rf.increment_deg)] == pytest.approx(10.0 * math.sqrt(2), abs=RES)


def test_a_sector_reports_its_nearest_ray_and_nothing_beyond_max_range():
    occ = np.zeros((200, 200), dtype=bool)
    occ[60:62, 100:102] = True               # a 1 m post at north 30 m, east 50 m
    rf = quiet_rangefinder(occ, rays_per_sector=5, max_range=40.0)
    d = rf.true_ranges(0.0, 50.0, 0.0)
    assert d[0] == pytest.approx(30.0, abs=RES / 2)
    assert np.isinf(d[1:]).all()
    far = quiet_rangefinder(occ, max_range=20.0)
    assert math.isinf(far.true_ranges(0.0, 50.0, 0.0)[0])
    scan = far.scan(0.0, 50.0, 0.0)
    assert len(scan) == 72 and scan[0] == far.max_cm + 1     # MAVLink: max_distance + 1 = no obstacle


def march_equals_numpy(rf, rng, poses, beyond):
    """Compare the compiled march with the numpy evaluation at ``poses`` random poses, up to
    ``beyond`` m outside the grid; returns how many sectors saw something."""
    rows, cols = rf.world.occ.shape
    returns = 0
    for _ in range(poses):
        n = rng.uniform(-beyond, rows * RES + beyond)
        e = rng.uniform(-beyond, cols * RES + beyond)
        psi = rng.uniform(-4.0, 4.0)
        got, want = rf.true_ranges(n, e, psi), rf.true_ranges_numpy(n, e, psi)
        assert np.array_equal(got, want), (n, e, psi)
        returns += int(np.isfinite(want).sum())
    return returns


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_compiled_ray_march_equals_the_numpy_evaluation_bit_for_bit(seed):
    """simulator/raycast.py (issue 17) against the numpy evaluation of every sample of every ray, on
    random clutter, at random poses inside, on the edge of and outside the grid."""
    rng = np.random.default_rng(seed)
    occ = rng.random((120, 160)) < 0.02 * (seed + 1)
    occ[rng.integers(0, 120, 5), :] = True                   # a few walls across the map
    rf = quiet_rangefinder(occ, rays_per_sector=int(rng.integers(1, 6)))
    returns = march_equals_numpy(rf, rng, poses=60, beyond=10.0)
    assert returns > 200  # sectors that saw something: the comparison is not between two empty scans


@pytest.mark.parametrize("seed", [3, 4, 5, 6])
def test_the_skipping_march_equals_the_numpy_evaluation_on_sparse_maps(seed):
    """The march skips the samples the map's clearance proves free and stops rays that left the grid
    for good (simulator/raycast.py): on sparse maps of blobs, posts and walls of random sizes, an
    empty map, and from poses outside the grid looking in, its returns are numpy's, bit for bit."""
    rng = np.random.default_rng(seed)
    rows, cols = int(rng.integers(40, 260)), int(rng.integers(40, 260))
    occ = np.zeros((rows, cols), dtype=bool)
    if seed != 6:                                            # seed 6: open water everywhere
        for _ in range(int(rng.integers(1, 12))):
            r, c = int(rng.integers(0, rows)), int(rng.integers(0, cols))
            h, w = int(rng.integers(1, 30)), int(rng.integers(1, 30))
            occ[r:r + h, c:c + w] = True
    rf = quiet_rangefinder(occ, rays_per_sector=int(rng.integers(1, 6)),
                           max_range=float(rng.choice([5.0, 25.0, 40.0, 80.0])))
    returns = march_equals_numpy(rf, rng, poses=80, beyond=30.0)
    assert (returns > 20) == (seed != 6)


def test_a_scan_is_its_true_ranges_plus_noise_rounded_clipped_and_missed_per_sector():
    """Rangefinder.scan against the rule written out sector by sector, with the same random draws:
    noise, half-to-even rounding to cm, clipping to [min, max] range, a miss or no return as
    max_distance + 1, and 72 entries with the unused ones UINT16_MAX."""
    rng = np.random.default_rng(7)
    occ = rng.random((100, 100)) < 0.03
    cfg = load(None, QUIET + ["sensors.rangefinder.range_std=0.8", "sensors.rangefinder.miss_probability=0.2",
                              "sensors.rangefinder.sectors=60", "sensors.rangefinder.min_range=0.5"])
    rf = Rangefinder(cfg.sensors.rangefinder, WorldMap(occ, RES), np.random.default_rng(11))
    draws = np.random.default_rng(11)
    for _ in range(40):
        n, e, psi = rng.uniform(0, 50), rng.uniform(0, 50), rng.uniform(-4, 4)
        true = rf.true_ranges(n, e, psi)
        noise, miss = draws.standard_normal(true.shape), draws.random(true.shape) < 0.2
        want = []
        for d, z, m in zip(true, noise, miss, strict=True):
            if m or not math.isfinite(d):
                want.append(rf.max_cm + 1)
            else:
                want.append(int(min(max(round((d + 0.8 * z) * 100.0), rf.min_cm), rf.max_cm)))
        got = rf.scan(n, e, psi)
        assert got == want + [65535] * 12 and all(type(v) is int for v in got)


def test_simulator_sends_obstacle_distance_at_its_rate_only_with_a_world():
    cfg = load(None, QUIET + ["sim.initial.x=10.0", "sim.initial.y=50.0"])
    dec = Codec(255, 0, accept=("HIL_SENSOR", "HIL_GPS", "HIL_STATE_QUATERNION", "OBSTACLE_DISTANCE", "BATTERY_STATUS"))
    for world, expected in ((WorldMap(wall_world(), RES), 5), (None, 0)):
        core = SimulatorCore(simulator_settings(cfg), world)
        scans = []
        for _ in range(100):                 # 1 s of IMU frames
            msgs, rejects = dec.decode(core.frame())
            assert not rejects
            scans += [m for m in msgs if m.get_type() == "OBSTACLE_DISTANCE"]
            core.apply(Command(core.time_usec, 0.0, 0.0))
            core.step()
        assert len(scans) == expected
        for m in scans:
            assert m.increment_f == pytest.approx(5.0) and m.max_distance == 4000
            assert abs(m.distances[0] - 1000) <= 30     # the wall 10 m ahead, in cm


def test_chart_explains_returns_from_charted_obstacles():
    occ = wall_world()
    sensed = SensedObstacles(occ, RES, confirm_hits=2, explain_radius=1.0)
    rf = Rangefinder(load(None, QUIET).sensors.rangefinder, WorldMap(occ, RES), np.random.default_rng(3))
    width = math.radians(rf.increment_deg)
    for i in range(20):
        d = np.array(rf.scan(10.0 + 0.1 * i, 50.0, 0.3 * i), dtype=float)
        valid = d <= rf.max_cm
        bearings = np.deg2rad(np.arange(72) * rf.increment_deg)[valid]
        sensed.add_scan(bearings, d[valid] / 100.0, 10.0 + 0.1 * i, 50.0, 0.3 * i, width)
    s = sensed.summary()
    assert s["returns"] > 100 and s["explained_by_chart"] == s["returns"] and s["cells"] == 0


def test_uncharted_obstacle_is_confirmed_after_two_scans_through_the_link():
    """Simulator bytes -> HilLink.decode -> SensedObstacles: the sensed cells lie on the true disc."""
    chart = np.zeros((200, 200), dtype=bool)
    truth = chart.copy()
    rr, cc = np.mgrid[0:200, 0:200]
    cx, cy, radius = 50.0, 30.0, 2.0         # map x east, y north
    truth |= ((cc + 0.5) * RES - cx) ** 2 + ((rr + 0.5) * RES - cy) ** 2 <= radius ** 2
    cfg = load(None, QUIET + ["sim.initial.x=10.0", "sim.initial.y=50.0"])
    core = SimulatorCore(simulator_settings(cfg), WorldMap(truth, RES))
    geo = LocalFrame(cfg.geodesy.lat0, cfg.geodesy.lon0, cfg.geodesy.alt0)
    link = HilLink.open("127.0.0.1:0", (), geo)
    sensed = SensedObstacles(chart, RES, confirm_hits=2)
    confirmed_after = []
    try:
        for _ in range(60):
            f = link.decode(core.frame())
            if f.scan is not None:
                new = sensed.add_scan(f.scan.bearings, f.scan.ranges, 10.0, 50.0, 0.0, f.scan.sector_width)
                confirmed_after.append(len(new))
            core.apply(Command(core.time_usec, 0.0, 0.0))
            core.step()
    finally:
        link.close()
    assert confirmed_after[0] == 0 and confirmed_after[1] > 0      # one scan is not enough, two are
    cells = sensed.cells()
    centres = (cells + 0.5) * RES                                  # (north, east)
    dist = np.hypot(centres[:, 0] - cy, centres[:, 1] - cx)
    # On the near face, widened by at most half a sector's arc (at ~18 m) and one cell's diagonal.
    half_arc = 0.5 * math.hypot(cy - 10.0, cx - 50.0) * math.radians(5.0)
    assert (dist <= radius + half_arc + RES * math.sqrt(2)).all()
    assert (centres[:, 0] < cy).all()       # all seen from the south side
    assert link.rejects == {}


def test_path_blocked_by_distance_to_the_polyline():
    path = np.array([[0.0, 0.0], [20.0, 0.0]])          # NED: north along east = 0
    def cell_at(n, e):
        return np.array([[int(n / RES), int(e / RES)]])
    assert path_blocked(path, cell_at(10.0, 1.0), RES, 2.0)      # 1.25 m from the path
    assert not path_blocked(path, cell_at(10.0, 3.0), RES, 2.0)  # 3.25 m
    assert not path_blocked(path, cell_at(23.0, 0.0), RES, 2.0)  # beyond the end
    assert not path_blocked(path, np.zeros((0, 2), dtype=int), RES, 2.0)


def test_planner_worker_plans_around_sensed_obstacles():
    """The cycle handler adds the sensed cells to the chart: the straight line is no longer taken."""
    from autopilot_bridge.local_planning import CycleInput, World, online_cycle_handler
    from autopilot_bridge.planning_worker import PlanRequest
    from planner.online import OnlineParams
    from planner.params import PlannerParams

    occ = np.zeros((120, 200), dtype=bool)              # 100 m x 60 m of open water
    ref = np.column_stack([np.linspace(10.0, 90.0, 17), np.full(17, 30.0)])   # every 5 m
    world = World(occ, RES, (90.0, 30.0), ref, None, PlannerParams(), OnlineParams(), "ddrrt-star")
    handle = online_cycle_handler(world)
    rr, cc = np.mgrid[0:120, 0:200]
    block = np.argwhere(((cc + 0.5) * RES - 30.0) ** 2 + ((rr + 0.5) * RES - 30.0) ** 2 <= 3.0 ** 2)
    grid_with = occ.copy()
    grid_with[block[:, 0], block[:, 1]] = True
    from planner.gridmap import OccupancyGrid
    safe = OccupancyGrid(grid_with, RES).inflate(1.9)

    def plan(sensed, version):
        req = PlanRequest(cycle=1, problem=CycleInput(10.0, 30.0, 0.0, 0.0, 7, sensed, version),
                          deadline_s=0.3, iterations=1500)
        return handle(req)

    without = plan(None, 0)
    assert without.status != "none" and not safe.path_free(without.path)   # straight through the disc
    with_ = plan(block.astype(np.int32), 1)
    assert with_.status != "none" and safe.path_free(with_.path)
    again = plan(None, 0)                                # a restarted autopilot: back to the chart
    assert not safe.path_free(again.path)


def _add_scan_reference(s: SensedObstacles, bearings, ranges, north, east, psi, sector_width) -> np.ndarray:
    """SensedObstacles.add_scan's cell work as it was written in numpy before it was compiled: the
    reference for the compiled version (the same cells, order, hits and counters). The arcs' float
    geometry (arc_cells) did not change."""
    s.stats.scans += 1
    rows, cols = s.chart.shape
    d = np.asarray(ranges, dtype=float)
    if len(d) == 0:
        return np.zeros((0, 2), dtype=np.int32)
    s.stats.returns += len(d)
    r, c = arc_cells(bearings, d, north, east, psi, sector_width, s.resolution)
    inside = (r >= 0) & (r < rows) & (c >= 0) & (c < cols)
    rc_r, rc_c = np.where(inside, r, 0), np.where(inside, c, 0)
    explained = (s.explained[rc_r, rc_c] & inside).any(axis=1)
    outside = ~inside.any(axis=1)
    s.stats.outside_map += int(outside.sum())
    s.stats.explained_by_chart += int((explained & ~outside).sum())
    keep = (~explained & ~outside)[:, None] & inside
    lin = np.unique(r[keep] * cols + c[keep])
    hr, hc = lin // cols, lin % cols
    fresh = ~s.confirmed[hr, hc]
    hr, hc = hr[fresh], hc[fresh]
    s.hits[hr, hc] += 1
    done = s.hits[hr, hc] >= s.confirm_hits
    new = np.column_stack([hr[done], hc[done]]).astype(np.int32).reshape(-1, 2)
    if len(new):
        s.confirmed[new[:, 0], new[:, 1]] = True
        s._cells.extend((int(r), int(c)) for r, c in new.tolist())
        s.version += 1
    return new


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_compiled_add_scan_places_what_the_numpy_version_placed(seed):
    """Random charts (blobs, walls, none) and random scans from inside and outside the grid, arcs
    from points to wide sectors, one to three hits to confirm: the same new cells in the same order,
    hits, confirmed cells, cell list and counters after every scan."""
    rng = np.random.default_rng(seed)
    for _ in range(6):
        rows, cols = int(rng.integers(20, 160)), int(rng.integers(20, 160))
        chart = rng.random((rows, cols)) < rng.choice([0.0, 0.002, 0.02])
        if rng.random() < 0.5:
            chart[int(rng.integers(rows)), :] = True
        res = float(rng.choice([0.25, 0.5, 1.0]))
        args = (chart, res, int(rng.integers(1, 4)), float(rng.uniform(0.0, 2.0)))
        fast, ref = SensedObstacles(*args), SensedObstacles(*args)
        for _ in range(60):
            n = int(rng.integers(0, 73))
            bearings = np.sort(rng.uniform(0, 2 * np.pi, n))
            ranges = rng.uniform(0.1, 40.0, n)
            north, east = rng.uniform(-10, rows * res + 10), rng.uniform(-10, cols * res + 10)
            psi, width = float(rng.uniform(-np.pi, np.pi)), float(rng.choice([0.0, 0.01, 0.087, 0.5]))
            got = fast.add_scan(bearings, ranges, north, east, psi, width)
            want = _add_scan_reference(ref, bearings, ranges, north, east, psi, width)
            assert got.dtype == want.dtype and got.shape == want.shape and np.array_equal(got, want)
            assert np.array_equal(fast.hits, ref.hits) and np.array_equal(fast.confirmed, ref.confirmed)
            assert fast.summary() == ref.summary() and fast._cells == ref._cells
        assert ref.count > 0 or not (~chart).any()


def test_sort_unique_is_numpys_unique():
    """The sensed-obstacle map's own sort-and-dedupe (it replaced np.unique for a shorter cold compile):
    empty, one value, all equal, sorted, reversed and random cell indices with repeats."""
    from autopilot_bridge.obstacle_map import _sort_unique

    rng = np.random.default_rng(5)
    cases = [np.zeros(0, np.int64), np.array([7]), np.full(9, 3), np.arange(20), np.arange(20)[::-1].copy()]
    cases += [rng.integers(0, hi, n) for hi, n in ((3, 50), (1000, 300), (10**9, 64), (40, 1))]
    for a in cases:
        buf = np.concatenate([a, rng.integers(0, 5, 4)]).astype(np.int64)   # values past k stay untouched
        tail = buf[len(a):].copy()
        u = _sort_unique(buf, len(a))
        assert np.array_equal(buf[:u], np.unique(a)) and np.array_equal(buf[len(a):], tail)
