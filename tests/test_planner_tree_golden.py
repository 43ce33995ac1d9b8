"""The compiled tree kernel grows the trees it grew before its state was named (issue 30 point 5):
every node, parent, cost, heading and dynamic domain, and every counter, bit for bit, for RRT*,
Informed RRT* and DDRRT* with and without issue 34's switches, on labyrinth and on a random map.

The golden record ``tests/data/tree_golden.json`` holds SHA-256 digests of the exact bytes of each
array; it was written by ``python tests/test_planner_tree_golden.py`` on the kernel of before (the
commit that added this file), and must never be regenerated to make this test pass."""

from __future__ import annotations

import hashlib
import json
import math
import sys
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from planner import PlannerParams, make_planner
from planner import core as planner_core
from planner.gridmap import OccupancyGrid
from planner.problem import PlanningProblem
from planner.termination import Termination

GOLDEN = Path(__file__).parent / "data" / "tree_golden.json"


def _labyrinth() -> PlanningProblem:
    from hil import scenario as scenarios

    sc = scenarios.instance(scenarios.load_spec("labyrinth"), None)
    grid = OccupancyGrid(sc.occ, sc.resolution).inflate(2.0)
    s = (float(sc.start[0]), float(sc.start[1]))
    g = (float(sc.goal[0]), float(sc.goal[1]))
    ref = np.array([s, ((s[0] + g[0]) / 2, (s[1] + g[1]) / 2), g], dtype=float)
    return PlanningProblem(grid, s, g, field=sc.planning_field(), domain_center=s, domain_radius=33.0,
                           reference_path=ref, start_heading=0.3, wave_drift=(0.15, -0.1))


def _blocks() -> PlanningProblem:
    """60 m x 40 m of random blocks, a swirling current, no perceptual domain, no start heading."""
    rng = np.random.default_rng(4)
    occ = np.zeros((80, 120), dtype=bool)
    for _ in range(25):
        r, c = rng.integers(0, 72), rng.integers(0, 112)
        occ[r:r + rng.integers(2, 8), c:c + rng.integers(2, 8)] = True
    occ[:6, :6] = False
    occ[-6:, -6:] = False

    def field(x, y):
        return 0.4 * np.sin(y / 7.0), 0.3 * np.cos(x / 9.0)

    return PlanningProblem(OccupancyGrid(occ, 0.5), (1.5, 1.5), (58.0, 38.0), field=field)


# (name, map, algorithm, iterations, parameter overrides)
CASES: list[tuple[str, str, str, int, dict]] = []
for _alg in ("rrt-star", "informed-rrt-star", "ddrrt-star"):
    for _obj in ("length", "current"):
        CASES.append((f"{_alg}-{_obj}-lab", "labyrinth", _alg, 2500, {"objective": _obj}))
        CASES.append((f"{_alg}-{_obj}-blocks", "blocks", _alg, 2500, {"objective": _obj}))
    CASES.append((f"{_alg}-nofan-lab", "labyrinth", _alg, 2500, {"turn_radius_factor": 0.0}))
CASES += [
    ("informed-long-length-blocks", "blocks", "informed-rrt-star", 20000, {"objective": "length"}),
    ("informed-long-current-lab", "labyrinth", "informed-rrt-star", 12000, {"objective": "current"}),
    ("rrt-long-length-lab", "labyrinth", "rrt-star", 12000, {"objective": "length"}),
    ("ddrrt-png-repair", "labyrinth", "ddrrt-star", 3000, {"png_repair": True, "png_probability": 0.5}),
    ("ddrrt-failed-turn", "labyrinth", "ddrrt-star", 3000,
     {"failed_extension": "collision+turn", "turn_radius_factor": 3.0}),
    ("ddrrt-dd-radius", "labyrinth", "ddrrt-star", 3000, {"dd_radius": 8.0, "dynamic_domain": "constant"}),
    ("ddrrt-dd-off", "blocks", "ddrrt-star", 3000, {"dynamic_domain": "off"}),
    ("ddrrt-resultant", "labyrinth", "ddrrt-star", 3000, {"alpha_y": "resultant"}),
    ("ddrrt-all-switches", "labyrinth", "ddrrt-star", 3000,
     {"png_repair": True, "failed_extension": "collision+turn", "dd_radius": 8.0, "alpha_y": "resultant",
      "turn_radius_factor": 3.0, "png_probability": 0.5}),
    ("ddrrt-kgrowth", "blocks", "ddrrt-star", 3000, {"k_growth": 4.48}),
    ("ddrrt-exact-stop", "blocks", "ddrrt-star", 20000, {"objective": "length"}),
    ("rrt-full", "blocks", "rrt-star", 5000, {"max_nodes": 400}),
]
STOP_ON_EXACT = {"ddrrt-exact-stop"}


def _digest(a: np.ndarray) -> str:
    return hashlib.sha256(np.ascontiguousarray(a).tobytes()).hexdigest()


def _capture(planner) -> dict[str, np.ndarray]:
    """Wrap the planner's result builder to keep the final tree arrays of the kernel."""
    kept: dict[str, np.ndarray] = {}
    inner = planner._result

    def spy(problem, t0, tree: planner_core._tree.Tree, st, *rest):
        n = int(st["n"])
        kept.update(nodes=tree.X[:n].copy(), parents=tree.parent[:n].copy(), costs=tree.cost[:n].copy(),
                    dd=tree.dd[:n].copy())
        return inner(problem, t0, tree, st, *rest)

    planner._result = spy
    return kept


def record(name: str, problems: dict[str, PlanningProblem]) -> dict[str, object]:
    case = next(c for c in CASES if c[0] == name)
    _, map_name, alg, iters, over = case
    params = replace(PlannerParams(algorithm=alg), **over)
    planner = make_planner(alg, params, seed=3)
    kept = _capture(planner)
    term = Termination.iterations(iters)
    if name in STOP_ON_EXACT:
        term = Termination.any_of(term, Termination.exact_solution())
    r = planner.solve(problems[map_name], term)
    d = r.diagnostics
    out: dict[str, object] = {k: _digest(v) for k, v in kept.items()}
    out.update(n=len(kept["nodes"]), status=r.status, path=_digest(r.path), iterations=r.iterations,
               rejected=r.samples_rejected, cost=float(r.cost).hex())
    for key in ("collision_checks", "first_solution_iteration", "first_solution_checks", "dynamic_domains",
                "failed_extensions", "failed_turns", "png_reached", "png_wasted"):
        out[key] = d[key]
    out["tree_cost"] = float(d["tree_cost"]).hex() if math.isfinite(d["tree_cost"]) else "inf"
    return out


@pytest.fixture(scope="module")
def problems() -> dict[str, PlanningProblem]:
    return {"labyrinth": _labyrinth(), "blocks": _blocks()}


@pytest.fixture(scope="module")
def golden() -> dict:
    return json.loads(GOLDEN.read_text())


@pytest.mark.parametrize("name", [c[0] for c in CASES])
def test_tree_is_bit_identical_to_the_golden_record(name, problems, golden):
    assert record(name, problems) == golden[name]


def test_the_cases_exercise_what_they_name(golden):
    """The record is not trivial: trees grew, the goal was reached, the switches acted."""
    assert all(g["n"] > 50 for g in golden.values())
    assert sum(g["status"] == "exact" for g in golden.values()) >= 10  # blocks: the exact goal connection
    assert golden["ddrrt-failed-turn"]["failed_turns"] > 0
    assert golden["ddrrt-png-repair"]["png_reached"] or golden["ddrrt-png-repair"]["png_wasted"] == 0
    assert golden["rrt-full"]["n"] == 399  # full: one slot kept for the goal
    assert golden["ddrrt-exact-stop"]["iterations"] < 20000


if __name__ == "__main__":
    probs = {"labyrinth": _labyrinth(), "blocks": _blocks()}
    rec = {c[0]: record(c[0], probs) for c in CASES}
    GOLDEN.write_text(json.dumps(rec, indent=1, sort_keys=True) + "\n")
    print(f"wrote {len(rec)} cases to {GOLDEN}", file=sys.stderr)
