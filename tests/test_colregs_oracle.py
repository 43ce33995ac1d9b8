"""The encounter report's COLREGs oracle (hil/colregs_oracle.py) against the vessel computer's
rules (planner.colregs, planner.collision_cone): two implementations by different routes must
agree on random encounters, except within a hair of a sector edge; and the oracle alone on the
textbook cases."""

from __future__ import annotations

import math

import numpy as np
import pytest

from hil import colregs_oracle as O
from planner import colregs as C
from planner.collision_cone import assess

RNG_SEED = 20261124


def _near_edge(own_pos, own_course, tgt_pos, tgt_course, p: C.ColregsParams, eps: float = 1e-6) -> bool:
    """Either ship's view of the other within ``eps`` deg of a sector edge (where rounding decides)."""
    b = C.relative_bearing(own_pos, own_course, tgt_pos)
    a = C.relative_bearing(tgt_pos, tgt_course, own_pos)
    edges = (p.head_on_sector, 360.0 - p.head_on_sector, p.overtaking_sector, 360.0 - p.overtaking_sector, 0.0,
             180.0, 360.0)
    rel = C.wrap360(math.degrees(tgt_course - own_course))
    return any(abs(x - e) < eps for x in (a, b) for e in edges) or min(abs(rel - 180.0), rel, 360 - rel) < eps


def test_the_oracle_uses_the_same_vocabulary_as_the_vessel_computer():
    assert {O.HEAD_ON, O.OVERTAKING, O.OVERTAKEN, O.CROSSING_GIVE_WAY, O.CROSSING_STAND_ON, O.STATIC} \
        == set(C.ENCOUNTER_TYPES)
    assert O.ROLE == C.ROLE and O.REQUIRED == C.REQUIRED_ACTION


def test_classification_agrees_with_planner_colregs_on_random_encounters():
    rng = np.random.default_rng(RNG_SEED)
    p = C.ColregsParams()
    kinds: dict[str, int] = {}
    compared = 0
    for _ in range(20000):
        own = tuple(rng.uniform(-50, 50, 2))
        tgt = tuple(rng.uniform(-50, 50, 2))
        oc, tc = rng.uniform(-math.pi, math.pi, 2)
        if rng.random() < 0.2:      # many near-reciprocal and near-parallel courses: the rules' edges
            tc = oc + math.pi + rng.normal(0, 0.1) if rng.random() < 0.5 else oc + rng.normal(0, 0.1)
            ang = oc + rng.normal(0, 0.1)
            r = rng.uniform(5, 60)
            tgt = (own[0] + r * math.cos(ang), own[1] + r * math.sin(ang))
        os_, ts = rng.uniform(0, 4, 2)
        if _near_edge(own, oc, tgt, tc, p) or abs(os_ - ts) < 1e-9:
            continue
        mine = C.classify(own, oc, os_, tgt, tc, ts, p)
        judge = O.classify(own, oc, os_, tgt, tc, ts, p.head_on_sector, p.overtaking_sector, p.min_target_speed)
        assert judge.type == mine.type, (own, oc, os_, tgt, tc, ts, mine, judge)
        assert judge.role == mine.role
        assert judge.bearing_deg == pytest.approx(mine.bearing, abs=1e-9)
        kinds[judge.type] = kinds.get(judge.type, 0) + 1
        compared += 1
    assert compared > 19000
    assert set(kinds) == set(C.ENCOUNTER_TYPES) and min(kinds.values()) > 100, kinds


def test_closest_approach_agrees_with_the_collision_cone_on_random_pairs():
    rng = np.random.default_rng(RNG_SEED + 1)
    for _ in range(5000):
        own, tgt = rng.uniform(-100, 100, 2), rng.uniform(-100, 100, 2)
        ov, tv = rng.uniform(-5, 5, 2), rng.uniform(-5, 5, 2)
        R = rng.uniform(1, 30)
        cone = assess(own, ov, tgt, tv, R)
        ap = O.approach(tuple(own), tuple(ov), tuple(tgt), tuple(tv))
        assert ap.range_m == pytest.approx(cone.r, rel=1e-12)
        assert ap.tcpa_s == pytest.approx(cone.tcpa, rel=1e-9, abs=1e-9)
        assert ap.dcpa_m == pytest.approx(cone.dcpa, rel=1e-9, abs=1e-9)
        if abs(ap.dcpa_m - R) > 1e-6:
            assert ap.collision_course(R) == (cone.collision or cone.inside)


@pytest.mark.parametrize("tgt, tc, ts, want", [
    ((100.0, 0.0), math.pi, 2.0, O.HEAD_ON),                   # dead ahead, reciprocal
    ((100.0, 5.0), math.pi, 2.0, O.HEAD_ON),                   # 2.9 deg off the bow, both ways
    ((100.0, 20.0), math.pi, 2.0, O.CROSSING_GIVE_WAY),        # 11 deg to starboard: crossing
    ((50.0, 50.0), -math.pi / 2, 2.0, O.CROSSING_GIVE_WAY),    # on our starboard bow, heading west
    ((50.0, -50.0), math.pi / 2, 2.0, O.CROSSING_STAND_ON),    # on our port bow, heading east
    ((30.0, 0.0), 0.0, 1.0, O.OVERTAKING),                     # ahead, same course, slower
    ((-30.0, 0.0), 0.0, 4.0, O.OVERTAKEN),                     # astern, same course, faster
    ((40.0, 10.0), 0.0, 0.1, O.STATIC),                        # nearly stopped
])
def test_textbook_cases(tgt, tc, ts, want):
    """Own ship at the origin heading north at 2 m/s."""
    assert O.classify((0.0, 0.0), 0.0, 2.0, tgt, tc, ts).type == want


@pytest.mark.parametrize("deg, want", [(5.9, O.HEAD_ON), (6.1, O.CROSSING_GIVE_WAY)])
def test_head_on_sector_edge(deg, want):
    """She is ``deg`` to starboard of our bow and sees us ``deg`` to starboard of hers."""
    s = math.radians(deg)
    her = (100.0 * math.cos(s), 100.0 * math.sin(s))
    assert O.classify((0.0, 0.0), 0.0, 2.0, her, math.pi + 2 * s, 2.0).type == want


@pytest.mark.parametrize("deg, want", [(112.6, O.OVERTAKING), (112.4, O.CROSSING_GIVE_WAY)])
def test_overtaking_sector_edge(deg, want):
    """We come up with her (she heads north at 1 m/s) from ``deg`` off her bow, to her port side."""
    b = math.radians(-deg)
    us = (30.0 * math.cos(b), 30.0 * math.sin(b))
    assert O.classify(us, 0.0, 3.0, (0.0, 0.0), 0.0, 1.0).type == want
