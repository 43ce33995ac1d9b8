"""`hil bench frame`: the in-process profile of an autopilot frame runs and accounts for the frame.

No timing is asserted (the machine is shared): only that the closed loop ran, the parts of the
frame add up to the profiled whole, and both navigation filters were measured.
"""

from __future__ import annotations

import json

import pytest


@pytest.mark.parametrize("flt", ["fast", "filterpy"])
def test_bench_frame_json(hil, flt):
    p = hil("bench", "frame", "--steps", "150", "--top", "5", "--json", "--set", f'navigation.filter="{flt}"')
    assert p.returncode == 0, p.stderr
    d = json.loads(p.stdout)
    assert d["navigation_filter"] == flt
    assert d["steps"] == 150 and 0 <= d["frames_waiting_for_planner"] < 150
    assert 0 < d["frame_us"]["p50"] <= d["frame_us"]["p99"]
    parts = {r["part"].split(" (")[0]: r for r in d["profile"]}
    top_level = [r for r in d["profile"] if not r["part"].startswith("  ")]
    # The rows are disjoint calls: none double-counted, so the rest ("other") is not negative.
    assert all(r["share"] >= 0.0 for r in top_level), top_level
    assert parts["navigation EKF: predicts + updates"]["us_per_frame"] > 0
    assert parts["MAVLink decode + plausibility"]["us_per_frame"] > 0
    assert set(d["navigation_alone_us_per_frame"]) == {"filterpy", "fast"}
    assert len(d["top_own_time"]) == 5


def test_bench_frame_bad_arguments(hil_main):
    p = hil_main("bench", "frame", "--steps", "10")
    assert p.returncode == 2 and "Traceback" not in p.stderr
    p = hil_main("bench", "frame", "--scenario", "random", "--steps", "100")
    assert p.returncode == 2 and "Traceback" not in p.stderr
