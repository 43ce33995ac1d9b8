"""Scenario files, the map generators and the map-frame current adapter."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

from hil import maps
from hil import scenario as scenarios
from hil.errors import ConfigError, UsageError
from hil.optimum import shortest_path

FIXED = ("harbour", "labyrinth", "bench_discs", "bench_bugtrap", "bench_maze")


def test_committed_maps_match_their_generators():
    for name, make in maps.MAPS.items():
        committed = np.load(maps.MAP_DIR / f"{name}.npy")
        assert committed.dtype == bool
        assert np.array_equal(committed, make()), f"configs/maps/{name}.npy is stale: run python -m hil.maps"
        assert (maps.MAP_DIR / f"{name}.npy").stat().st_size < 200_000


@pytest.mark.parametrize("name", FIXED)
def test_fixed_scenarios_load_and_are_solvable(name):
    sc = scenarios.load(name)
    assert sc.occ.dtype == bool and sc.resolution > 0
    for p in (sc.start, sc.goal):
        assert 0 <= p[0] < sc.width and 0 <= p[1] < sc.height
        assert not sc.occ[int(p[1] / sc.resolution), int(p[0] / sc.resolution)]
    assert np.allclose(sc.reference_path[0], sc.start) and np.allclose(sc.reference_path[-1], sc.goal)
    assert math.isfinite(shortest_path(sc.occ, sc.resolution, sc.start, sc.goal).length)


def test_harbour_chart_route_crosses_obstacles_and_the_global_route_goes_round():
    """Figure 9: the chart route (the scenario's waypoints) cuts through piers/breakwater; the global
    reference path planned from it (planner.global_route, issue 12) goes round them."""
    from hil.optimum import segment_clear
    sc = scenarios.load("harbour")
    wps = sc.waypoints
    blocked = [not segment_clear(sc.occ, sc.resolution, *a, *b) for a, b in zip(wps[:-1], wps[1:], strict=True)]
    assert sum(blocked) >= 2
    ref = sc.reference_path
    assert all(segment_clear(sc.occ, sc.resolution, *a, *b) for a, b in zip(ref[:-1], ref[1:], strict=True))


def test_labyrinth_has_the_current():
    sc = scenarios.load("labyrinth")
    f = sc.map_field()
    assert f is not None
    vx, vy = f(np.array([50.0, 10.0]), np.array([50.0, 50.0]))
    assert np.hypot(vx[0], vy[0]) > 0.1                 # on the jet axis (map x = 50 m)
    assert np.hypot(vx[1], vy[1]) < np.hypot(vx[0], vy[0])


def test_map_frame_conversion_matches_ned_field():
    sc = scenarios.load("labyrinth")
    ned = sc.current_field()
    f = sc.map_field()
    x, y = 37.0, 61.0                                   # map: east 37, north 61
    v_north, v_east = ned.velocity_at(61.0, 37.0, sc.field_time)
    vx, vy = f(x, y)
    assert vx == pytest.approx(v_east) and vy == pytest.approx(v_north)


def test_random_maps_with_the_global_route_keep_the_draw_and_route_round_the_obstacles():
    """random-global: per seed the map, start and goal of `random`; the reference path is the
    global route, clear of the chart inflated by the safety radius (2 m), where the straight
    line of `random` crosses obstacles."""
    from planner.gridmap import OccupancyGrid

    straight, routed = scenarios.load_spec("random"), scenarios.load_spec("random-global")
    crossed = 0
    for seed in range(6):
        a = scenarios.instance(straight, np.random.default_rng(seed), safety_radius=2.0)
        b = scenarios.instance(routed, np.random.default_rng(seed), safety_radius=2.0)
        assert np.array_equal(a.occ, b.occ) and a.start == b.start and a.goal == b.goal
        safe = OccupancyGrid(b.occ, b.resolution).inflate(2.0)
        ref = b.reference_path
        assert np.allclose(ref[0], b.start) and np.allclose(ref[-1], b.goal)
        assert all(safe.segment_free(*p, *q) for p, q in zip(ref[:-1].tolist(), ref[1:].tolist(), strict=True))
        line = a.reference_path
        if not all(safe.segment_free(*p, *q) for p, q in zip(line[:-1].tolist(), line[1:].tolist(), strict=True)):
            crossed += 1
            assert not np.array_equal(ref, line)
    assert crossed >= 2        # the straight line crosses obstacles on most draws


def test_random_scenario_is_reproducible_and_valid():
    spec = scenarios.load_spec("random")
    a = scenarios.instance(spec, np.random.default_rng(3))
    b = scenarios.instance(spec, np.random.default_rng(3))
    c = scenarios.instance(spec, np.random.default_rng(4))
    assert np.array_equal(a.occ, b.occ) and a.start == b.start and a.goal == b.goal
    assert not np.array_equal(a.occ, c.occ)
    for sc in (a, c):
        assert math.dist(sc.start, sc.goal) >= spec.random.min_distance
        for p in (sc.start, sc.goal):
            assert not sc.occ[int(p[1] / sc.resolution), int(p[0] / sc.resolution)]
        assert np.allclose(sc.reference_path[0], sc.start) and np.allclose(sc.reference_path[-1], sc.goal)
    with pytest.raises(UsageError):
        scenarios.instance(spec, None)


BASE = """
name = "t"
description = "test"
kind = "fixed"
map = "maps/labyrinth.npy"
resolution = 0.5
start = [8.0, 8.0]
start_heading = 0.0
goal = [92.0, 92.0]
reference_path = [[8.0, 8.0], [92.0, 92.0]]
"""


def _full_load(path):
    """Everything a command does with a scenario file: spec, instance, planner and online params."""
    from planner.params import PlannerParams
    sc = scenarios.instance(scenarios.load_spec(str(path)), None)
    scenarios.planner_params(PlannerParams(), sc.planner_overrides, str(path))
    scenarios.online_params(sc.online_overrides, str(path))
    return sc


def test_base_scenario_loads(tmp_path):
    path = tmp_path / "t.toml"
    path.write_text(BASE)
    assert _full_load(path).name == "t"


@pytest.mark.parametrize("extra, message", [
    ('colour = "red"\n', "colour: unknown key"),
    ("[current]\nspeed = 3\n", "current.speed: unknown key"),
    ("[current]\norigin_y = true\n", "current.origin_y"),
    ("[planner]\nstep = -1.0\n", "planner.step"),
    ("[planner]\nwarp = 9\n", "planner.warp"),
    ("[online]\ncycle_time = 0\n", "online.cycle_time"),
])
def test_scenario_errors_are_one_line(tmp_path, extra, message):
    path = tmp_path / "t.toml"
    path.write_text(BASE + extra)
    with pytest.raises(ConfigError, match=message) as err:
        _full_load(path)
    assert "\n" not in str(err.value)


@pytest.mark.parametrize("replace, message", [
    ('start = [8.0, 8.0]', 'start = [500.0, 8.0]', ),
    ('start = [8.0, 8.0]', 'start = "here"'),
    ('map = "maps/labyrinth.npy"', 'map = "maps/none.npy"'),
    ('kind = "fixed"', 'kind = "spiral"'),
    ('resolution = 0.5', 'resolution = 0.0'),
    ('reference_path = [[8.0, 8.0], [92.0, 92.0]]', 'reference_path = [[8.0, 8.0]]'),
])
def test_scenario_bad_values(tmp_path, replace, message):
    path = tmp_path / "t.toml"
    path.write_text(BASE.replace(replace, message))
    with pytest.raises(ConfigError) as err:
        scenarios.instance(scenarios.load_spec(str(path)), None)
    assert "\n" not in str(err.value)


def test_start_inside_obstacle(tmp_path):
    occ = np.load(maps.MAP_DIR / "labyrinth.npy")
    r, c = np.argwhere(occ)[0]
    path = tmp_path / "t.toml"
    path.write_text(BASE.replace("start = [8.0, 8.0]", f"start = [{(c + 0.5) * 0.5}, {(r + 0.5) * 0.5}]"))
    with pytest.raises(ConfigError, match="inside an obstacle"):
        scenarios.instance(scenarios.load_spec(str(path)), None)


@pytest.mark.parametrize("uncharted, message", [
    ("[[8.0, 8.0, 1.0]]", "an obstacle covers the start"),
    ("[[50.0, 50.0, -1.0]]", "positive radius"),
    ("[[50.0, 50.0]]", "uncharted"),
])
def test_uncharted_obstacles_are_validated(tmp_path, uncharted, message):
    path = tmp_path / "t.toml"
    path.write_text(BASE.replace('kind = "fixed"', f'kind = "fixed"\nuncharted = {uncharted}'))
    with pytest.raises(ConfigError, match=message) as err:
        scenarios.instance(scenarios.load_spec(str(path)), None)
    assert "\n" not in str(err.value)


def test_uncharted_obstacles_are_in_the_truth_not_on_the_chart():
    sc = scenarios.load("harbour-uncharted")
    truth = sc.truth_occ()
    assert (truth | sc.occ).sum() == truth.sum() and truth.sum() > sc.occ.sum()
    for x, y, _r in sc.uncharted:
        row, col = int(y / sc.resolution), int(x / sc.resolution)
        assert truth[row, col] and not sc.occ[row, col]


def test_unknown_scenario_name():
    with pytest.raises(UsageError, match="unknown scenario"):
        scenarios.load_spec("atlantis")


def test_random_spec_needs_table(tmp_path):
    path = tmp_path / "r.toml"
    path.write_text('name = "r"\ndescription = "x"\nkind = "random"\n')
    with pytest.raises(ConfigError, match="random"):
        scenarios.load_spec(str(path))


@pytest.mark.parametrize("key", ["start", "goal"])
def test_a_fixed_scenario_without_start_or_goal_says_so(tmp_path, key):
    """A forgotten `goal` was read as (0, 0): 'goal: (0.0, 0.0) m is inside an obstacle' on this map, and a
    run to the map's corner where (0, 0) is open water. It is a missing key (random scenarios draw both)."""
    import re

    path = tmp_path / "t.toml"
    path.write_text(re.sub(rf"(?m)^{key} = .*\n", "", BASE))
    with pytest.raises(ConfigError, match=f"{key}: missing key") as err:
        scenarios.load_spec(str(path))
    assert "\n" not in str(err.value)


def test_the_vessel_computer_takes_the_route_hil_run_planned_and_plans_it_when_started_alone(tmp_path, monkeypatch,
                                                                                             capsys):
    """hil.assembly.computer.known_scenario: with `hil run`'s route.json the route is taken as planned there
    (no planning); alone it plans the route itself; a route planned for another scenario, chart or safety
    radius, or a file that is not one, is a one-line UsageError."""
    from hil import routing, settings
    from hil.assembly.computer import known_scenario

    cfg = settings.load()
    calls: list[routing.RouteRequest] = []
    real = scenarios.plan_route

    def counted(req: routing.RouteRequest) -> np.ndarray:
        calls.append(req)
        return real(req)

    monkeypatch.setattr(scenarios, "plan_route", counted)
    alone = known_scenario(cfg, "harbour")
    assert len(calls) == 1 and "planned the global route through" in capsys.readouterr().err
    planned = scenarios.load("harbour", cfg.current, cfg.planner.safety_radius, cfg.geodesy)
    request = planned.route
    assert isinstance(request, routing.RouteRequest)
    file = tmp_path / "route.json"
    routing.write_route(file, routing.planned_route(request, planned.reference_path))
    assert len(calls) == 2
    handed = known_scenario(cfg, "harbour", str(file))
    assert len(calls) == 2, "the vessel computer planned the route again"
    np.testing.assert_array_equal(handed.reference_path, alone.reference_path)
    assert "not planned here" in capsys.readouterr().err

    def refused(route_file: str, scenario: str = "harbour", safety: float | None = None) -> str:
        c = cfg if safety is None else settings.load(None, [f"planner.safety_radius={safety}"])
        with pytest.raises(UsageError) as exc:
            known_scenario(c, scenario, route_file)
        assert "\n" not in str(exc.value)
        return str(exc.value)

    assert "another route's waypoints" in refused(str(file), "labyrinth")
    assert "another safety radius" in refused(str(file), safety=cfg.planner.safety_radius + 0.5)
    table = json.loads(file.read_text())
    table["chart_sha256"] = "0" * 64
    (tmp_path / "chart.json").write_text(json.dumps(table))
    assert "another chart" in refused(str(tmp_path / "chart.json"))
    table = json.loads(file.read_text())
    table["path"][3] = [1e6, 5.0]
    (tmp_path / "far.json").write_text(json.dumps(table))
    assert "on the chart" in refused(str(tmp_path / "far.json"))
    del table["path"]
    (tmp_path / "short.json").write_text(json.dumps(table))
    assert refused(str(tmp_path / "short.json")).endswith("path: missing key")
    (tmp_path / "junk.json").write_text("{not json")
    assert "not JSON" in refused(str(tmp_path / "junk.json"))
    assert "No such file" in refused(str(tmp_path / "none.json"))
    assert len(calls) == 2     # a refused route is one line before anything is planned
