"""The vehicle's mission progress (no I/O): each item is reported reached once."""

from __future__ import annotations

import numpy as np

from autopilot_bridge.vehicle import Mode, Vehicle, Waypoint


def test_each_item_is_reached_once_even_while_the_boat_stays_at_the_final_goal():
    mission = [Waypoint(0.0, 0.0, 3.0), Waypoint(50.0, 0.0, 3.0), Waypoint(100.0, 0.0, 3.0)]
    v = Vehicle(mission, armed=True, mode=Mode.AUTO, scenario_route=np.array([[0.0, 0.0], [100.0, 0.0]]))
    reported, finished = [], False
    for north in list(np.arange(0.0, 101.0, 0.5)) + [100.0] * 500:   # then station keeping at the goal
        v.update(north, 0.2)
        if v.complete and not finished:
            v.finish()  # what the autopilot does once, at the final goal
            finished = True
        reported += v.take_reached()
    assert reported == [0, 1, 2]
    assert v.complete
