"""The COLREGs judge (hil.encounter_report) takes manoeuvres against the boat's planned route: her first
turn onto the route is no manoeuvre (issue 32: a run scored 0 % for it)."""

from __future__ import annotations

import math

import numpy as np

from hil.encounter_report import EncounterJudge
from hil.settings import load


def _overtaken(route):
    """The boat starts 12 deg off her eastward route and turns onto it within 3 s; a faster ship
    overtakes her from astern 8 m to port (she is the stand-on vessel) and she stands on."""
    cfg = load()
    judge = EncounterJudge(cfg.vessel.L, cfg.vessel.W, cfg.colregs, route=route)
    own, n, e = {}, 0.0, 0.0
    dt = 0.1
    for k in range(601):
        t = k * dt
        course = math.radians(78.0 + 12.0 * min(max((t - 1.5) / 1.5, 0.0), 1.0))
        vn, ve = 1.5 * math.cos(course), 1.5 * math.sin(course)
        t_us = int(round(t * 1e6))
        own[t_us] = (n, e, vn, ve)
        judge.add(t_us, (n, e, course), 412000001, "OVERTAKER", (4.0, 4.0, 1.5, 1.5),
                  8.0, -60.0 + 3.0 * t, math.pi / 2, 3.0)
        n, e = n + vn * dt, e + ve * dt
    (enc,) = judge.report(own)
    return enc


def test_turning_onto_the_route_is_no_manoeuvre():
    enc = _overtaken(np.array([[0.0, 0.0], [300.0, 0.0]]))     # map frame: x east, y north
    assert enc["role"] == "stand-on" and enc["risk_time_s"] < 1.0
    assert enc["action"] == "stand on" and enc["compliant"], enc


def test_without_the_route_the_first_turn_counts_as_the_manoeuvre():
    """What the judge did before it knew the route (the issue's 0 %)."""
    enc = _overtaken(None)
    assert enc["action"] == "starboard turn" and enc["action_time_s"] < 3.5
    assert not enc["compliant"] and "manoeuvred before she clearly failed" in enc["note"]
