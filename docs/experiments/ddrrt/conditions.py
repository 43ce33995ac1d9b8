"""Where DDRRT* (eq. (12)) beats RRT* (length) and where not: one local planning query per
position along the labyrinth's reference path, varying current strength, clutter, horizon and budget."""

import json
import sys
from dataclasses import replace

import numpy as np

import planner
from hil import scenario as scenarios
from planner import PlannerParams, make_planner
from planner.field import GridField
from planner.gridmap import OccupancyGrid
from planner.metrics import path_metrics
from planner.online import resample
from planner.problem import PlanningProblem
from planner.termination import Termination

planner.warm_up()
sc = scenarios.load("labyrinth")
base = scenarios.planner_params(PlannerParams(), sc.planner_overrides)
lab = OccupancyGrid(sc.occ, sc.resolution).inflate(base.safety_radius)
empty = OccupancyGrid(np.zeros_like(sc.occ), sc.resolution).inflate(base.safety_radius)
f0 = sc.planning_field()
ref = np.asarray(sc.reference_path)
POS = [tuple(ref[i]) for i in (0, 4, 8, 12, 16, 20, 24)]
SEEDS = range(1, 7)


def scaled(k):
    return GridField(f0.vx * k, f0.vy * k, f0.resolution, f0.origin)


def run(grid, field, radius, iters):
    out = {a: {"cost": [], "sum_cos": [], "first_ms": [], "solved": 0, "n": 0} for a in ("rrt-star", "ddrrt-star")}
    for cx, cy in POS:
        d = np.hypot(ref[:, 0] - cx, ref[:, 1] - cy)
        k = int(np.argmin(d))
        while k < len(ref) - 1 and np.hypot(ref[k, 0] - cx, ref[k, 1] - cy) < radius - 5:
            k += 1
        goal = tuple(ref[k])
        prob = PlanningProblem(grid, (cx, cy), goal, None, field, ref, None, (cx, cy), radius)
        pair = {}
        for alg, obj in (("rrt-star", "length"), ("ddrrt-star", "current")):
            p = replace(base, algorithm=alg, objective=obj, perceptual_radius=radius)
            for s in SEEDS:
                r = make_planner(alg, p, s).solve(prob, Termination.iterations(iters))
                pair[(alg, s)] = r
        for s in SEEDS:
            if all(pair[(a, s)].status == "exact" for a in out):
                for a in out:
                    r = pair[(a, s)]
                    m = path_metrics(resample(r.path, 2.0), field, grid, replace(base, objective="current"), 1.0)
                    out[a]["cost"].append(m["cost"])
                    out[a]["sum_cos"].append(m["sum_cos"])
                    out[a]["first_ms"].append(r.time_to_first_solution_s * 1e3)
            for a in out:
                out[a]["n"] += 1
                out[a]["solved"] += pair[(a, s)].status == "exact"
    R, D = out["rrt-star"], out["ddrrt-star"]

    def pct(k):
        return (np.mean(D[k]) - np.mean(R[k])) / abs(np.mean(R[k])) * 100

    return {
        "pairs": len(R["cost"]),
        "solved_rrt": R["solved"],
        "solved_dd": D["solved"],
        "n": R["n"],
        "cost_pct": pct("cost"),
        "sum_cos_pct": pct("sum_cos"),
        "first_pct": pct("first_ms"),
        "first_ms_rrt": float(np.median(R["first_ms"])),
        "first_ms_dd": float(np.median(D["first_ms"])),
    }


rows = []


def show(label, res):
    rows.append((label, res))
    print(
        f"{label:34} pairs {res['pairs']:3d} solved {res['solved_rrt']:3d}/{res['solved_dd']:3d} of {res['n']:3d}  "
        f"cost {res['cost_pct']:+6.1f}%  sum_cos {res['sum_cos_pct']:+7.1f}%  first {res['first_pct']:+7.1f}% "
        f"(median {res['first_ms_rrt']:.2f} vs {res['first_ms_dd']:.2f} ms)",
        flush=True,
    )


show("default (x1, labyrinth, 33 m, 1500)", run(lab, f0, 33.0, 1500))
for k in (0.0, 0.5, 2.0, 4.0):
    show(f"current x{k:g}", run(lab, scaled(k) if k else None, 33.0, 1500))
show("clutter: open water", run(empty, f0, 33.0, 1500))
for r in (20.0, 50.0):
    show(f"horizon {r:g} m", run(lab, f0, r, 1500))
for it in (300, 6000):
    show(f"budget {it} iterations", run(lab, f0, 33.0, it))
json.dump(rows, open(sys.argv[1] if len(sys.argv) > 1 else "/tmp/ddrrt/conditions.json", "w"), indent=1)
