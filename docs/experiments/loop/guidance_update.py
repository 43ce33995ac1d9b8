"""One LineOfSight.update (docs/performance.md, "The range scan and the guidance"): a 120-vertex
path of 0.3-0.6 m steps, the vessel beside vertex 10, 20,000 calls after a first one (which loads
the compiled kernels). Run it in each checkout to compare:
python docs/experiments/loop/guidance_update.py"""
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[3]))
from autopilot_bridge.guidance import LineOfSight  # noqa: E402

path = np.cumsum(np.random.default_rng(0).uniform(0.3, 0.6, (120, 2)), axis=0)
los = LineOfSight(path, 2.0, 1.0)
los.update(1.0, 1.0, 5.0)
for _ in range(3):
    t = time.perf_counter()
    for _ in range(20000):
        los.index = 0
        los.update(path[10, 0] + 0.1, path[10, 1] - 0.1, 5.0)
    print(f"LineOfSight.update: {(time.perf_counter() - t) / 20000 * 1e6:.1f} us")
