"""Issue 34's defects of DDRRT*, each fixed behind a parameter whose default keeps the trees of
before bit for bit: the PGNode (compiled, repaired into usable free space, never a wasted sample
once reached), failed extensions that count the turning-radius fan, a constant dynamic domain
that can act, and alpha_y against the resultant of current and wave drift."""

from __future__ import annotations

import hashlib
import math
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from hil import scenario as scenarios
from planner import PlannerParams, _png, make_planner
from planner.core import free_regions
from planner.cost import path_cost
from planner.ddrrt_star import DDRRTStar
from planner.field import GridField
from planner.gridmap import OccupancyGrid
from planner.png import pg_node
from planner.problem import PlanningProblem
from planner.termination import Termination


def _digest(r) -> str:
    return hashlib.sha256(np.ascontiguousarray(r.tree_nodes).tobytes()
                          + np.ascontiguousarray(r.tree_parents).tobytes()
                          + np.ascontiguousarray(r.path).tobytes()).hexdigest()[:16]


@pytest.fixture(scope="module")
def labyrinth():
    sc = scenarios.instance(scenarios.load_spec("labyrinth"), None)
    grid = OccupancyGrid(sc.occ, sc.resolution).inflate(2.0)
    s, g = tuple(sc.start), tuple(sc.goal)
    ref = np.array([s, ((s[0] + g[0]) / 2, (s[1] + g[1]) / 2), g], dtype=float)
    return PlanningProblem(grid, s, g, field=sc.planning_field(), domain_center=s, domain_radius=33.0,
                           reference_path=ref, start_heading=0.3)


# Trees of 1,500 iterations, seed 1, on labyrinth with a 33 m perceptual domain, before issue 34's
# changes (commit 85fb9e8): the defaults must still grow exactly these.
GOLDEN = {
    ("rrt-star", "current", 0.2, "adaptive"): "bfcb42f782541991",
    ("informed-rrt-star", "length", 0.2, "adaptive"): "d6ed14838b7c960c",
    ("ddrrt-star", "length", 0.7, "constant"): "745420be941c69d0",
    ("ddrrt-star", "current", 0.2, "adaptive"): "c4097abf652426a3",
    ("ddrrt-star", "current", 0.7, "adaptive"): "a019d3aac7c05e0d",
}


@pytest.mark.parametrize("key", sorted(GOLDEN))
def test_default_trees_are_those_of_before(labyrinth, key):
    alg, obj, png_p, dd = key
    params = PlannerParams(algorithm=alg, objective=obj, png_probability=png_p, dynamic_domain=dd)
    r = make_planner(alg, params, seed=1).solve(labyrinth, Termination.iterations(1500))
    assert _digest(r) == GOLDEN[key]


def test_compiled_hypot_is_cpythons(monkeypatch):
    from planner.png import hypot

    rng = np.random.default_rng(1)
    ab = rng.uniform(-100, 100, (50_000, 2)) * 10.0 ** rng.integers(-8, 4, (50_000, 1))
    assert all(hypot(a, b) == math.hypot(a, b) for a, b in ab)
    assert hypot(0.0, -0.0) == 0.0 and hypot(-math.inf, 1.0) == math.inf and math.isnan(hypot(math.nan, 1.0))


def test_compiled_pg_node_is_the_python_one_bit_for_bit(monkeypatch):
    import planner.png as png

    args_list = []
    rng = np.random.default_rng(3)
    for _ in range(3000):
        u = (float(rng.uniform(-50, 50)), float(rng.uniform(-50, 50)))
        p = (float(rng.uniform(-50, 50)), float(rng.uniform(-50, 50)))
        args_list.append((u, float(rng.uniform(-4, 4)), p, float(rng.uniform(-4, 4)), float(rng.uniform(0, 20)),
                          float(rng.uniform(0.5, 5)), 1e-3, 20))
    compiled = [pg_node(*a) for a in args_list]
    # the same source run by the interpreter, with the interpreter's math.hypot
    monkeypatch.setattr(png, "hypot", math.hypot)
    monkeypatch.setattr(png, "_wrap", png._wrap.py_func)
    monkeypatch.setattr(png, "_acos", png._acos.py_func)
    assert compiled == [pg_node.py_func(*a) for a in args_list]


def _grid_with_blob(cx, cy, r):
    occ = np.zeros((120, 120), dtype=bool)
    yy, xx = (np.mgrid[0:120, 0:120] + 0.5) * 0.5
    occ[np.hypot(xx - cx, yy - cy) <= r] = True
    return OccupancyGrid(occ, 0.5)


def test_a_pgnode_in_an_obstacle_is_moved_to_the_nearest_usable_cell():
    start, goal = (5.0, 30.0), (50.0, 30.0)
    free = OccupancyGrid(np.zeros((120, 120), dtype=bool), 0.5)
    base = PlanningProblem(free, start, goal, start_heading=0.6, domain_center=start, domain_radius=33.0)
    raw = DDRRTStar(PlannerParams()).png_node(base)
    assert raw is not None
    grid = _grid_with_blob(raw[0], raw[1], 4.0)  # an island right on the raw PGNode
    assert not grid.is_free(*raw) and grid.is_free(*start) and grid.is_free(*goal)
    problem = replace(base, grid=grid)
    assert DDRRTStar(PlannerParams()).png_node(problem) == raw  # the default: unchanged, in the island
    fixed = DDRRTStar(PlannerParams(png_repair=True)).png_node(problem)
    assert fixed is not None and grid.is_free(*fixed)
    assert math.hypot(fixed[0] - start[0], fixed[1] - start[1]) <= 33.0
    # the nearest usable cell centre, by brute force over the whole map
    labels = free_regions(grid)
    region = labels[grid.cell_of(*start)]
    rows, cols = grid.occ.shape
    best = math.inf
    for r in range(rows):
        for c in range(cols):
            x, y = (c + 0.5) * 0.5, (r + 0.5) * 0.5
            if not grid.occ[r, c] and labels[r, c] == region and math.hypot(x - start[0], y - start[1]) <= 33.0:
                best = min(best, math.hypot(x - raw[0], y - raw[1]))
    assert math.hypot(fixed[0] - raw[0], fixed[1] - raw[1]) == pytest.approx(best)
    assert best > 3.5  # it was inside the 4 m island


def test_repair_keeps_a_usable_pgnode_and_refuses_other_free_regions():
    occ = np.zeros((40, 40), dtype=bool)
    occ[:, 20] = True  # a wall: two free regions
    grid = OccupancyGrid(occ, 1.0)
    labels = free_regions(grid)
    box = np.array([0.0, 40.0, 0.0, 40.0])
    start_region = int(labels[grid.cell_of(5.0, 5.0)])
    assert _png.repair(7.3, 8.1, grid._u8, labels, 1.0, start_region, box, 0.0, 0.0, 0.0) == (7.3, 8.1)
    x, y = _png.repair(25.2, 10.2, grid._u8, labels, 1.0, start_region, box, 0.0, 0.0, 0.0)
    assert (x, y) == (19.5, 10.5)  # across the wall, back in the start's region


def test_a_reached_pgnode_is_never_drawn_again(labyrinth):
    params = PlannerParams(png_probability=0.7, objective="length")
    free = OccupancyGrid(np.zeros((100, 100), dtype=bool), 1.0)
    problem = PlanningProblem(free, (10.0, 50.0), (40.0, 50.0), start_heading=0.0, domain_center=(10.0, 50.0),
                              domain_radius=33.0)
    before = make_planner("ddrrt-star", params, seed=2).solve(problem, Termination.iterations(600))
    after = make_planner("ddrrt-star", replace(params, png_repair=True), seed=2).solve(
        problem, Termination.iterations(600))
    assert before.diagnostics["png_wasted"] > 100  # P = 0.7: most of the budget sampled an existing node
    assert after.diagnostics["png_reached"]
    assert after.diagnostics["png_wasted"] <= 1
    assert len(after.tree_nodes) > len(before.tree_nodes)


def test_turning_fan_refusals_count_as_failed_extensions():
    free = OccupancyGrid(np.zeros((100, 100), dtype=bool), 1.0)
    # heading away from the goal: the fan refuses most parents at first
    problem = PlanningProblem(free, (50.0, 50.0), (20.0, 50.0), start_heading=0.0)
    params = PlannerParams(objective="length")
    coll = make_planner("ddrrt-star", params, seed=1).solve(problem, Termination.iterations(800))
    turn = make_planner("ddrrt-star", replace(params, failed_extension="collision+turn"), seed=1).solve(
        problem, Termination.iterations(800))
    assert coll.diagnostics["failed_extensions"] == 0 and coll.diagnostics["failed_turns"] == 0  # no obstacles
    assert turn.diagnostics["failed_turns"] > 0
    assert turn.diagnostics["failed_extensions"] == turn.diagnostics["failed_turns"]
    assert turn.diagnostics["dynamic_domains"] > 0
    with pytest.raises(ValueError, match="failed_extension"):
        PlannerParams(failed_extension="sometimes")


def test_the_papers_constant_domain_cannot_act_in_a_33_m_domain_a_smaller_one_does(labyrinth):
    params = PlannerParams(objective="current", png_probability=0.2)
    assert params.dynamic_domain_start == 40.0 > params.perceptual_radius
    trees = {}
    for name, p in (("off", replace(params, dynamic_domain="off")),
                    ("paper", replace(params, dynamic_domain="constant")),
                    ("8m", replace(params, dynamic_domain="constant", dd_radius=8.0))):
        r = make_planner("ddrrt-star", p, seed=1).solve(labyrinth, Termination.iterations(1500))
        trees[name] = (_digest(r), r.samples_rejected, r.diagnostics["dynamic_domains"])
    assert trees["paper"] == trees["off"][:2] + (trees["paper"][2],)  # DD = DR = 40 m: the same tree
    assert trees["paper"][2] > 0  # although domains were set
    assert trees["8m"][0] != trees["off"][0]
    assert trees["8m"][1] > trees["off"][1]  # samples outside an 8 m domain are dropped


def test_alpha_y_against_the_resultant_of_current_and_wave_drift():
    free = OccupancyGrid(np.zeros((60, 60), dtype=bool), 1.0)
    current = GridField.uniform(0.5, 0.0)   # east
    drift = (0.0, 0.5)                       # waves push north as hard
    problem = PlanningProblem(free, (10.0, 10.0), (40.0, 40.0), field=current, wave_drift=drift)
    params = PlannerParams(objective="current", algorithm="rrt-star")
    north = np.array([[10.0, 10.0], [10.0, 40.0]])
    plain = make_planner("rrt-star", params, seed=1).solve(problem, Termination.iterations(800))
    nodrift = make_planner("rrt-star", params, seed=1).solve(replace(problem, wave_drift=None),
                                                              Termination.iterations(800))
    assert _digest(plain) == _digest(nodrift)  # alpha_y = "current" ignores the waves
    res = replace(params, alpha_y="resultant")
    both = make_planner("rrt-star", res, seed=1).solve(problem, Termination.iterations(800))
    resultant = GridField.uniform(0.5, 0.5)  # north-east: the goal lies straight downstream
    assert both.cost == pytest.approx(path_cost(both.path, resultant, res), rel=1e-12)
    assert path_cost(north, resultant, res) < path_cost(north, current, res)  # 45 deg off the stream, not 90
    with pytest.raises(ValueError, match="alpha_y"):
        PlannerParams(alpha_y="waves")


def test_campaign_runs_plan_alpha_y_against_the_resultant_when_asked():
    """`hil montecarlo --set planner.alpha_y="resultant"` gives the planners the wave drift of
    [waves] (it used to reach `hil plan` only): DDRRT*'s cycles change, the default ones do not."""
    from hil import experiment
    from hil.commands.plan import wave_drift

    online = (("local_iterations", 300), ("max_cycles", 2))
    plain = experiment.Task("labyrinth", 0, "ddrrt-star", 1, online_overrides=online)
    res = replace(plain, config_overrides=('planner.alpha_y="resultant"',))
    sc = experiment.scenario_instance("labyrinth", 1, 0)
    assert experiment._context(plain, sc).wave_drift is None
    drift = experiment._context(res, sc).wave_drift
    assert drift is not None and drift == wave_drift(experiment._settings(None, ()))
    assert 0.01 < math.hypot(*drift) < 0.1    # m/s: the default waves' mean drift, north-east
    a, b = experiment.run_task(plain), experiment.run_task(res)
    assert (a["search_iterations"], a["cost"]) != (b["search_iterations"], b["cost"])


def test_first_solution_is_measured_four_ways(labyrinth):
    r = make_planner("rrt-star", PlannerParams(objective="length"), seed=1).solve(
        labyrinth, Termination.iterations(1500))
    d = r.diagnostics
    assert r.status == "exact" or d["first_solution_iteration"] is None
    if r.status == "exact":
        assert 0 < d["first_solution_checks"] <= d["collision_checks"]
        assert 0 <= d["first_solution_cpu_s"] <= d["thread_cpu_s"] + 1e-3
        assert 0 < d["first_solution_iteration"] <= r.iterations
        assert r.time_to_first_solution_s is not None


def test_campaign_rows_measure_time_four_ways():
    from hil import experiment

    task = experiment.Task("labyrinth", 0, "ddrrt-star", 1,
                           online_overrides=(("local_iterations", 300), ("max_cycles", 3)))
    row = experiment.run_task(task)
    assert row["cycles"] == 3
    assert 0 < row["search_iterations"] <= row["iterations"]
    assert row["search_checks"] > 0
    assert 0 < row["time_cpu_s"] and 0 < row["time_s"] <= row["planning_time_s"]
    again = experiment.run_task(task)
    assert (again["search_iterations"], again["search_checks"]) == (row["search_iterations"], row["search_checks"])


def test_campaign_decision_rule():
    """The pre-registered rule: the 95 % interval of DDRRT* - RRT* excludes 0 in the paper's
    direction (reproduced), in the other (refuted), or not (no difference)."""
    from hil import campaign

    rng = np.random.default_rng(0)

    def rows(shift_cost, shift_cos):
        out = []
        for alg, dc, ds in (("rrt-star", 0.0, 0.0), ("ddrrt-star", shift_cost, shift_cos)):
            for i in range(40):
                out.append({"algorithm": alg, "reached": True, "run": i, "cost": 100 + dc + rng.normal(0, 2),
                            "sum_cos": 40 + ds + rng.normal(0, 2), "time_s": 1.0 + rng.normal(0, 0.1)})
        return out

    v = {x["claim"]: x for x in campaign.verdicts(rows(-10.0, 0.0))}
    assert v["cost"]["verdict"] == "reproduced" and v["cost"]["ci_high"] < 0
    assert v["Σcos α_y"]["verdict"] == "no difference"
    assert v["Σsin α_y"]["verdict"] == "not measured"
    v = {x["claim"]: x for x in campaign.verdicts(rows(+10.0, -10.0))}
    assert v["cost"]["verdict"] == "refuted" and v["Σcos α_y"]["verdict"] == "refuted"
    assert v["cost"]["relative_pct"] == pytest.approx(10.0, abs=2.0)
    cmd = campaign.command(campaign.CELLS[1], 20, Path("out"))
    assert cmd[:2] == ["hil", "montecarlo"] and "planner.png_repair=true" in cmd
    two = campaign.command(campaign.CELLS[0], 20, Path("out"), algorithms="rrt-star,ddrrt-star")
    assert two[two.index("--algorithms") + 1] == "rrt-star,ddrrt-star"
    table = campaign.summary_markdown({"a": campaign.verdicts(rows(-10.0, 0.0)),
                                       "b": campaign.verdicts(rows(+10.0, -10.0))})
    cost = next(line for line in table.splitlines() if line.startswith("| cost |"))
    assert "**R** -10 %" in cost.split("|")[2] and "✗ +10 %" in cost.split("|")[3]
    assert "| Σcos α_y (waypoints) | n/a | n/a |" in table and "40 / 40 of 40" in table


def test_whole_path_execution_sails_each_local_path_to_its_end():
    from hil import experiment
    from planner.cost import path_length

    def run(execution):
        task = experiment.Task("labyrinth", 0, "ddrrt-star", 1, detail=True,
                               online_overrides=(("execution", execution), ("local_iterations", 300),
                                                 ("max_cycles", 4)))
        return experiment.run_task(task)["_detail"]

    whole = run("whole-path")
    sailed = [c for c in whole.cycles if len(c.smooth_path) >= 2]
    assert len(sailed) >= 3
    for a, b in zip(sailed[:-1], sailed[1:], strict=False):
        assert path_length(a.travelled) == pytest.approx(path_length(a.smooth_path))
        assert (b.start.x, b.start.y) == pytest.approx(tuple(a.smooth_path[-1]))
    receding = run("receding")
    first = next(c for c in receding.cycles if len(c.smooth_path) >= 2)
    assert path_length(first.travelled) == pytest.approx(12.0)  # speed 2 m/s x cycle 6 s
    with pytest.raises(ValueError, match="execution"):
        from planner.online import OnlineParams
        OnlineParams(execution="sometimes")


def test_reusable_subtree_is_the_subtree_rooted_where_the_vessel_is():
    from planner.online import reusable_subtree

    # 0 -> 1 -> 2 -> {3, 5}; 0 -> 4; the vessel ends at node 2 (within the tolerance)
    nodes = np.array([[0, 0], [4, 0], [8, 0], [12, 0], [0, 4], [8, 4]], dtype=float)
    parents = np.array([-1, 0, 1, 2, 0, 2])
    x, p = reusable_subtree(nodes, parents, (8.0, 0.1), 0.25)
    assert x.tolist() == [[8.0, 0.1], [12, 0], [8, 4]] and p.tolist() == [-1, 0, 0]
    assert reusable_subtree(nodes, parents, (6.0, 0.0), 0.25) is None     # between nodes: nothing to reuse
    # breadth-first: every parent before its children, whatever the original numbering
    x, p = reusable_subtree(nodes[[0, 3, 2, 1, 4, 5]], np.array([-1, 2, 3, 0, 0, 2]), (4.0, 0.0), 0.25)
    assert x[0].tolist() == [4.0, 0.0] and all(p[i] < i for i in range(1, len(p)))
    assert sorted(map(tuple, x[1:].tolist())) == [(8.0, 0.0), (8.0, 4.0), (12.0, 0.0)]


def test_a_search_keeps_the_valid_nodes_of_its_initial_tree(labyrinth):
    """The seeded tree holds every node of the initial tree that is still valid (in the domain,
    in its parent's fan, collision free), each at its place, its parent the same node, its cost
    recomputed from the new root; an empty budget returns it unchanged."""
    params = PlannerParams(algorithm="rrt-star", objective="current")
    first = make_planner("rrt-star", params, seed=3).solve(labyrinth, Termination.iterations(600))
    from planner.online import reusable_subtree

    # the largest subtree of a node one level below the root: a fresh start there, heading free
    subtrees = [reusable_subtree(first.tree_nodes, first.tree_parents, tuple(first.tree_nodes[c]), 1e-9)
                for c in np.nonzero(first.tree_parents == 0)[0]]
    init = max((t for t in subtrees if t is not None), key=lambda t: len(t[0]))
    pos = tuple(init[0][0])
    assert len(init[0]) > 10
    problem = replace(labyrinth, start=pos, start_heading=None, domain_center=pos, initial_tree=init)
    seeded = make_planner("rrt-star", params, seed=3).solve(problem, Termination.iterations(0))
    kept = seeded.diagnostics["reused_nodes"]
    inside = np.hypot(*(init[0][1:] - np.asarray(pos)).T) <= 33.0
    assert 0 < kept <= int(inside.sum())
    assert seeded.iterations == 0
    # each kept node is an initial-tree node with the same parent node (the goal node, if a kept
    # node reached the goal, is the only other one)
    where = {tuple(v): i for i, v in enumerate(init[0].tolist())}
    assert len(seeded.tree_nodes) == 1 + kept + (seeded.status == "exact")
    for j in range(1, len(seeded.tree_nodes)):
        if tuple(seeded.tree_nodes[j].tolist()) == tuple(problem.goal):
            continue
        i = where[tuple(seeded.tree_nodes[j].tolist())]
        assert tuple(seeded.tree_nodes[seeded.tree_parents[j]].tolist()) == tuple(init[0][init[1][i]].tolist())
    # only the water within 6 m of the root left: the nodes beyond (or behind a wall) are dropped
    res = labyrinth.grid.resolution
    rows, cols = labyrinth.grid.occ.shape
    yy, xx = np.mgrid[0:rows, 0:cols]
    pond = np.hypot((xx + 0.5) * res - pos[0], (yy + 0.5) * res - pos[1]) <= 6.0
    walled = replace(problem, grid=OccupancyGrid(~pond, res), goal=(pos[0] + 0.5 * res, pos[1]))
    small = make_planner("rrt-star", params, seed=3).solve(walled, Termination.iterations(0))
    near = small.tree_nodes[1:1 + small.diagnostics["reused_nodes"]]
    assert small.diagnostics["reused_nodes"] < kept and np.all(np.hypot(*(near - np.asarray(pos)).T) <= 6.0)
    # a perceptual disc of 1 m keeps none of them
    tiny = replace(problem, domain_radius=1.0)
    assert make_planner("rrt-star", params, seed=3).solve(tiny, Termination.iterations(0)).diagnostics[
        "reused_nodes"] == 0
    # growing on from the seeded tree is deterministic per seed
    a = make_planner("rrt-star", params, seed=5).solve(problem, Termination.iterations(300))
    b = make_planner("rrt-star", params, seed=5).solve(problem, Termination.iterations(300))
    assert _digest(a) == _digest(b) and a.diagnostics["reused_nodes"] == kept


@pytest.mark.parametrize("algorithm", ["rrt-star", "ddrrt-star"])
def test_whole_path_with_tree_reuse_starts_each_cycle_from_the_last_subtree(algorithm):
    from hil import experiment

    def run(reuse):
        task = experiment.Task("labyrinth", 0, algorithm, 1, detail=True,
                               online_overrides=(("execution", "whole-path"), ("local_iterations", 300),
                                                 ("max_cycles", 5), ("tree_reuse", reuse)))
        return experiment.run_task(task)

    row = run(True)
    res = row["_detail"]
    sailed = [c for c in res.cycles if len(c.smooth_path) >= 2]
    assert len(sailed) >= 3
    assert res.cycles[0].reused_nodes == 0
    assert sum(c.reused_nodes for c in res.cycles[1:]) > 0
    for a, b in zip(res.cycles[:-1], res.cycles[1:], strict=False):
        if b.reused_nodes:   # the new tree's first nodes are the old tree's, rooted at the new start
            assert tuple(b.tree_nodes[0]) == (b.start.x, b.start.y)
            old = {tuple(v) for v in a.tree_nodes.tolist()}
            first = [tuple(v) for v in b.tree_nodes[1:2 + b.reused_nodes].tolist()
                     if tuple(v) != tuple(b.subgoal)][:b.reused_nodes]      # the goal node may join among them
            assert all(v in old for v in first)
    again = run(True)
    assert {k: row[k] for k in experiment.DETERMINISTIC} == {k: again[k] for k in experiment.DETERMINISTIC}
    fresh = run(False)["_detail"]
    assert all(c.reused_nodes == 0 for c in fresh.cycles)
    from planner.online import OnlineParams
    with pytest.raises(ValueError, match="tree_reuse"):
        OnlineParams(tree_reuse=True)          # receding: no node where the vessel stops
