"""The independent judge of eq. (12) (hil/flow_optimum.py): the shortest path when the current is
off (against the exact visibility-graph optimum of hil/optimum.py), hand values in a uniform
current, and a route that takes the longer channel with the stream."""

from __future__ import annotations

import math

import numpy as np
import pytest

from hil import scenario as scenarios
from hil.flow_optimum import FlowJudge
from hil.optimum import shortest_path
from planner.gridmap import OccupancyGrid

F_DOWN = 1.0 / (1.0 + math.e)            # eq. (12) per metre straight downstream (D_alpha = 1)
F_UP = 1.0 / (1.0 + math.exp(-1.0))      # straight upstream


@pytest.mark.parametrize("name", ["labyrinth", "harbour", "bench_bugtrap"])
def test_without_a_current_the_judge_finds_the_exact_shortest_path(name):
    sc = scenarios.instance(scenarios.load_spec(name), None)
    grid = OccupancyGrid(sc.occ, sc.resolution).inflate(2.0)
    exact = shortest_path(grid.occ, sc.resolution, sc.start, sc.goal)
    judge = FlowJudge(grid.occ, sc.resolution, None)
    judged = judge.optimum(sc.start, sc.goal)
    assert exact.length * (1 - 1e-9) <= judged.cost <= exact.length * 1.002  # measured: +0.10 to +0.14 %
    assert judged.cost <= judged.lattice_cost  # refinement only lowers the lattice's cost
    assert judged.cost == pytest.approx(sum(np.hypot(*np.diff(judged.path, axis=0).T)))
    assert np.allclose(judged.path[0], sc.start) and np.allclose(judged.path[-1], sc.goal)
    assert all(judge.clear(a, b) for a, b in zip(judged.path[:-1], judged.path[1:], strict=True))


def _uniform(vx, vy):
    return lambda x, y: (np.full(np.shape(x), vx), np.full(np.shape(y), vy))


def test_uniform_current_hand_values():
    occ = np.zeros((40, 80), dtype=bool)
    judge = FlowJudge(occ, 0.5, _uniform(0.5, 0.0))
    down = judge.optimum((2.0, 10.0), (38.0, 10.0))
    up = judge.optimum((38.0, 10.0), (2.0, 10.0))
    assert down.cost == pytest.approx(36.0 * F_DOWN, rel=1e-9)
    assert up.cost == pytest.approx(36.0 * F_UP, rel=1e-9)
    # the cost depends on the current's direction, never its strength (D_alpha = 1)
    assert FlowJudge(occ, 0.5, _uniform(2.0, 0.0)).optimum((2.0, 10.0), (38.0, 10.0)).cost == pytest.approx(down.cost)


def test_the_optimum_takes_the_longer_channel_with_the_stream():
    """An island with a stream east in the north channel and west in the south one; the start and
    goal lie nearer the south channel: the shortest path goes south, eq. (12)'s optimum north."""
    occ = np.zeros((80, 120), dtype=bool)   # 60 m x 40 m at 0.5 m
    occ[30:60, 30:90] = True                # island x 15-45 m, y 15-30 m
    judge_still = FlowJudge(occ, 0.5, None)
    start, goal = (3.0, 14.0), (57.0, 14.0)

    def stream(x, y):
        return np.where(y > 22.5, 0.5, -0.5) * np.ones(np.shape(x)), np.zeros(np.shape(y))

    judge = FlowJudge(occ, 0.5, stream)
    best = judge.optimum(start, goal)
    shortest = judge_still.optimum(start, goal)
    assert np.max(shortest.path[:, 1]) < 15.0 and np.max(best.path[:, 1]) > 30.0
    assert best.cost < 0.8 * judge.path_cost(shortest.path)
