# Run: python docs/experiments/ddrrt/unseen_maps.py 2   (maps written to /tmp/ddrrt/maps)
"""Random maps hil plan never saw: discs and a bug trap, 200 x 200 cells at 0.5 m; hil plan through the CLI
at 0.2 s and 1 s against hil.optimum's exact shortest path on the same inflated grid."""

import json
import os
import subprocess
import sys
import time

import numpy as np

from hil.optimum import shortest_path
from planner.gridmap import OccupancyGrid

os.makedirs("/tmp/ddrrt/maps", exist_ok=True)

R = 0.5
N = 200


def discs(rng):
    occ = np.zeros((N, N), bool)
    yy, xx = np.mgrid[0:N, 0:N] * R + R / 2
    for _ in range(rng.integers(15, 30)):
        cx, cy, r = rng.uniform(10, 90), rng.uniform(10, 90), rng.uniform(2, 7)
        occ |= (xx - cx) ** 2 + (yy - cy) ** 2 <= r * r
    return occ, (4.0, 4.0), (96.0, 96.0)


def bugtrap(rng):
    occ = np.zeros((N, N), bool)
    cx, cy = rng.uniform(40, 60), rng.uniform(40, 60)
    a = rng.uniform(12, 20)
    t = 2.0

    def c(v):
        return int(v / R)

    occ[c(cy - a) : c(cy + a), c(cx + a - t) : c(cx + a)] = True  # back wall (east)
    occ[c(cy + a - t) : c(cy + a), c(cx - a) : c(cx + a)] = True  # north arm
    occ[c(cy - a) : c(cy - a + t), c(cx - a) : c(cx + a)] = True  # south arm
    return occ, (cx, cy), (95.0, cy + rng.uniform(-5, 5))


out = []
for kind, gen in (("discs", discs), ("bugtrap", bugtrap)):
    for m in range(int(sys.argv[1]) if len(sys.argv) > 1 else 3):
        rng = np.random.default_rng(1000 + m)
        occ, s, g = gen(rng)
        path = f"/tmp/ddrrt/maps/{kind}{m}.npy"
        np.save(path, occ)
        infl = OccupancyGrid(occ, R).inflate(2.0)
        if not (infl.is_free(*s) and infl.is_free(*g)):
            continue
        opt = shortest_path(infl.occ, R, s, g).length
        for alg in ("rrt-star", "ddrrt-star"):
            for B in (0.2, 1.0):
                for seed in (1, 2, 3):
                    t = time.monotonic()
                    p = subprocess.run(
                        [
                            sys.executable,
                            "-m",
                            "hil",
                            "plan",
                            "--map",
                            path,
                            "--resolution",
                            "0.5",
                            "--start",
                            f"{s[0]},{s[1]}",
                            "--goal",
                            f"{g[0]},{g[1]}",
                            "--algorithm",
                            alg,
                            "--objective",
                            "length",
                            "--deadline",
                            str(B),
                            "--seed",
                            str(seed),
                            "--json",
                        ],
                        capture_output=True,
                        text=True,
                    )
                    wall = time.monotonic() - t
                    j = json.loads(p.stdout) if p.stdout.strip() else {}
                    ratio = (j["length"] / opt) if j.get("status") == "exact" else float("inf")
                    out.append(
                        (
                            kind,
                            m,
                            alg,
                            B,
                            seed,
                            p.returncode,
                            j.get("status"),
                            ratio,
                            j.get("time_to_first_solution_s"),
                            j.get("planning_time_s"),
                            j.get("setup_s"),
                            j.get("warm_up_s"),
                            wall,
                        )
                    )
                    print(*[f"{v:.4f}" if isinstance(v, float) else v for v in out[-1]], flush=True)
