"""The simulator's range scan on harbour's true map (docs/performance.md, "The range scan and the
guidance"): `Rangefinder.true_ranges` (the ray march) and `Rangefinder.scan` (march, noise,
rounding) from 300 random poses, those in open water timed, three passes. Run it in each checkout
to compare: python docs/experiments/loop/range_scan.py"""
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[3]))
from hil import scenario as scenarios  # noqa: E402
from hil.settings import load  # noqa: E402
from simulator.rangefinder import Rangefinder, WorldMap  # noqa: E402

cfg = load()
scen = scenarios.instance(scenarios.load_spec("harbour"), None, cfg.current)
world = WorldMap(scen.truth_occ(), scen.resolution)
rf = Rangefinder(cfg.sensors.rangefinder, world, np.random.default_rng(1))
rows, cols = world.occ.shape
rng = np.random.default_rng(0)
poses = [(rng.uniform(0, rows * world.resolution), rng.uniform(0, cols * world.resolution), rng.uniform(-4, 4))
         for _ in range(300)]
free = [p for p in poses if not world.occ[int(p[0] / world.resolution), int(p[1] / world.resolution)]]
for _ in range(3):
    t = time.perf_counter()
    for p in free:
        rf.true_ranges(*p)
    march = (time.perf_counter() - t) / len(free) * 1e6
    t = time.perf_counter()
    for p in free:
        rf.scan(*p)
    scan = (time.perf_counter() - t) / len(free) * 1e6
    print(f"{len(free)} poses in open water: true_ranges {march:.1f} us, scan {scan:.1f} us")
