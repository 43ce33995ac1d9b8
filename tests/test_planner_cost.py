"""Eqs. (11)-(12), the encounter angle and the gridded current."""

import math

import numpy as np
import pytest

from planner.cost import cost_distance, esd, min_cost_factor, path_cost, segment_cost
from planner.field import GridField, encounter_angle
from planner.params import PlannerParams

# Hand values, D_alpha = 1, gamma_alpha = 0.1, Ed = 10 m, DR = 40 m:
#   alpha = 0:    x = cos 0 - 0.1 sin 0 = 1            D_C = 10 / (1 + e)        = 2.689414
#                                                     ESD = 40 / (1 + e^-1)     = 29.242343
#   alpha = pi/3: x = 0.5 - 0.1 * 0.8660254 = 0.4133975
#                                                     D_C = 10 / (1 + 1.511929) = 3.980978
#                                                     ESD = 40 / (1 + 0.661407) = 24.076090
#   alpha = pi/2: x = -0.1                            D_C = 10 / (1 + 0.904837) = 5.249792
#                                                     ESD = 40 / (1 + 1.105171) = 19.000833
#   alpha = pi:   x = -1                              D_C = 10 / (1 + e^-1)     = 7.310586
#                                                     ESD = 40 / (1 + e)        = 10.757657
HAND = [
    (0.0, 2.689414, 29.242343),
    (math.pi / 3, 3.980978, 24.076090),
    (math.pi / 2, 5.249792, 19.000833),
    (math.pi, 7.310586, 10.757657),
]


@pytest.mark.parametrize("alpha,dc,e", HAND)
def test_eq11_eq12_hand_values(alpha, dc, e):
    assert cost_distance(10.0, alpha) == pytest.approx(dc, abs=1e-6)
    assert esd(math.inf, alpha, 40.0) == pytest.approx(e, abs=1e-6)


def test_esd_takes_the_dynamic_domain_when_smaller():
    assert esd(5.0, 0.0, 40.0) == 5.0
    assert esd(math.inf, math.nan, 40.0) == 40.0  # no current: D_alpha * DR


def test_cost_distance_is_euclidean_with_large_d_alpha_or_no_current():
    assert cost_distance(10.0, math.pi, d_alpha=10.0) == 10.0  # the min picks Ed
    assert cost_distance(10.0, math.nan) == 10.0


def test_min_cost_factor_is_a_lower_bound():
    f = min_cost_factor()
    alphas = np.linspace(0, math.pi, 1001)
    ratios = [cost_distance(1.0, a) for a in alphas]
    assert f == pytest.approx(min(ratios), abs=1e-9)


def test_encounter_angle():
    assert encounter_angle(1, 0, 2, 0) == pytest.approx(0.0)
    assert encounter_angle(1, 0, -2, 0) == pytest.approx(math.pi)
    assert encounter_angle(0, 1, 3, 0) == pytest.approx(math.pi / 2)
    assert math.isnan(encounter_angle(1, 0, 0, 0))
    a = encounter_angle(np.array([1.0, 0.0]), np.array([0.0, 1.0]), 1.0, 0.0)
    assert a == pytest.approx([0.0, math.pi / 2])


def test_segment_cost_follows_the_current():
    p = PlannerParams(objective="current")
    east = GridField.uniform(0.5, 0.0)
    down = segment_cost((0, 0), (10, 0), east, p)
    up = segment_cost((10, 0), (0, 0), east, p)
    assert down == pytest.approx(10 / (1 + math.e), rel=1e-9)
    assert up == pytest.approx(10 / (1 + math.exp(-1)), rel=1e-9)
    # long segment: split into pieces <= step, same total in a uniform field
    assert segment_cost((0, 0), (37, 0), east, p) == pytest.approx(37 / (1 + math.e), rel=1e-9)


def test_no_field_or_length_objective_is_euclidean():
    path = np.array([[0, 0], [3, 4], [3, 10]])
    assert path_cost(path, None, PlannerParams()) == pytest.approx(11.0)
    east = GridField.uniform(1.0, 0.0)
    assert path_cost(path, east, PlannerParams(objective="length")) == pytest.approx(11.0)
    zero = GridField.uniform(0.0, 0.0)
    assert path_cost(path, zero, PlannerParams(objective="current")) == pytest.approx(11.0)


def test_grid_field_bilinear_and_sample():
    f = GridField.sample(lambda x, y: (x + 2 * y, -y), 10.0, 10.0, 1.0)
    vx, vy = f(2.5, 3.25)
    assert vx == pytest.approx(2.5 + 6.5)
    assert vy == pytest.approx(-3.25)
    vx, vy = f(np.array([0.0, 100.0]), np.array([0.0, 0.0]))  # clamped outside
    assert vx == pytest.approx([0.0, 10.0])
