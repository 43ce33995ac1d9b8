"""The current as the run met it (common/current_tally.py): the tally's arithmetic, the source's name,
and the simulator's count of the current at its hull."""

from __future__ import annotations

import math

import pytest

from common.current_params import CurrentParams
from common.current_tally import CurrentTally, describe
from hil.assembly.simulator import simulator_settings
from hil.settings import load
from simulator.core import SimulatorCore


def test_the_tally_gives_the_mean_vector_the_mean_speed_and_the_largest():
    t = CurrentTally()
    assert t.stats() is None
    for north, east in ((0.3, 0.4), (-0.3, 0.4), (0.0, 0.0), (math.nan, 1.0), (math.inf, 0.0)):
        t.add(north, east)
    s = t.stats()
    assert s is not None and s["samples"] == 3          # the two non-finite samples are not counted
    assert s["mean_north_m_s"] == pytest.approx(0.0)
    assert s["mean_east_m_s"] == pytest.approx(0.8 / 3, abs=1e-4)
    assert s["mean_speed_m_s"] == pytest.approx(1.0 / 3, abs=1e-4)   # speeds 0.5, 0.5, 0
    assert s["max_speed_m_s"] == pytest.approx(0.5)


def test_the_source_is_named_as_configured():
    base = load(None, []).current
    assert describe(base) == "eq. (13)"
    assert describe(CurrentParams(**{**base.__dict__, "enabled": False})) == "none"
    assert describe(CurrentParams(**{**base.__dict__, "uniform": (0.5, -1.0)})) == "uniform [0.5, -1] m/s east, north"
    assert describe(CurrentParams(**{**base.__dict__, "file": "tide.nc"})) == "file tide.nc"


@pytest.mark.parametrize("overrides, north, east", [
    (["current.uniform=[0.3, -0.4]"], -0.4, 0.3),    # [east, north]
    (["current.enabled=false"], 0.0, 0.0),
])
def test_the_simulator_counts_the_current_at_its_hull_once_a_frame(overrides, north, east):
    core = SimulatorCore(simulator_settings(load(None, ["waves.enabled=false", *overrides])))
    for _ in range(250):
        core.step()
    s = core.current_felt.stats()
    assert s is not None and s["samples"] == 250
    assert (s["mean_north_m_s"], s["mean_east_m_s"]) == pytest.approx((north, east), abs=1e-9)
    assert s["max_speed_m_s"] == pytest.approx(math.hypot(north, east), abs=1e-9)


def test_the_simulator_counts_eq13_where_the_hull_is():
    """eq. (13) varies in space and time: the tally is the source's value at the hull's own positions."""
    # on the jet's axis (50 m east of the origin, configs/default.toml), where it runs at ~0.1 m/s
    core = SimulatorCore(simulator_settings(load(None, ["waves.enabled=false", "sim.initial.y=45.0"])))
    expected = CurrentTally()
    for _ in range(300):
        core.step()
        expected.add(*core.current.velocity_at(core.state[0], core.state[1], core.t))
    assert core.current_felt.stats() == expected.stats()
    felt = core.current_felt.stats()
    assert felt is not None and felt["mean_speed_m_s"] > 0.05
