"""A local path is a ground track that the guidance steers as a course (Helm._control turns the
hull by the drift angle beta = atan2(v, u)), so each planning cycle starts along the course over
ground, not along the hull's heading. Started along the heading, a cross-current made every new
path begin turned by beta, the compensation turned the hull by beta again, and the vessel spiralled
off its route (labyrinth seeds 2 and 4 hit a wall, README "The HIL loop")."""

from __future__ import annotations

import math

import numpy as np
import pytest

from autopilot_bridge.computer_setup import AutopilotStats
from autopilot_bridge.navigation import NavState
from autopilot_bridge.obstacle_map import SensedObstacles
from autopilot_bridge.plan_handoff import PlanHandoff
from common.frames import map_to_ned
from hil.settings import load


class _Recorder:
    """The planner worker's submit side: keeps the requests instead of planning them."""

    def __init__(self) -> None:
        self.requests: list = []

    def submit(self, request) -> bool:
        self.requests.append(request)
        return True

    def wait_ready(self, timeout: float) -> bool:
        return True


def _submitted_heading(s: NavState) -> float:
    params = load().autopilot
    worker = _Recorder()
    handoff = PlanHandoff(worker, params, lockstep=False, seed=1, stats=AutopilotStats(), event=lambda t, m: None,
                          speed=lambda: params.cruise_speed)
    handoff.submit(s, SensedObstacles(np.zeros((10, 10), bool), 1.0), None, None)
    start = worker.requests[-1].problem
    return map_to_ned(start.x, start.y, start.heading)[2]


def _wrapped(a: float) -> float:
    return (a + math.pi) % (2.0 * math.pi) - math.pi


@pytest.mark.parametrize("psi, u, v", [(0.87, 1.0, -0.45), (-2.0, 1.2, 0.6), (3.0, 0.9, 0.0)])
def test_a_cycle_starts_along_the_course_over_ground(psi, u, v):
    s = NavState(t=10.0, x=20.0, y=30.0, psi=psi, u=u, v=v, r=0.0, gyro_bias=0.0, position_std=0.1)
    course = psi + math.atan2(v, u)
    assert abs(_wrapped(_submitted_heading(s) - course)) < 1e-12


def test_below_steerage_way_the_heading_is_the_course():
    params = load().autopilot
    u = 0.5 * params.min_turn_speed   # the velocity's direction is noise: no drift angle
    s = NavState(t=10.0, x=20.0, y=30.0, psi=1.0, u=u, v=0.4, r=0.0, gyro_bias=0.0, position_std=0.1)
    assert abs(_wrapped(_submitted_heading(s) - 1.0)) < 1e-12
