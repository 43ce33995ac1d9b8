"""An independent judge of COLREGs encounters, for the encounter report (hil/encounter_report.py).

The vessel computer decides with :mod:`planner.colregs` (bearings in degrees, sector tests) and
:mod:`planner.collision_cone` (eqs. (9)-(10) in polar components). A judge that used the same
code would agree with it by construction, bugs included, as `hil/optimum.py` would if it were
the planner. This module reaches the same rules by another route, from vectors only: dot and
cross products of unit course vectors and the line of sight, and the closest point of approach
from relative position and velocity. tests/test_colregs_oracle.py compares the two on random
encounters; they agree except within a hair of a sector edge.

Frame: NED (north, east), metres, m/s; courses in radians clockwise from north.

The rules (COLREGs 1972, rules 13-15), as geometry:

* **overtaking** (rule 13): a ship "coming up with another from a direction more than 22.5
  degrees abaft her beam". With u the overtaken ship's unit course and l the unit line of sight
  from her to the overtaking ship, that is u . l <= cos(112.5 deg). The faster ship is the one
  coming up; in doubt she is overtaking (13(c)), so the edge is included;
* **head-on** (rule 14): reciprocal or nearly reciprocal courses, each ship seeing the other
  within ``head_on_deg`` of her bow: u_own . l >= cos(s) and u_tgt . (-l) >= cos(s), edge included
  (14(c): in doubt, head-on);
* **crossing** (rule 15): otherwise. The ship with the other on her starboard side keeps out of
  the way. "On her starboard side" is l to the right of u_own: cross(u_own, l) > 0 with
  cross(a, b) = a_n b_e - a_e b_n (positive: b clockwise of a). For a ship almost dead ahead but
  not on a reciprocal course, the side is the one she comes from: she is crossing from starboard
  when her course turns anticlockwise of ours, cross(u_own, u_tgt) < 0;
* a ship slower than ``min_target_speed`` has no course: a static obstacle, keep clear.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

HEAD_ON = "head-on"
OVERTAKING = "overtaking"
OVERTAKEN = "overtaken"
CROSSING_GIVE_WAY = "crossing-give-way"
CROSSING_STAND_ON = "crossing-stand-on"
STATIC = "static"

GIVE_WAY, STAND_ON = "give-way", "stand-on"
ROLE = {HEAD_ON: GIVE_WAY, OVERTAKING: GIVE_WAY, OVERTAKEN: STAND_ON, CROSSING_GIVE_WAY: GIVE_WAY,
        CROSSING_STAND_ON: STAND_ON, STATIC: GIVE_WAY}
REQUIRED = {HEAD_ON: "alter to starboard, pass port to port", OVERTAKING: "keep clear", OVERTAKEN: "stand on",
            CROSSING_GIVE_WAY: "give way, pass astern", CROSSING_STAND_ON: "stand on", STATIC: "keep clear"}


def _unit(course: float) -> tuple[float, float]:
    return math.cos(course), math.sin(course)


def _dot(a: tuple[float, float], b: tuple[float, float]) -> float:
    return a[0] * b[0] + a[1] * b[1]


def _cross(a: tuple[float, float], b: tuple[float, float]) -> float:
    return a[0] * b[1] - a[1] * b[0]


@dataclass(frozen=True)
class Judgement:
    """The rule between the own ship and one target, from the own ship's side."""

    type: str
    role: str
    required: str
    bearing_deg: float          # relative bearing of the target, clockwise from our course [0, 360)


def relative_bearing_deg(own_pos: tuple[float, float], own_course: float, tgt_pos: tuple[float, float]) -> float:
    """Where the target is, in degrees clockwise from our course, [0, 360) (from the vectors' angle)."""
    los = (tgt_pos[0] - own_pos[0], tgt_pos[1] - own_pos[1])
    u = _unit(own_course)
    deg = math.degrees(math.atan2(_cross(u, los), _dot(u, los)))
    return deg + 360.0 if deg < 0.0 else deg


def classify(own_pos: tuple[float, float], own_course: float, own_speed: float,
             tgt_pos: tuple[float, float], tgt_course: float, tgt_speed: float,
             head_on_deg: float = 6.0, abaft_deg: float = 112.5, min_target_speed: float = 0.3) -> Judgement:
    """Rules 13-15 from positions (NED m), courses (rad from north) and speeds (m/s)."""
    dn, de = tgt_pos[0] - own_pos[0], tgt_pos[1] - own_pos[1]
    rng = math.hypot(dn, de)
    los = (dn / rng, de / rng) if rng > 0 else (1.0, 0.0)        # own -> target
    back = (-los[0], -los[1])                                       # target -> own
    u_own, u_tgt = _unit(own_course), _unit(tgt_course)
    bearing = relative_bearing_deg(own_pos, own_course, tgt_pos)

    def judged(kind: str) -> Judgement:
        return Judgement(kind, ROLE[kind], REQUIRED[kind], bearing)

    if tgt_speed < min_target_speed:
        return judged(STATIC)
    abaft = math.cos(math.radians(abaft_deg))
    if _dot(u_tgt, back) <= abaft and own_speed > tgt_speed:      # we come up from abaft her beam
        return judged(OVERTAKING)
    if _dot(u_own, los) <= abaft and tgt_speed > own_speed:       # she comes up from abaft ours
        return judged(OVERTAKEN)
    ahead = math.cos(math.radians(head_on_deg))
    she_is_ahead = _dot(u_own, los) >= ahead
    if she_is_ahead and _dot(u_tgt, back) >= ahead:
        return judged(HEAD_ON)
    if she_is_ahead:
        return judged(CROSSING_GIVE_WAY if _cross(u_own, u_tgt) < 0.0 else CROSSING_STAND_ON)
    return judged(CROSSING_GIVE_WAY if _cross(u_own, los) > 0.0 else CROSSING_STAND_ON)


@dataclass(frozen=True)
class Approach:
    """Closest point of approach under constant velocities."""

    range_m: float
    tcpa_s: float               # s from now (0 when opening or without relative motion)
    dcpa_m: float

    def collision_course(self, radius: float, horizon_s: float = math.inf) -> bool:
        """Within ``radius`` now, or closing to within it no later than ``horizon_s``."""
        return self.range_m <= radius or (0.0 < self.tcpa_s <= horizon_s and self.dcpa_m <= radius)


def approach(own_pos: tuple[float, float], own_vel: tuple[float, float],
             tgt_pos: tuple[float, float], tgt_vel: tuple[float, float]) -> Approach:
    """CPA from relative position p and velocity w (target minus own): t* = -p.w / |w|^2."""
    p = (tgt_pos[0] - own_pos[0], tgt_pos[1] - own_pos[1])
    w = (tgt_vel[0] - own_vel[0], tgt_vel[1] - own_vel[1])
    rng = math.hypot(*p)
    w2 = _dot(w, w)
    t = -_dot(p, w) / w2 if w2 > 1e-12 else 0.0
    if t <= 0.0:
        return Approach(rng, 0.0, rng)
    return Approach(rng, t, math.hypot(p[0] + w[0] * t, p[1] + w[1] * t))
