"""The vessel computer's view of ship traffic: AIS tracks, encounters, and what the planner avoids.

Per sensor frame, :meth:`TrafficAwareness.on_frame` folds the AIS reports the link decoded into
the per-MMSI tracker (:mod:`autopilot_bridge.ais_tracking`), forwards the accepted ones to the
ground station (``telemetry.forward("ais_vessel", ...)``), and assesses every confirmed target
with the collision cone of eqs. (9)-(10) (R = own influence radius + the target's hull radius
+ margin). A target on a collision course with its closest approach within ``horizon`` starts an
*encounter*, classified once by COLREGs rules 13-15 (:func:`planner.colregs.classify`); its
roles do not change while it lasts (rule 17's "keep course and speed" needs a fixed role). The
encounter ends when the target is opening and outside R.

* give-way (head-on, overtaking, crossing with the target to starboard): the target and its rule
  zones go to the planner;
* stand-on (crossing with the target to port, being overtaken): the target is left out of
  planning, so the vessel keeps its course and speed along the reference path, until the
  give-way ship *clearly fails*: still on a collision course with TCPA <= ``rule17_tcpa``. Then
  rule 17 applies: the target goes to the planner with the no-turn-to-port zone of rule 17(c).

Targets without an encounter are still given to the planner as discs (a plan must not create a
new risk). Frames: tracks are NED; :meth:`snapshot` converts to the planner's map frame.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace
from typing import TYPE_CHECKING, TypedDict

from autopilot_bridge.ais_tracking import AisReport, AisSummary, AisTracker, Target, TrackerParams
from planner import colregs as C
from planner.collision_cone import assess
from planner.traffic_map import MovingObstacle, TrafficSnapshot

if TYPE_CHECKING:
    from autopilot_bridge.gcs.link import GcsLink
    from autopilot_bridge.navigation import NavState
    from common.geodesy import LocalFrame

RULE17_PORT_TOLERANCE = 1.0  # m: path-following error allowed to port of the rule-17 course line
SHORT_ACTION = {C.HEAD_ON: "starboard turn", C.OVERTAKING: "keep clear", C.OVERTAKEN: "stand on",
                C.CROSSING_GIVE_WAY: "pass astern", C.CROSSING_STAND_ON: "stand on", C.STATIC: "keep clear"}


@dataclass
class EncounterState:
    mmsi: int
    type: str
    role: str
    start_t: float
    bearing: float
    tcpa: float
    dcpa: float
    acting: bool = False           # stand-on ship manoeuvring under rule 17
    act_t: float | None = None
    act_pose: tuple[float, float, float] | None = None   # map x, y, course (rad from east) when it began
    end_t: float | None = None


class EncounterRecord(TypedDict):
    """One COLREGs encounter as the vessel computer saw it: the ship, the rule's type and our role,
    when it began (s), the bearing then (deg), when a stand-on vessel acted under rule 17 and when
    it ended (s; None: not)."""

    mmsi: int
    type: str
    role: str
    start_s: float
    bearing_deg: float
    rule17_act_s: float | None
    end_s: float | None


class TrafficSummary(TypedDict):
    """The ``traffic`` section of the autopilot's summary."""

    ais: AisSummary
    forwarded_to_gcs: int
    encounters: list[EncounterRecord]


class TrafficAwareness:
    """Tracker + encounter monitor + the planner's traffic snapshot."""

    def __init__(self, tracking: TrackerParams, colregs: C.ColregsParams, geo: LocalFrame) -> None:
        self.p = colregs
        self.tracker = AisTracker(tracking, geo)
        self.geo = geo
        self.active: dict[int, EncounterState] = {}
        self.history: list[EncounterState] = []
        self.forwarded = 0
        self.new_encounters = 0
        self.cleared: set[int] = set()   # passed ships: a new encounter only once they are 2 R away

    def reset(self) -> None:
        """Simulator restart: its clock starts again, the tracks' times are meaningless."""
        self.tracker = AisTracker(self.tracker.p, self.geo)
        self.active.clear()
        self.cleared.clear()

    def radius(self, tg: Target) -> float:
        return self.p.own_radius + tg.hull_radius + self.p.margin

    def on_frame(self, t: float, s: NavState, reports: list[AisReport],
                 telemetry: GcsLink | None = None) -> tuple[list[str], bool]:
        """Fold in the frame's AIS reports and update encounters; returns (event texts, replan now)."""
        if not reports and not self.tracker.tracks and not self.active:
            return [], False   # no ship known (most frames of a run without traffic): nothing to assess
        for r in reports:
            if self.tracker.update(r) and telemetry is not None and hasattr(telemetry, "forward"):
                telemetry.forward("ais_vessel", *_ais_fields(r))
                self.forwarded += 1
        self.tracker.forget(t)
        events: list[str] = []
        replan = False
        vn = s.u * math.cos(s.psi) - s.v * math.sin(s.psi)
        ve = s.u * math.sin(s.psi) + s.v * math.cos(s.psi)
        speed = math.hypot(vn, ve)
        course = math.atan2(ve, vn) if speed > 0.3 else s.psi
        seen = set()
        for tg in self.tracker.targets(t):
            seen.add(tg.mmsi)
            R = self.radius(tg)
            cone = assess((s.x, s.y), (vn, ve), (tg.north, tg.east), (tg.vn, tg.ve), R)
            risk = (cone.collision and cone.tcpa <= self.p.horizon) or cone.inside
            enc = self.active.get(tg.mmsi)
            if tg.mmsi in self.cleared:
                if cone.r <= 2.0 * R:
                    continue
                self.cleared.discard(tg.mmsi)
            if enc is None:
                if risk:
                    e = C.classify((s.x, s.y), course, speed, (tg.north, tg.east), tg.course, tg.speed, self.p)
                    enc = EncounterState(tg.mmsi, e.type, e.role, t, e.bearing, cone.tcpa, cone.dcpa)
                    self.active[tg.mmsi] = enc
                    self.history.append(enc)
                    self.new_encounters += 1
                    events.append(f"COLREG {tg.mmsi} {e.type}: {SHORT_ACTION[e.type]}")
                    replan = True
                continue
            enc.tcpa, enc.dcpa = cone.tcpa, cone.dcpa
            if enc.role == C.STAND_ON and not enc.acting and cone.collision and cone.tcpa <= self.p.rule17_tcpa:
                enc.acting, enc.act_t = True, t
                # Rule 17(c) forbids turning to port from the course held until now: anchor it here.
                enc.act_pose = (s.y, s.x, math.pi / 2.0 - course)
                events.append(f"COLREG {tg.mmsi} give-way fails: rule 17 act")
                replan = True
            if not cone.collision and cone.v_r >= 0.0 and not cone.inside:
                enc.end_t = t
                del self.active[tg.mmsi]
                self.cleared.add(tg.mmsi)
                events.append(f"COLREG {tg.mmsi} clear, CPA {cone.r:.0f} m")
        for m in [m for m in self.active if m not in seen]:
            self.active[m].end_t = t
            del self.active[m]
        return events, replan

    def snapshot(self, t: float, x: float, y: float, heading: float, speed: float) -> TrafficSnapshot | None:
        """The traffic for a planning cycle starting at time ``t`` at map position (x, y) with map
        heading ``heading`` (rad from east) at ``speed`` m/s; None when there is none."""
        obstacles = []
        for tg in self.tracker.targets(t):
            enc = self.active.get(tg.mmsi)
            zones: tuple = ()
            if enc is not None:
                if not C.needs_planning(enc.type, enc.acting):
                    continue   # stand on: keep course and speed, the target is not avoided by planning
                zones = C.forbidden_zones(enc.type, self.radius(tg), self.p, act_stand_on=enc.acting)
                if enc.act_pose is not None:
                    ox, oy, oc = enc.act_pose
                    # Our offset to starboard of that course line now: the zone never includes
                    # where we are, it only stops us moving further to port.
                    lateral = (x - ox) * math.sin(oc) - (y - oy) * math.cos(oc)
                    top = min(RULE17_PORT_TOLERANCE, lateral) - RULE17_PORT_TOLERANCE
                    zones = tuple(replace(z, origin=(ox, oy), course=oc, starboard=(z.starboard[0], top))
                                  if z.frame == "own" else z for z in zones)
            obstacles.append(MovingObstacle(tg.mmsi, tg.east, tg.north, tg.ve, tg.vn, self.radius(tg), zones))
        if not obstacles:
            return None
        return TrafficSnapshot(tuple(obstacles), speed, heading, (x, y), self.p.time_slack, self.p.time_slack_s)

    def summary(self) -> TrafficSummary:
        return TrafficSummary(
            ais=self.tracker.summary(),
            forwarded_to_gcs=self.forwarded,
            encounters=[EncounterRecord(mmsi=e.mmsi, type=e.type, role=e.role, start_s=round(e.start_t, 2),
                                        bearing_deg=round(e.bearing, 1),
                                        rule17_act_s=None if e.act_t is None else round(e.act_t, 2),
                                        end_s=None if e.end_t is None else round(e.end_t, 2))
                        for e in self.history],
        )


def _ais_fields(r: AisReport) -> tuple:
    """AIS_VESSEL fields of an accepted report, for the ground station."""
    from common.mavlink import MAV_TYPE as M

    cog = 36000 if r.course is None else int(round(math.degrees(r.course) * 100)) % 36000
    vel = 65535 if r.speed is None else min(int(round(r.speed * 100)), 65534)
    flags = M.AIS_FLAGS_VALID_DIMENSIONS | (M.AIS_FLAGS_VALID_COG if r.course is not None else 0) | \
        (M.AIS_FLAGS_VALID_VELOCITY if r.speed is not None else 0) | (M.AIS_FLAGS_VALID_NAME if r.name else 0)
    return (r.mmsi, int(round(r.lat * 1e7)), int(round(r.lon * 1e7)), cog, cog, vel, 0, 0, 0,
            int(r.bow), int(r.stern), min(int(r.port), 255), min(int(r.starboard), 255), b"",
            r.name.encode("ascii", "replace")[:20], 0, flags)
