"""COLREGs rules 13-15 and 17: classify an encounter and describe where the rule lets us sail.

Frame: NED, the maritime convention: positions (north, east) in metres, courses and bearings
clockwise from north. A *relative bearing* is measured clockwise from the own ship's course, in
degrees [0, 360).

Classification (COLREGs 1972, International Maritime Organization; the sector values are the
rules' own):

* rule 13, overtaking: a vessel coming up with another from more than 22.5 degrees abaft her
  beam, i.e. from a relative bearing in [112.5, 247.5] of the vessel being overtaken. Rule 13(c)
  says the vessel in doubt assumes she is overtaking, so the boundary 112.5 belongs to the
  overtaking sector (from either ship's point of view: both then agree who keeps clear);
* rule 14, head-on: reciprocal or nearly reciprocal courses, each ship seeing the other within
  ``head_on_sector`` (6 degrees, the value most often used for "nearly", e.g. Tam & Bucknall
  2010) of her bow; rule 14(c): in doubt assume head-on, so 6.0 is inclusive. Both alter course to
  starboard and pass port to port;
* rule 15, crossing: any other risk of collision. The ship that has the other on her own
  starboard side (relative bearing (0, 112.5)) keeps out of the way and avoids crossing ahead
  (we pass astern); the other (bearing (247.5, 360)) is the stand-on ship;
* rule 17: the stand-on ship keeps course and speed; she may act when the give-way ship is not
  taking appropriate action, and must when collision cannot be avoided by the give-way ship
  alone; she shall not alter course to port for a vessel on her own port side. "Clearly failing"
  is defined by numbers here (see :class:`ColregsParams`): on a collision course (eq. 10) with
  TCPA below ``rule17_tcpa``.

A target slower than ``min_target_speed`` has no meaningful course: it is a static obstacle
(keep clear) for these rules.

:func:`forbidden_zones` turns the required action into regions the planner must not enter,
expressed in the target's frame at the time the USV would be there (see
:mod:`planner.traffic_map`): the target's disc of radius R always; head-on adds the target's
starboard side ahead of it (so we pass on its port side); crossing give-way adds the water ahead
of its bow (so we pass astern); the stand-on ship acting under rule 17 adds the water to port of
her own course line.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

from planner.traffic_map import Zone

HEAD_ON = "head-on"
OVERTAKING = "overtaking"                  # we overtake: we keep clear (rule 13)
OVERTAKEN = "overtaken"                    # the target overtakes us: we stand on (rules 13, 17)
CROSSING_GIVE_WAY = "crossing-give-way"    # target on our starboard side: we give way (rule 15)
CROSSING_STAND_ON = "crossing-stand-on"    # target on our port side: we stand on (rules 15, 17)
STATIC = "static"                          # a (nearly) stopped target: keep clear
ENCOUNTER_TYPES = (HEAD_ON, OVERTAKING, OVERTAKEN, CROSSING_GIVE_WAY, CROSSING_STAND_ON, STATIC)

GIVE_WAY, STAND_ON = "give-way", "stand-on"
ROLE = {HEAD_ON: GIVE_WAY, OVERTAKING: GIVE_WAY, OVERTAKEN: STAND_ON, CROSSING_GIVE_WAY: GIVE_WAY,
        CROSSING_STAND_ON: STAND_ON, STATIC: GIVE_WAY}
REQUIRED_ACTION = {HEAD_ON: "alter to starboard, pass port to port", OVERTAKING: "keep clear",
                   OVERTAKEN: "stand on", CROSSING_GIVE_WAY: "give way, pass astern",
                   CROSSING_STAND_ON: "stand on", STATIC: "keep clear"}


def _p(help: str, unit: str = "", *, gt: float | None = None, ge: float | None = None, lt: float | None = None,
       le: float | None = None, default: object = None) -> Any:   # a field specifier: Any, as dataclasses.field's own
    return field(default=default, metadata={"help": help, "unit": unit, "gt": gt, "ge": ge, "lt": lt, "le": le})


@dataclass(frozen=True)
class ColregsParams:
    """The [colregs] section: encounter classification, the collision cone and the rule zones."""

    head_on_sector: float = _p("rule 14: each ship sees the other within this of her bow (inclusive)", "deg",
                               gt=0, lt=90, default=6.0)
    overtaking_sector: float = _p("rule 13: relative bearing of the abaft-beam sector's edge (inclusive)", "deg",
                                  gt=90, lt=180, default=112.5)
    min_target_speed: float = _p("a slower target has no course: static obstacle", "m/s", ge=0, default=0.3)
    own_radius: float = _p("influence radius of the USV (its half length + tracking error)", "m", gt=0, default=2.0)
    margin: float = _p("extra distance added to R = own_radius + target hull radius", "m", ge=0, default=3.0)
    horizon: float = _p("a collision course matters when the closest approach is at most this far ahead", "s",
                        gt=0, default=90.0)
    rule17_tcpa: float = _p("rule 17: a give-way ship on a collision course this close to the CPA has clearly "
                            "failed to act; the stand-on USV then manoeuvres", "s", gt=0, default=25.0)
    zone_length: float = _p("length of the rule zones ahead of a target (its bow for crossing, its starboard "
                            "side for head-on)", "m", gt=0, default=25.0)
    zone_width: float = _p("width of the rule zones beside the target's track", "m", gt=0, default=25.0)
    time_slack: float = _p("arrival times in the planner's occupancy test span [t, (1 + k) t + slack]: k", "",
                           ge=0, default=0.3)
    time_slack_s: float = _p("... and slack", "s", ge=0, default=2.0)


def wrap360(deg: float) -> float:
    d = math.fmod(deg, 360.0)
    return d + 360.0 if d < 0 else d


def bearing_deg(frm: tuple[float, float], to: tuple[float, float]) -> float:
    """True bearing (deg clockwise from north) from NED point ``frm`` to ``to``."""
    return wrap360(math.degrees(math.atan2(to[1] - frm[1], to[0] - frm[0])))


def relative_bearing(own_pos: tuple[float, float], own_course: float, tgt_pos: tuple[float, float]) -> float:
    """Bearing (deg, [0, 360), clockwise from the own ship's course ``own_course`` in rad) of the target."""
    return wrap360(bearing_deg(own_pos, tgt_pos) - math.degrees(own_course))


@dataclass(frozen=True)
class Encounter:
    """The rule that applies between the USV and one target, seen from the USV."""

    type: str                  # one of ENCOUNTER_TYPES
    role: str                  # give-way | stand-on
    action: str                # what the rule requires of us (REQUIRED_ACTION)
    bearing: float             # deg, relative bearing of the target from our course
    aspect: float              # deg, relative bearing of us from the target's course


def classify(own_pos: tuple[float, float], own_course: float, own_speed: float, tgt_pos: tuple[float, float],
             tgt_course: float, tgt_speed: float,
             p: ColregsParams = ColregsParams()) -> Encounter:
    """Rules 13-15 from positions (NED m), courses (rad, clockwise from north) and speeds (m/s)."""
    b = relative_bearing(own_pos, own_course, tgt_pos)        # where the target is, from our bow
    a = relative_bearing(tgt_pos, tgt_course, own_pos)        # where we are, from the target's bow
    lo, hi = p.overtaking_sector, 360.0 - p.overtaking_sector

    def done(kind: str) -> Encounter:
        return Encounter(kind, ROLE[kind], REQUIRED_ACTION[kind], b, a)

    if tgt_speed < p.min_target_speed:
        return done(STATIC)
    # Rule 13 (overtaking prevails over rules 14-15, 13(d)); the faster ship is the one closing.
    if lo <= a <= hi and own_speed > tgt_speed:
        return done(OVERTAKING)
    if lo <= b <= hi and tgt_speed > own_speed:
        return done(OVERTAKEN)
    s = p.head_on_sector
    ahead_b = b <= s or b >= 360.0 - s
    ahead_a = a <= s or a >= 360.0 - s
    if ahead_b and ahead_a:
        return done(HEAD_ON)
    if ahead_b:
        # Nearly dead ahead but not reciprocal: the side she comes from is the side she heads away from.
        rel_course = wrap360(math.degrees(tgt_course - own_course))
        return done(CROSSING_GIVE_WAY if rel_course > 180.0 else CROSSING_STAND_ON)
    if b < 180.0:
        return done(CROSSING_GIVE_WAY)
    return done(CROSSING_STAND_ON)


def forbidden_zones(encounter_type: str, radius: float, p: ColregsParams, act_stand_on: bool = False) -> tuple[Zone,
                                                                                                               ...]:
    """The rule zones (besides the target's disc of radius R) for one encounter.

    ``act_stand_on``: the stand-on USV is acting under rule 17 (the give-way ship clearly fails);
    then it must not turn to port for a ship on its port side (rule 17(c))."""
    L, W = p.zone_length, p.zone_width
    if encounter_type == HEAD_ON:
        # Passing port to port: ahead of the target and beside it, we must be on its port side.
        return (Zone("target", (-radius, L), (-0.25 * radius, W)),)
    if encounter_type == CROSSING_GIVE_WAY:
        # Never cross ahead of her: the water ahead of her bow, as wide as R each side.
        return (Zone("target", (0.0, L), (-radius, radius)),)
    if encounter_type == CROSSING_STAND_ON and act_stand_on:
        return (Zone("own", (0.0, 2.0 * L), (-2.0 * W, -0.5 * radius)),)
    return ()


def needs_planning(encounter_type: str, act_stand_on: bool) -> bool:
    """Does the planner have to avoid this target (False: stand on, keep course and speed)?"""
    if ROLE[encounter_type] == STAND_ON:
        return act_stand_on
    return True
