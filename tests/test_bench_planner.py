"""The benchmark's independent optimum (visibility graph) and `hil bench planner` itself."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

from hil.optimum import convex_corners, segment_clear, shortest_path


def test_optimum_around_a_wall_solved_by_hand():
    # 10 m x 10 m at 1 m/cell; wall cells x in [4, 6), y in [0, 8). From (1, 1) to (9, 1) the
    # shortest path climbs to the wall's top corners (4, 8) and (6, 8): 2 * sqrt(3^2 + 7^2) + 2.
    occ = np.zeros((10, 10), dtype=bool)
    occ[0:8, 4:6] = True
    opt = shortest_path(occ, 1.0, (1.0, 1.0), (9.0, 1.0))
    assert opt.length == pytest.approx(2 * math.hypot(3, 7) + 2, abs=1e-5)
    assert np.allclose(opt.path, [[1, 1], [4, 8], [6, 8], [9, 1]], atol=1e-5)


def test_optimum_free_and_blocked():
    occ = np.zeros((20, 20), dtype=bool)
    assert shortest_path(occ, 0.5, (1, 1), (9, 6)).length == pytest.approx(math.hypot(8, 5))
    occ[:, 10] = True                                    # a full wall: no path
    assert math.isinf(shortest_path(occ, 0.5, (1, 1), (9, 6)).length)


def test_optimum_resolution_scales():
    occ = np.zeros((10, 10), dtype=bool)
    occ[0:8, 4:6] = True
    a = shortest_path(occ, 1.0, (1, 1), (9, 1)).length
    b = shortest_path(occ, 0.5, (0.5, 0.5), (4.5, 0.5)).length
    assert b == pytest.approx(a / 2, abs=1e-5)


def test_segment_check_counts_corner_touches():
    occ = np.zeros((4, 4), dtype=bool)
    occ[1, 2] = occ[2, 1] = True                         # diagonal pair touching at lattice point (2, 2)
    assert not segment_clear(occ, 1.0, 0.5, 0.5, 3.5, 3.5)   # passes exactly through the touch point
    assert segment_clear(occ, 1.0, 0.5, 0.5, 1.5, 0.5)
    assert not segment_clear(occ, 1.0, 0.5, 2.5, 3.5, 2.5)   # crosses cell (row 2, col 1)
    assert not segment_clear(occ, 1.0, -0.5, 0.5, 0.5, 0.5)  # leaves the map


def test_convex_corners_of_a_block():
    occ = np.zeros((6, 6), dtype=bool)
    occ[2:4, 2:4] = True                                 # a 2 x 2 block: 4 convex corners
    pts = convex_corners(occ, 1.0)
    assert len(pts) == 4
    assert np.allclose(sorted(map(tuple, np.round(pts, 3))), [(2, 2), (2, 4), (4, 2), (4, 4)])


def test_optimum_never_beaten_by_the_planner():
    """A planner path is collision free, so it can never be shorter than the optimum."""
    from hil import scenario as scenarios
    from planner import make_planner
    from planner.gridmap import OccupancyGrid
    from planner.params import PlannerParams
    from planner.problem import PlanningProblem
    from planner.termination import Termination

    sc = scenarios.load("bench_bugtrap")
    opt = shortest_path(sc.occ, sc.resolution, sc.start, sc.goal)
    params = PlannerParams(algorithm="informed-rrt-star", objective="length", safety_radius=0.0,
                           turn_radius_factor=0.0, seed=3)
    r = make_planner("informed-rrt-star", params).solve(
        PlanningProblem(grid=OccupancyGrid(sc.occ, sc.resolution), start=sc.start, goal=sc.goal),
        Termination.iterations(20000))
    assert r.status == "exact"
    assert r.length >= opt.length - 1e-6
    assert r.length <= 1.2 * opt.length


def test_bench_planner_quick_json(hil):
    p = hil("bench", "planner", "--quick", "--maps", "bench_maze", "--algorithms", "ddrrt-star,rrt-star",
            "--no-ompl", "--json")
    assert p.returncode == 0, p.stderr
    d = json.loads(p.stdout)
    e = d["maps"]["bench_maze"]
    assert e["optimum_m"] == pytest.approx(shortest_path(np.load("configs/maps/bench_maze.npy"), 0.5,
                                                         (5, 5), (95, 95)).length)
    for alg in ("ddrrt-star", "rrt-star"):
        m = e["planners"][alg]
        assert m["iterations_per_s"] > 0
        assert m["first_solution_s"] is not None and m["first_solution_s"] > 0
        for b in ("0.05", "0.2"):
            r = m["ratio"][b]                            # "inf": unsolved in most seeds at that budget
            assert r is None or r == "inf" or r >= 1.0 - 1e-9
    assert "disabled" in d["ompl"]
    assert "iter/s" in p.stderr                          # the human table goes to stderr
    e2e = e["end_to_end"]                                # one `hil plan --deadline B` process per budget
    assert [r["deadline_s"] for r in e2e] == [0.05, 0.2]
    for r in e2e:
        assert r["status"] in ("exact", "approximate", "none")
        assert r["wall_s"] >= r["search_s"] + r["setup_s"] + r["warm_up_s"] - 1e-6
        assert r["search_s"] >= r["deadline_s"] * 0.5     # the deadline is spent on the search


def test_bench_planner_bad_budget(hil_main):
    p = hil_main("bench", "planner", "--budgets", "0,1")
    assert p.returncode == 2 and "Traceback" not in p.stderr


def test_bench_planner_current_objective_on_the_island(hil_main):
    """Issue 34: --objective current divides each planner's eq. (12) cost by the judge's optimum;
    on the island the shortest path is far from it (the stream's channel is the longer one)."""
    p = hil_main("bench", "planner", "--quick", "--objective", "current", "--maps", "island",
                 "--algorithms", "rrt-star", "--no-ompl", "--json")
    assert p.returncode == 0, p.stderr
    e = json.loads(p.stdout)["maps"]["island"]
    assert e["optimum_m"] == pytest.approx(54.0)                      # the straight south channel
    assert e["shortest_path_eq12"] == pytest.approx(54.0 / (1 + math.exp(-1)), rel=1e-6)  # upstream all along
    assert e["shortest_path_eq12"] > 1.25 * e["optimum_eq12"]
    for b in ("0.05", "0.2"):
        r = e["planners"]["rrt-star"]["ratio"][b]
        assert r is None or r == "inf" or r >= 1.0 - 1e-6
    assert "end_to_end" not in e and "ompl_rrt_star" not in e
