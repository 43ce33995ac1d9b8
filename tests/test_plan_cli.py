"""`hil plan`: bad input is one line and exit 2; a good query returns a valid, collision-free path."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

from hil.optimum import segment_clear, shortest_path


def _one_line_error(proc) -> None:
    assert proc.returncode == 2, proc.stderr
    lines = [ln for ln in proc.stderr.strip().splitlines() if ln.strip()]
    assert len(lines) >= 1
    assert "Traceback" not in proc.stderr
    assert lines[-1].startswith("hil") and "error" in lines[-1]


@pytest.fixture
def wall_map(tmp_path):
    """20 m x 20 m at 0.5 m/cell, a wall x in [9, 11] m, y in [0, 14] m."""
    occ = np.zeros((40, 40), dtype=bool)
    occ[0:28, 18:22] = True
    path = tmp_path / "wall.npy"
    np.save(path, occ)
    return path, occ


def test_missing_map_file(hil_main, tmp_path):
    p = hil_main("plan", "--map", str(tmp_path / "nope.npy"), "--resolution", "0.5", "--start", "1,1", "--goal", "5,5")
    _one_line_error(p)
    assert "no such file" in p.stderr


def test_map_not_a_grid(hil_main, tmp_path):
    bad = tmp_path / "bad.npy"
    np.save(bad, np.zeros(10))               # 1-D: not a grid
    p = hil_main("plan", "--map", str(bad), "--resolution", "0.5", "--start", "1,1", "--goal", "2,2")
    _one_line_error(p)
    text = tmp_path / "text.png"
    text.write_text("this is not an image")
    p = hil_main("plan", "--map", str(text), "--resolution", "0.5", "--start", "1,1", "--goal", "2,2")
    _one_line_error(p)


@pytest.mark.parametrize("res", ["0", "-1"])
def test_resolution_not_positive(hil_main, wall_map, res):
    path, _ = wall_map
    p = hil_main("plan", "--map", str(path), f"--resolution={res}", "--start", "1,1", "--goal", "5,5")
    _one_line_error(p)
    assert "resolution" in p.stderr


@pytest.mark.parametrize("start", ["25,1", "1,-3", "-1,1"])
def test_start_outside_map(hil_main, wall_map, start):
    path, _ = wall_map
    p = hil_main("plan", "--map", str(path), "--resolution", "0.5", f"--start={start}", "--goal", "5,5")
    _one_line_error(p)
    assert "outside" in p.stderr


def test_bad_point_syntax_and_obstacle_start(hil_main, wall_map):
    path, _ = wall_map
    _one_line_error(hil_main("plan", "--map", str(path), "--resolution", "0.5", "--start", "1;1", "--goal", "5,5"))
    p = hil_main("plan", "--map", str(path), "--resolution", "0.5", "--start", "10,5", "--goal", "15,5")
    _one_line_error(p)
    assert "obstacle" in p.stderr


def test_start_or_goal_in_the_safety_margin_is_a_usage_error(hil_main, wall_map):
    """A goal in free water but within the inflation radius of the wall can never be reached: one line
    naming the margin (exit 2), not 'no path' (exit 1) with 'inside an obstacle or outside the map'."""
    path, _ = wall_map
    p = hil_main("plan", "--map", str(path), "--resolution", "0.5", "--start", "3,3", "--goal", "8,3",
                 "--inflate", "2", "--deadline", "0.05")
    _one_line_error(p)
    assert "--goal 8,3" in p.stderr and "margin" in p.stderr and "--inflate" in p.stderr
    p = hil_main("plan", "--map", str(path), "--resolution", "0.5", "--start", "8,3", "--goal", "3,3",
                 "--inflate", "2", "--deadline", "0.05")
    _one_line_error(p)
    assert "--start 8,3" in p.stderr and "margin" in p.stderr
    # the same goal with a smaller margin is fine
    p = hil_main("plan", "--map", str(path), "--resolution", "0.5", "--start", "3,3", "--goal", "8,3",
                 "--inflate", "0.5", "--deadline", "0.05", "--json")
    assert p.returncode == 0, p.stderr


@pytest.mark.parametrize("extra", [["--heading", "inf"], ["--heading", "nan"], ["--seed", str(2 ** 64)],
                                   ["--set", f"planner.seed={2 ** 63}"]])
def test_non_finite_heading_and_oversized_seed_are_usage_errors(hil_main, wall_map, extra):
    """A heading that is not a finite angle and a seed the planner's generator cannot take (it holds a
    signed 64-bit integer) are one line, exit 2, not a traceback or a silently ignored NaN."""
    path, _ = wall_map
    p = hil_main("plan", "--map", str(path), "--resolution", "0.5", "--start", "3,3", "--goal", "17,3",
                 "--deadline", "0.05", *extra)
    _one_line_error(p)
    assert ("heading" if extra[1] in ("inf", "nan") else "seed") in p.stderr.strip().splitlines()[-1]


def test_negative_coordinates_read_as_values(hil_main, wall_map):
    """`--start -1,5` is a point left of the map (its one-line 'outside'), not an unknown option."""
    path, _ = wall_map
    p = hil_main("plan", "--map", str(path), "--resolution", "0.5", "--start", "-1,5", "--goal", "17,3")
    _one_line_error(p)
    assert "outside" in p.stderr


def test_a_float_map_of_zeros_and_ones_is_a_map(hil_main, wall_map, tmp_path):
    """np.zeros() is float64: a 0.0/1.0 .npy is the same map as the bool one (the help says 0-1); other
    values stay refused, naming them."""
    _, occ = wall_map
    floats = tmp_path / "wall_f.npy"
    np.save(floats, occ.astype(np.float64))
    p = hil_main("plan", "--map", str(floats), "--resolution", "0.5", "--start", "10,5", "--goal", "15,5")
    _one_line_error(p)
    assert "obstacle" in p.stderr          # the wall is read as a wall
    p = hil_main("plan", "--map", str(floats), "--resolution", "0.5", "--start", "3,3", "--goal", "17,3",
                 "--deadline", "0.05", "--json")
    assert p.returncode == 0, p.stderr
    half = tmp_path / "half.npy"
    np.save(half, occ * 0.5)
    p = hil_main("plan", "--map", str(half), "--resolution", "0.5", "--start", "3,3", "--goal", "17,3")
    _one_line_error(p)
    assert "0/1" in p.stderr


def test_ddrrt_star_on_a_map_far_larger_than_its_domain_says_why(hil, tmp_path):
    """DDRRT* (the default) rejects every sample farther than its ESD (<= 29 m) from the tree: on a 400 m open
    map it ends 'approximate' after rejecting nearly all samples, where RRT* reaches the goal. The reason and
    the way out are said (stderr and the JSON's 'hint'); a successful or RRT* query has no hint."""
    np.save(tmp_path / "open.npy", np.zeros((200, 200), dtype=bool))
    base = ("plan", "--map", str(tmp_path / "open.npy"), "--resolution", "2", "--start", "10,10", "--goal", "390,390",
            "--deadline", "60", "--iterations", "5000", "--json")
    p = hil(*base, "--algorithm", "ddrrt-star")
    out = json.loads(p.stdout)
    assert out["status"] != "exact" and out["samples_rejected"] > 0.9 * out["iterations"]
    assert p.returncode == 1          # a path to the closest node does not reach the goal
    assert "ESD" in out["hint"] and "--algorithm rrt-star" in out["hint"]
    assert "hint" in p.stderr
    p = hil(*base, "--algorithm", "rrt-star")
    out = json.loads(p.stdout)
    assert p.returncode == 0 and out["status"] == "exact" and "hint" not in out


def test_a_path_that_does_not_reach_the_goal_is_exit_1(hil, wall_map):
    """'approximate' (the path to the node closest to the goal, printed) is not success: exit 1, as 'none'."""
    path, _ = wall_map
    p = hil("plan", "--map", str(path), "--resolution", "0.5", "--start", "3,3", "--goal", "17,3",
            "--algorithm", "rrt-star", "--deadline", "60", "--iterations", "3", "--json")
    out = json.loads(p.stdout)
    assert out["status"] == "approximate" and out["path"], out
    assert p.returncode == 1, p.stderr


def test_unknown_scenario(hil_main):
    _one_line_error(hil_main("plan", "--scenario", "atlantis", "--json"))


@pytest.mark.parametrize("algorithm", ["rrt-star", "informed-rrt-star", "ddrrt-star"])
def test_plan_json_path_is_valid(hil, wall_map, algorithm):
    path, occ = wall_map
    p = hil("plan", "--map", str(path), "--resolution", "0.5", "--start", "3,3", "--goal", "17,3",
            "--algorithm", algorithm, "--deadline", "20", "--iterations", "3000", "--seed", "4",
            "--inflate", "0", "--objective", "length", "--json")
    assert p.returncode == 0, p.stderr
    d = json.loads(p.stdout)
    for key in ("status", "path", "cost", "length", "iterations", "time_to_first_solution_s", "planning_time_s"):
        assert key in d
    assert d["status"] == "exact"
    pts = np.array(d["path"])
    assert np.allclose(pts[0], [3, 3]) and np.allclose(pts[-1], [17, 3])
    for a, b in zip(pts[:-1], pts[1:], strict=True):
        assert segment_clear(occ, 0.5, a[0], a[1], b[0], b[1]), (a, b)
    length = float(np.sum(np.hypot(*np.diff(pts, axis=0).T)))
    assert math.isclose(length, d["length"], rel_tol=1e-6)
    opt = shortest_path(occ, 0.5, (3, 3), (17, 3)).length
    assert opt - 1e-6 <= d["length"] <= 1.5 * opt
    assert d["iterations"] <= 3000
    assert 0 <= d["time_to_first_solution_s"] <= d["planning_time_s"]


def test_same_seed_same_path(hil, wall_map):
    path, _ = wall_map
    args = ("plan", "--map", str(path), "--resolution", "0.5", "--start", "3,3", "--goal", "17,3", "--deadline", "20",
            "--iterations", "1500", "--inflate", "0.5", "--json")
    a = json.loads(hil(*args, "--seed", "7").stdout)
    b = json.loads(hil(*args, "--seed", "7").stdout)
    c = json.loads(hil(*args, "--seed", "8").stdout)
    assert a["path"] == b["path"]
    assert a["path"] != c["path"]


def test_scenario_plot(hil, tmp_path):
    out = tmp_path / "harbour.png"
    p = hil("plan", "--scenario", "harbour", "--deadline", "60", "--iterations", "20000", "--seed", "2",
            "--plot", str(out), "--json")
    assert p.returncode == 0, p.stderr
    d = json.loads(p.stdout)
    assert d["status"] == "exact"
    assert d["objective"] == "current"
    assert out.stat().st_size > 20_000
    import matplotlib.image as mpimg
    img = mpimg.imread(out)
    assert img.shape[0] > 300 and img.std() > 0.05     # not a blank canvas


def _random_discs(seed: int) -> np.ndarray:
    """A 200 x 200 map (0.5 m cells) of random discs: a map the benchmarks never saw."""
    rng = np.random.default_rng(seed)
    occ = np.zeros((200, 200), dtype=bool)
    yy, xx = (np.mgrid[0:200, 0:200] + 0.5) * 0.5
    for _ in range(rng.integers(15, 30)):
        cx, cy, r = rng.uniform(10, 90), rng.uniform(10, 90), rng.uniform(2, 7)
        occ |= (xx - cx) ** 2 + (yy - cy) ** 2 <= r * r
    occ[0:12, 0:12] = occ[188:, 188:] = False
    return occ


@pytest.mark.parametrize("algorithm", ["rrt-star", "ddrrt-star"])
def test_unseen_random_map_against_the_optimum(hil, tmp_path, algorithm):
    """Set-up (warm-up, inflation, labelling) is reported apart from the search; the path is
    valid on the inflated map and near the exact optimum (iteration budget: no timing)."""
    from planner.gridmap import OccupancyGrid

    occ = _random_discs(11)
    path = tmp_path / "discs.npy"
    np.save(path, occ)
    p = hil("plan", "--map", str(path), "--resolution", "0.5", "--start", "3,3", "--goal", "97,97", "--algorithm",
            algorithm, "--objective", "length", "--deadline", "60", "--iterations", "20000", "--inflate", "1",
            "--seed", "2", "--json")
    assert p.returncode == 0, p.stderr
    d = json.loads(p.stdout)
    assert d["status"] == "exact"
    assert d["setup_s"] >= 0 and d["warm_up_s"] >= 0 and d["compiled"] in (True, False)
    inflated = OccupancyGrid(occ, 0.5).inflate(1.0).occ
    pts = np.array(d["path"])
    for a, b in zip(pts[:-1], pts[1:], strict=True):
        assert segment_clear(inflated, 0.5, a[0], a[1], b[0], b[1]), (a, b)
    opt = shortest_path(inflated, 0.5, (3, 3), (97, 97)).length
    assert opt - 1e-6 <= d["length"] <= 1.05 * opt


def test_cold_cache_compiles_before_the_clock(hil, wall_map, tmp_path):
    """With an empty numba cache the planner compiles first, says so on stderr, and the search
    still gets its budget (the first `hil plan` used to return 'none' after 0 iterations)."""
    path, _ = wall_map
    p = hil("plan", "--map", str(path), "--resolution", "0.5", "--start", "3,3", "--goal", "17,3", "--deadline", "0.5",
            "--inflate", "0", "--json", env={"NUMBA_CACHE_DIR": str(tmp_path / "numba-cache")}, timeout=900)
    assert p.returncode == 0, p.stderr
    assert "compiled the planner (cold numba cache)" in p.stderr
    d = json.loads(p.stdout)
    assert d["compiled"] is True and d["status"] == "exact" and d["iterations"] > 0


def _plan_json(hil_main, *args):
    p = hil_main("plan", *args, "--iterations", "400", "--deadline", "30", "--json")
    assert p.returncode in (0, 1), p.stderr
    return json.loads(p.stdout)


def test_the_users_current_reaches_the_planner(hil_main):
    """Issue 34: `--set current.*` changed nothing (the scenario's current came from the default
    configuration); now the speed scale and the jet's shape change the cost of eq. (12)."""
    base = ("--scenario", "labyrinth", "--objective", "current", "--algorithm", "rrt-star")
    plain = _plan_json(hil_main, *base)
    assert plain["current"].startswith("scenario labyrinth")
    still = _plan_json(hil_main, *base, "--set", "current.speed_scale=0")
    assert still["current"].startswith("scenario labyrinth")
    assert still["cost"] == pytest.approx(still["length"])  # no current: eq. (12) is the length
    assert plain["cost"] < 0.8 * plain["length"]
    other = _plan_json(hil_main, *base, "--set", "current.b=3")
    assert (other["path"], other["cost"]) != (plain["path"], plain["cost"])


def test_map_current_option_or_a_clear_none(hil_main, wall_map):
    path, _ = wall_map
    base = ("--map", str(path), "--resolution", "0.5", "--start", "2,17", "--goal", "18,17", "--inflate", "0.5",
            "--objective", "current", "--algorithm", "rrt-star")
    none = _plan_json(hil_main, *base)
    assert none["current"].startswith("none (--map has no current")
    assert none["cost"] == pytest.approx(none["length"])
    down = _plan_json(hil_main, *base, "--current", "0.5,0")     # straight downstream: 0.27 a metre
    assert down["current"].startswith("uniform")
    assert down["cost"] < 0.35 * down["length"]
    up = _plan_json(hil_main, *base, "--current", "-0.5,0")      # upstream: 0.73 a metre
    assert up["cost"] > 0.7 * up["length"]
    bad = hil_main("plan", *base, "--current", "east")
    _one_line_error(bad)
