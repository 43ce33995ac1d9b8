"""Routes as users give them (issue 12): sparse waypoints, legs longer than the perceptual radius.

Whole lockstep HIL runs (`hil run`, simulator and autopilot as real processes on UDP) on scenario
files the repository does not hold: the harbour's chart route as 4 waypoints 59-77 m apart, the
labyrinth with only start and goal, and random maps with 2-3 random waypoints after the start.
Bad routes in a scenario file are one-line errors with exit code 2.
"""

from __future__ import annotations

import json
import re
from pathlib import Path

import numpy as np
import pytest

from hil.config import CONFIG_DIR

HARBOUR_4 = [[22.0, 40.0], [60.0, 85.0], [120.0, 100.0], [185.0, 140.0]]


def scenario_file(tmp_path: Path, base: str, route, name: str = "sparse", **keys) -> Path:
    """``configs/scenarios/BASE.toml`` with its reference_path replaced by ``route`` (and ``keys`` set)."""
    text = (CONFIG_DIR / "scenarios" / f"{base}.toml").read_text()
    rel = re.search(r'^map = "(.*)"$', text, flags=re.M).group(1)      # relative to the scenario file
    text = re.sub(r"^map = .*$", f'map = "{(CONFIG_DIR / "scenarios" / rel).resolve()}"', text, flags=re.M)
    text = re.sub(r"^reference_path = .*$", f"reference_path = {json.dumps(route)}", text, flags=re.M)
    text = re.sub(r'^name = .*$', f'name = "{name}"', text, flags=re.M)
    for key, value in keys.items():
        text = re.sub(rf"^{key} = .*$", f"{key} = {value}", text, flags=re.M)
    path = tmp_path / f"{name}.toml"
    path.write_text(text)
    return path


def run_json(hil, tmp_path: Path, scenario: Path, seed: int) -> tuple[int, dict]:
    out = tmp_path / f"run-{scenario.stem}-{seed}"
    r = hil("run", "--scenario", str(scenario), "--lockstep", "--seed", str(seed), "--json", "--no-plot",
            "--out", str(out), timeout=900)
    assert r.stdout.strip(), r.stderr[-2000:]
    return r.returncode, json.loads(r.stdout.strip().splitlines()[-1])


def assert_reached(code: int, s: dict) -> None:
    assert s["outcome"] == "goal", s.get("events")
    assert s["reached_goal"] and s["collisions"] == 0 and code == 0
    assert s["min_clearance_m"] >= 1.0          # the hull's half length


@pytest.mark.slow
def test_harbour_as_four_sparse_waypoints_reaches_the_goal(hil, tmp_path):
    code, s = run_json(hil, tmp_path, scenario_file(tmp_path, "harbour", HARBOUR_4), 1)
    assert_reached(code, s)
    assert s["fallback_activations"] <= 3


@pytest.mark.slow
def test_labyrinth_with_start_and_goal_only_reaches_the_goal(hil, tmp_path):
    code, s = run_json(hil, tmp_path, scenario_file(tmp_path, "labyrinth", [[8.0, 8.0], [92.0, 92.0]]), 2)
    assert_reached(code, s)


@pytest.mark.slow
# (1, 22) and (1, 85): runs of `hil montecarlo --routes --seed 1` that ended in a U-turn at cruise
# speed into an obstacle beside a new path (autopilot.turn_in_place_angle).
@pytest.mark.parametrize("seed, run", [(5, 0), (5, 1), (17, 3), (1, 22), (1, 85)])
def test_random_map_with_sparse_route_reaches_the_goal(hil, tmp_path, seed, run):
    from hil import scenario as scenarios
    from hil.route_montecarlo import write_instance

    spec = scenarios.load_spec("random-route")
    scen = scenarios.instance(spec, np.random.default_rng([seed, run]))
    legs = np.hypot(*np.diff(scen.waypoints, axis=0).T)
    assert 2 <= len(legs) <= 3 and legs.min() >= 35.0     # sparse: every leg beyond the 33 m radius
    path = write_instance(scen, spec, tmp_path / "scen", f"random-route-{seed}-{run}")
    code, s = run_json(hil, tmp_path, path, seed * 1000 + run)
    assert_reached(code, s)


# -- bad routes in a scenario file: one line, exit 2, the waypoint named ------------------------

def _pond_map(tmp_path: Path) -> Path:
    """100 m x 80 m at 0.5 m: a wall at x = 50-52 m for y < 60 m and a closed ring round (80, 60)."""
    rows, cols = 160, 200
    y, x = (np.mgrid[0:rows, 0:cols] + 0.5) * 0.5
    occ = (x >= 50) & (x < 52) & (y < 60)
    r = np.hypot(x - 80, y - 60)
    occ |= (r >= 8) & (r < 10)
    path = tmp_path / "pond.npy"
    np.save(path, occ)
    return path


def pond_scenario(tmp_path: Path, route, goal=(90.0, 20.0)) -> Path:
    text = "\n".join([
        'name = "pond"', 'description = "a wall and a walled pond"', 'kind = "fixed"',
        f'map = "{_pond_map(tmp_path)}"', "resolution = 0.5", "start = [10.0, 20.0]", "start_heading = 0.0",
        f"goal = {json.dumps(list(goal))}", f"reference_path = {json.dumps(route)}", "", "[current]",
        "enabled = false", ""])
    path = tmp_path / "pond.toml"
    path.write_text(text)
    return path


@pytest.mark.parametrize("route, goal, expected", [
    ([[10.0, 20.0], [51.0, 30.0], [90.0, 20.0]], (90.0, 20.0),
     r"reference_path\[1\]: \(51\.0, 30\.0\) m is inside an obstacle or its safety margin \(safety radius 2 m\)"),
    ([[10.0, 20.0], [30.0, 95.0], [90.0, 20.0]], (90.0, 20.0), r"reference_path\[1\]: \(30\.0, 95\.0\) m is off the"),
    ([[10.0, 20.0], [30.0, 70.0], [80.0, 60.0]], (80.0, 60.0), r"goal: \(80\.0, 60\.0\) m cannot be reached by water"),
])
def test_bad_route_in_a_scenario_file_is_a_one_line_error(hil, tmp_path, route, goal, expected):
    path = pond_scenario(tmp_path, route, goal)
    r = hil("run", "--scenario", str(path), "--lockstep", "--duration", "5", "--no-plot", "--out", str(tmp_path / "o"))
    assert r.returncode == 2, r.stderr
    errors = [line for line in r.stderr.strip().splitlines() if "error" in line]
    assert len(errors) == 1 and "Traceback" not in r.stderr, r.stderr
    assert re.search(expected, errors[0]) and str(path) in errors[0], errors[0]
    assert not (tmp_path / "o" / "run.tlog").exists()          # nothing was started


def test_start_and_goal_alone_are_routed_round_the_wall(tmp_path):
    from hil import scenario as scenarios
    from planner.gridmap import OccupancyGrid

    scen = scenarios.load(str(pond_scenario(tmp_path, [])))
    ref = scen.reference_path
    assert np.allclose(ref[0], scen.start) and np.allclose(ref[-1], scen.goal)
    assert ref[:, 1].max() > 60.0                       # round the end of the wall (y < 60 m)
    grid = OccupancyGrid(scen.occ, scen.resolution).inflate(2.0)
    assert all(grid.segment_free(*a, *b) for a, b in zip(ref[:-1], ref[1:], strict=True))
    assert np.max(np.hypot(*np.diff(ref, axis=0).T)) <= 10.0 + 1e-9


def test_loading_a_scenario_plans_no_route_its_first_use_plans_it_once(tmp_path, monkeypatch):
    """Configuration loading does no planning (issue 30): the route is planned where it is first
    needed, once; a bad waypoint is found then, as the same one-line ConfigError."""
    import planner.global_route as global_route
    from hil import scenario as scenarios
    from hil.errors import ConfigError

    calls: list[int] = []
    real = global_route.plan_chart_route
    monkeypatch.setattr(global_route, "plan_chart_route", lambda *a, **k: calls.append(1) or real(*a, **k))
    scen = scenarios.load(str(pond_scenario(tmp_path, [])))
    assert calls == []
    first = scen.reference_path
    assert calls == [1] and scen.reference_path is first and calls == [1]

    bad = scenarios.load(str(pond_scenario(tmp_path, [[10.0, 20.0], [51.0, 30.0], [90.0, 20.0]])))
    with pytest.raises(ConfigError, match=r"reference_path\[1\]: \(51\.0, 30\.0\) m is inside an obstacle"):
        _ = bad.reference_path


def test_a_run_plans_its_route_once_and_its_vessel_computer_takes_it(hil, tmp_path):
    """`hil run` plans the global route before starting any process and hands it to the vessel computer
    (route.json, `hil autopilot --route`), which does not plan it again: one planning per run, counted by
    the line each planning process writes."""
    from hil.routing import read_route

    out = tmp_path / "run"
    r = hil("run", "--scenario", str(scenario_file(tmp_path, "harbour", HARBOUR_4)), "--lockstep", "--duration", "3",
            "--json", "--no-plot", "--out", str(out), timeout=600)
    assert r.stdout.strip(), r.stderr[-2000:]
    autopilot_log = (out / "autopilot.log").read_text()
    planned = [ln for ln in (r.stderr + autopilot_log).splitlines() if "planned the global route" in ln]
    assert len(planned) == 1 and planned[0].startswith("run: "), planned
    taken = [ln for ln in autopilot_log.splitlines() if "global route from" in ln]
    assert len(taken) == 1 and str(out / "route.json") in taken[0] and "not planned here" in taken[0]
    route = read_route(out / "route.json")
    assert len(route.waypoints) == len(HARBOUR_4) and f"({len(route.path)} points)" in planned[0]
    assert json.loads(r.stdout.strip().splitlines()[-1])["sim_time_s"] == 3.0
