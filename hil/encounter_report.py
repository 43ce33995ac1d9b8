"""Judging ship encounters from the truth: hull overlap, closest approach, action and compliance.

The tap receives the own ship's truth (HIL_STATE_QUATERNION) and every traffic ship's truth
(AIS_VESSEL from the simulator's truth component) in the same datagrams, so each ship sample
has an own-ship sample at the same instant. From those:

* **collision**: the hulls overlap. The own hull is the L x W rectangle of ``[vessel]`` about its
  reference point, along the true heading; a ship's hull is the rectangle of its AIS dimensions
  A/B/C/D about its reference point, along its course (separating-axis test);
* **CPA** per ship: the smallest distance between the reference points, and when;
* **type**: COLREGs rules 13-15 (:func:`hil.colregs_oracle.classify`, written independently of
  the vessel computer's :mod:`planner.colregs`, which it judges) from the truth at the first
  instant the ship is on a collision course (eq. 10 with R = own_radius + its hull radius +
  margin, closest approach within ``horizon``), or "no risk" if it never is;
* **our action** between that instant and the CPA, from the true track: "starboard turn" /
  "port turn" (course at least ``TURN_DEG`` off the planned route's course where she is and farther
  off it than at the risk instant, so closing on the route is none; without a route: changed by at
  least ``TURN_DEG`` from the course at the risk instant), "slow down" (speed below
  ``SLOW_RATIO`` of the speed at the start), else "stand on"; with the instant it began;
* **compliance**: no collision, CPA at least the safety radius (own_radius + the ship's hull
  radius), and the rule's manoeuvre: head-on, the ship passes on our port side (port to port);
  crossing give-way, we pass astern of her (at the CPA we are abaft her beam); stand-on (crossing
  from the left, being overtaken), no manoeuvre before she clearly failed (on a collision course
  with TCPA <= rule17_tcpa, R widened by ``DCPA_TOLERANCE`` for what AIS lets the vessel know)
  and never a turn to port.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import NotRequired, TypedDict

import numpy as np

from hil import colregs_oracle as O
from planner.colregs import ColregsParams

TURN_DEG = 10.0      # deg of course change that counts as a turn
SLOW_RATIO = 0.75    # speed below this fraction of the initial speed counts as slowing down
ACTION_GRACE = 1.0   # s: a stand-on manoeuvre this early before the rule-17 instant is still compliant
MOVING = 0.3         # m/s: below this the own ship has no course to classify from
DCPA_TOLERANCE = 3.0 # m: the vessel computer knows her CPA only to the AIS position noise it assumes
                     # (tracking.pos_std); rule 17's instant is judged with R widened by this much


def _corners(x: float, y: float, heading: float, ahead: float, behind: float, left: float, right: float) -> np.ndarray:
    """Rectangle corners in NED for a hull about (x, y) with course ``heading`` (rad from north)."""
    c, s = math.cos(heading), math.sin(heading)
    fwd, stb = np.array([c, s]), np.array([-s, c])
    p = np.array([x, y])
    return np.array([p + fwd * ahead + stb * right, p + fwd * ahead - stb * left,
                     p - fwd * behind - stb * left, p - fwd * behind + stb * right])


def hulls_overlap(a: np.ndarray, b: np.ndarray) -> bool:
    """Separating-axis test for two convex quadrilaterals (4 x 2 corner arrays)."""
    for poly in (a, b):
        for i in range(4):
            e = poly[(i + 1) % 4] - poly[i]
            n = np.array([-e[1], e[0]])
            pa, pb = a @ n, b @ n
            if pa.max() < pb.min() or pb.max() < pa.min():
                return False
    return True


class EncounterVerdict(TypedDict):
    """The judge's verdict on one ship (``encounters`` of summary.json). Every ship has its MMSI and
    name; one never met has ``type`` "not met"; one met has its CPA (m, s), and, when there was a risk
    of collision, the COLREGs type, our role and required action, what we did and when (s), how far
    we turned (deg) and slowed, whether it complied and why."""

    mmsi: int
    name: str
    type: NotRequired[str]
    compliant: NotRequired[bool | None]
    cpa_m: NotRequired[float]
    cpa_time_s: NotRequired[float]
    safety_radius_m: NotRequired[float]
    collision: NotRequired[bool]
    action: NotRequired[str]
    role: NotRequired[str]
    required: NotRequired[str]
    risk_time_s: NotRequired[float]
    bearing_deg: NotRequired[float]
    action_time_s: NotRequired[float | None]
    max_starboard_deg: NotRequired[float]
    max_port_deg: NotRequired[float]
    min_speed_ratio: NotRequired[float]
    rule17_time_s: NotRequired[float | None]
    note: NotRequired[str]


class EncounterTotals(TypedDict):
    """Over a run's ships: how many, how many encounters with a risk of collision, collisions, the
    mean CPA (m) and the share of risky encounters that complied (None without any)."""

    ships: int
    encounters: int
    collisions: int
    mean_cpa_m: float | None
    compliance_rate: float | None


@dataclass
class ShipTrack:
    mmsi: int
    name: str
    dims: tuple[float, float, float, float]       # bow, stern, port, starboard (m)
    samples: list[tuple[int, float, float, float, float]] = field(default_factory=list)  # t_us, n, e, course, speed

    @property
    def hull_radius(self) -> float:
        b, s, p, d = self.dims
        return math.hypot(max(b, s), max(p, d))


class EncounterJudge:
    """Collects own/ship truth pairs, flags hull overlaps as they happen, reports per encounter."""

    def __init__(self, own_length: float, own_width: float, colregs: ColregsParams,
                 route: np.ndarray | None = None) -> None:
        """``route``: the boat's planned route (map frame: x east, y north, m); its manoeuvres are then
        judged against the route's course where she is, so turning onto the route is no manoeuvre."""
        self.L, self.W, self.p = own_length, own_width, colregs
        self.route = None if route is None or len(route) < 2 else np.asarray(route, dtype=float)[:, ::-1]  # NED
        self.ships: dict[int, ShipTrack] = {}
        self.collision: tuple[float, int] | None = None   # (t s, mmsi)

    def add(self, t_us: int, own: tuple[float, float, float], mmsi: int, name: str,
            dims: tuple[float, float, float, float], north: float, east: float, course: float, speed: float) -> None:
        """One ship truth sample with the own truth (north, east, heading) of the same instant."""
        tr = self.ships.get(mmsi)
        if tr is None:
            tr = self.ships[mmsi] = ShipTrack(mmsi, name, dims)
        tr.samples.append((t_us, north, east, course, speed))
        if self.collision is None:
            b, s, p, d = dims
            if math.hypot(north - own[0], east - own[1]) <= tr.hull_radius + math.hypot(self.L, self.W):
                mine = _corners(own[0], own[1], own[2], self.L / 2, self.L / 2, self.W / 2, self.W / 2)
                hers = _corners(north, east, course, b, s, p, d)
                if hulls_overlap(mine, hers):
                    self.collision = (t_us * 1e-6, mmsi)

    def planned_course(self, north: np.ndarray, east: np.ndarray) -> np.ndarray | None:
        """The course (rad, clockwise from north) of the route's leg nearest each point; None without a route."""
        if self.route is None:
            return None
        a, b = self.route[:-1], self.route[1:]
        d = b - a
        p = np.stack([north, east], axis=1)[:, None, :]                     # (N, 1, 2)
        u = np.clip(((p - a) * d).sum(-1) / np.maximum((d * d).sum(-1), 1e-12), 0.0, 1.0)
        gap = np.hypot(*(a + u[..., None] * d - p).transpose(2, 0, 1))      # (N, legs)
        leg = np.argmin(gap, axis=1)
        return np.arctan2(d[leg, 1], d[leg, 0])

    def report(self, own_truth: dict[int, tuple[float, float, float, float]]) -> list[EncounterVerdict]:
        """One entry per ship; ``own_truth``: time_usec -> (north, east, vn, ve)."""
        return [self._one(tr, own_truth) for tr in sorted(self.ships.values(), key=lambda s: s.mmsi)]

    def _one(self, tr: ShipTrack, own: dict[int, tuple[float, float, float, float]]) -> EncounterVerdict:
        p = self.p
        rows = [(t, *own[t], n, e, c, s) for t, n, e, c, s in tr.samples if t in own]
        out = EncounterVerdict(mmsi=tr.mmsi, name=tr.name)
        if not rows:
            out["type"] = "not met"
            out["compliant"] = None
            return out
        a = np.array(rows, dtype=float)
        t = a[:, 0] * 1e-6
        on, oe, ovn, ove, sn, se, sc, ss = a[:, 1:].T
        dist = np.hypot(sn - on, se - oe)
        k = int(np.argmin(dist))
        R = p.own_radius + tr.hull_radius + p.margin
        safety = p.own_radius + tr.hull_radius
        out["cpa_m"] = round(float(dist[k]), 2)
        out["cpa_time_s"] = round(float(t[k]), 2)
        out["safety_radius_m"] = round(safety, 2)
        svn, sve = ss * np.cos(sc), ss * np.sin(sc)
        risk = None
        rule17 = None
        moving = np.hypot(ovn, ove) >= MOVING
        for i in range(len(t)):
            if not moving[i]:
                continue  # no course yet (starting from rest): no encounter geometry
            ap = O.approach((on[i], oe[i]), (ovn[i], ove[i]), (sn[i], se[i]), (svn[i], sve[i]))
            if risk is None and ap.collision_course(R, p.horizon) and i <= k:
                risk = i
            if risk is not None:
                break
        if risk is not None:
            for i in range(risk, k + 1):
                ap = O.approach((on[i], oe[i]), (ovn[i], ove[i]), (sn[i], se[i]), (svn[i], sve[i]))
                if 0.0 < ap.tcpa_s <= p.rule17_tcpa and ap.dcpa_m <= R + DCPA_TOLERANCE:
                    rule17 = i
                    break
        collided = self.collision is not None and self.collision[1] == tr.mmsi
        out["collision"] = collided
        if risk is None:
            out["type"] = "no risk"
            out["action"] = "none"
            out["compliant"] = bool(not collided and dist[k] >= safety)
            return out
        i0 = risk
        own_speed = math.hypot(ovn[i0], ove[i0])
        own_course = math.atan2(ove[i0], ovn[i0])
        enc = O.classify((on[i0], oe[i0]), own_course, own_speed, (sn[i0], se[i0]), sc[i0], ss[i0],
                         head_on_deg=p.head_on_sector, abaft_deg=p.overtaking_sector,
                         min_target_speed=p.min_target_speed)
        seg = slice(i0, k + 1)
        course = np.arctan2(ove[seg], ovn[seg])
        planned = self.planned_course(on[seg], oe[seg])
        if planned is None:
            dev = np.degrees(np.angle(np.exp(1j * (course - own_course))))   # + = to starboard
            turned = np.abs(dev) >= TURN_DEG
        else:
            # Against the route's course: a turn takes her off it by TURN_DEG, and farther than she
            # was at the risk instant (closing on the route, e.g. her first turn onto it, is none).
            dev = np.degrees(np.angle(np.exp(1j * (course - planned))))
            turned = (np.abs(dev) >= TURN_DEG) & (np.abs(dev) > abs(dev[0]))
            dev = np.where(turned, dev, 0.0)
        speed = np.hypot(ovn[seg], ove[seg])
        slowed = speed < SLOW_RATIO * max(own_speed, 1e-6)
        acted = np.nonzero(turned | slowed)[0]
        stbd, port = float(max(dev.max(), 0.0)), float(max(-dev.min(), 0.0))
        if stbd >= TURN_DEG and stbd >= port:
            action = "starboard turn"
        elif port >= TURN_DEG:
            action = "port turn"
        elif slowed.any():
            action = "slow down"
        else:
            action = "stand on"
        act_t = float(t[i0 + acted[0]]) if len(acted) else None
        # Where each ship was at the CPA, seen from the other.
        rel_b = O.relative_bearing_deg((on[k], oe[k]), math.atan2(ove[k], ovn[k]), (sn[k], se[k]))
        along = (on[k] - sn[k]) * math.cos(sc[k]) + (oe[k] - se[k]) * math.sin(sc[k])  # ours, along her course
        ok = not collided and dist[k] >= safety
        why = []
        if enc.type == O.HEAD_ON:
            passed = "port to port" if rel_b > 180.0 else "starboard to starboard"
            ok = ok and rel_b > 180.0 and action != "port turn"
            why.append(passed)
        elif enc.type == O.CROSSING_GIVE_WAY:
            passed = "astern" if along < 0 else "ahead"
            ok = ok and along < 0
            why.append(f"passed {passed} of her")
        elif enc.role == O.STAND_ON:
            limit = float(t[rule17]) if rule17 is not None else None
            early = act_t is not None and (limit is None or act_t < limit - ACTION_GRACE)
            ok = ok and not early and action != "port turn"
            why.append("manoeuvred before she clearly failed" if early else
                       (f"stood on until {limit:.1f} s" if limit is not None else "stood on"))
        if dist[k] < safety:
            why.append(f"CPA below {safety:.1f} m")
        out["type"] = enc.type
        out["role"] = enc.role
        out["required"] = enc.required
        out["risk_time_s"] = round(float(t[i0]), 2)
        out["bearing_deg"] = round(enc.bearing_deg, 1)
        out["action"] = action
        out["action_time_s"] = None if act_t is None else round(act_t, 2)
        out["max_starboard_deg"] = round(stbd, 1)
        out["max_port_deg"] = round(port, 1)
        out["min_speed_ratio"] = round(float(speed.min() / max(own_speed, 1e-6)), 2)
        out["rule17_time_s"] = None if rule17 is None or enc.role != O.STAND_ON else round(float(t[rule17]), 2)
        out["compliant"] = bool(ok)
        out["note"] = "; ".join(why)
        return out


def totals(encounters: list[EncounterVerdict]) -> EncounterTotals:
    """Collision count, mean CPA and compliance rate over the encounters with a risk of collision."""
    risky = [e for e in encounters if e.get("type") not in (None, "no risk", "not met")]
    cpas = [e["cpa_m"] for e in encounters if "cpa_m" in e]
    return EncounterTotals(ships=len(encounters), encounters=len(risky),
                           collisions=sum(1 for e in encounters if e.get("collision")),
                           mean_cpa_m=round(float(np.mean(cpas)), 2) if cpas else None,
                           compliance_rate=round(sum(1 for e in risky if e.get("compliant")) / len(risky), 3)
                           if risky else None)
