"""Digests of 64 planner trees on labyrinth (3 planners x objectives x P x domains x seeds x perceptual domain):
`python docs/experiments/ddrrt/issue34_golden.py OUT.json` at two commits, then compare the files."""
import hashlib
import json
import sys

import numpy as np

from hil import scenario as scenarios
from planner import PlannerParams, make_planner
from planner.gridmap import OccupancyGrid
from planner.problem import PlanningProblem
from planner.termination import Termination


def cases():
    spec = scenarios.load_spec("labyrinth")
    sc = scenarios.instance(spec, None)
    grid = OccupancyGrid(sc.occ, sc.resolution).inflate(2.0)
    field = sc.planning_field()
    s, g = sc.start, sc.goal
    # a perceptual-domain problem like the online loop's
    mid = ((s[0] + g[0]) / 2, (s[1] + g[1]) / 2)
    ref = np.array([s, mid, g], dtype=float)
    for alg in ("rrt-star", "informed-rrt-star", "ddrrt-star"):
        for obj in ("length", "current"):
            for P in (0.2, 0.7):
                for dd in ("off", "constant", "adaptive"):
                    if alg != "ddrrt-star" and (P != 0.2 or dd != "adaptive"):
                        continue
                    p = PlannerParams(algorithm=alg, objective=obj, png_probability=P, dynamic_domain=dd)
                    for seed in (1, 2):
                        for dom in (False, True):
                            kw = {}
                            if dom:
                                kw = dict(domain_center=tuple(s), domain_radius=33.0, reference_path=ref,
                                          start_heading=0.3)
                            pr = PlanningProblem(grid, tuple(s), tuple(g), field=field, **kw)
                            yield (alg, obj, P, dd, seed, dom), p, pr

out = {}
for key, p, pr in cases():
    r = make_planner(key[0], p, seed=key[4]).solve(pr, Termination.iterations(1500))
    h = hashlib.sha256(np.ascontiguousarray(r.tree_nodes).tobytes() + np.ascontiguousarray(r.tree_parents).tobytes()
                       + np.ascontiguousarray(r.path).tobytes()).hexdigest()[:16]
    out["|".join(map(str, key))] = [h, r.cost, r.diagnostics["failed_extensions"], r.samples_rejected]
json.dump(out, open(sys.argv[1], "w"), indent=0)
print(len(out))
