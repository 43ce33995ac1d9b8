"""The [planner] section of configs/default.toml and the PlannerParams schema agree."""

import dataclasses

import pytest

from hil.errors import ConfigError
from hil.settings import load
from planner.params import PlannerParams


def test_default_toml_matches_the_dataclass_defaults():
    assert load().planner == PlannerParams()


def test_every_field_is_documented_with_bounds_where_numeric():
    for f in dataclasses.fields(PlannerParams):
        assert f.metadata.get("help"), f.name


@pytest.mark.parametrize("override,message", [
    ("planner.algorithm=\"prm\"", "planner.algorithm"),
    ("planner.goal_bias=1.5", "planner.goal_bias"),
    ("planner.step=0", "planner.step"),
    ("planner.k_nearest=0", "planner.k_nearest"),
])
def test_bad_values_are_one_line_config_errors(override, message):
    with pytest.raises(ConfigError, match=message):
        load(None, [override])


def test_derived_quantities():
    p = PlannerParams()
    assert p.dynamic_domain_radius == pytest.approx(10 * 2.0 * 2.0)
    assert p.turning_radius == pytest.approx(3.0)
    assert p.max_turn_angle == pytest.approx(4.0 / 3.0)
    assert PlannerParams(turn_radius_factor=0.0).max_turn_angle == pytest.approx(3.141592653589793)
