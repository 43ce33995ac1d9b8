"""DDRRT*'s k: fixed as in the paper, or growing like k-nearest RRT* (asymptotic optimality)."""

from __future__ import annotations

import dataclasses
import math

import numpy as np

from planner import make_planner
from planner.gridmap import OccupancyGrid
from planner.params import PlannerParams
from planner.problem import PlanningProblem
from planner.termination import Termination


def _median_ratio(k_growth: float, seeds=range(5), iterations=20000) -> float:
    grid = OccupancyGrid(np.zeros((200, 200), dtype=bool), 0.5)  # 100 m x 100 m, empty
    problem = PlanningProblem(grid=grid, start=(5.0, 5.0), goal=(95.0, 95.0))
    optimum = math.hypot(90.0, 90.0)
    ratios = []
    for seed in seeds:
        params = dataclasses.replace(PlannerParams(), objective="length", turn_radius_factor=0.0,
                                     png_probability=0.0, k_growth=k_growth, seed=seed)
        result = make_planner("ddrrt-star", params).solve(problem, Termination.iterations(iterations))
        assert result.status == "exact"
        ratios.append(result.length / optimum)
    return float(np.median(ratios))


def test_growing_k_converges_where_a_fixed_k_stalls():
    fixed = _median_ratio(0.0)
    growing = _median_ratio(2.0)
    assert growing < 1.01, growing
    assert growing < fixed, (growing, fixed)
