"""Keeping station against the current (LOITER, mission end, RTL and GUIDED arrival, LOITER_* items).

ArduRover's boats drift inside LOIT_RADIUS and then steer back, bow towards the point; in a current
that is a sawtooth about the radius, and the way back is sailed across the stream (ArduPilot issues 7661
and 19306). Here the boat points into the water velocity it needs and holds its position with thrust
feed-forward:

* the current ``c`` (NED m/s) comes from :class:`autopilot_bridge.current_estimate.CurrentObserver`;
* the ground velocity wanted is ``v_d = k e`` towards the point (``e``: position error, m; ``k`` = 0.2 1/s,
  at most ``max_speed``); the water velocity that gives it is ``w = v_d - c``;
* the bow points along ``w`` - into the current when on the point (it weathervanes), towards the point
  in still water - and the surge set-point is ``v_d`` along the bow, over ground, with the current's
  component along the bow fed forward to the speed controller (the drag of the speed through the water);
* the boat goes along ``w`` by its nearer end: bow first, or stern first where the stern is nearer (with
  20 degrees of hysteresis either side of abeam; on taking over, whichever end is nearer) and the current is
  within what astern holds (``MAX_ASTERN``); stern first, the way back is slowed so the water speed stays
  within it, rather than the boat turned broadside to the current;
* in still water (``|c|`` below ``STILL_WATER``: no current, no wave drift) and within half of LOIT_RADIUS,
  the thrusters rest, as ArduRover's boats drift inside the radius; beyond it the boat is brought back.

Not looping (``loiter`` False: HOLD at the end, MIS_DONE_BEHAVE 0): thrusters off.
"""

from __future__ import annotations

import math
from collections.abc import Callable

from autopilot_bridge.behaviour import Behaviour, BehaviourMachine
from autopilot_bridge.control import Thrust
from autopilot_bridge.navigation import NavState
from autopilot_bridge.parameters import Tunable

# drive(state, dt, heading ref rad, speed ref m/s over ground, current along the bow m/s) -> Thrust
Drive = Callable[[NavState, float, float, float, float], Thrust]

POSITION_GAIN = 0.2      # 1/s: ground speed asked per metre off the point
STILL_WATER = 0.02       # m/s: below this the current is noise
ASTERN_HYSTERESIS = 0.34  # cos 70 deg: the end of the hull nearer to w by 20 deg either side of abeam
MAX_ASTERN = 1.0         # m/s: water speed held stern first at most (reverse 2 x 66.7 N; drag at 1 m/s 32 N)
TURN_HOLD = 0.08         # m/s: below this water speed the heading is kept (its direction is noise)


class StationKeeper:
    radius = Tunable("LOIT_RADIUS", 0.5, 100.0, "m",
                     "station keeping: in still water the boat rests within half this distance of the point "
                     "(ArduRover: LOIT_RADIUS, drift within it); in a current it holds the point")

    def __init__(self, radius: float, max_speed: float, zero_thrust: Thrust, method: str = "into-current") -> None:
        self.method = method                # "into-current" or "drift-and-return" (ArduRover's, for comparison)
        self.radius = radius
        self.max_speed = max_speed          # m/s over ground towards the point
        self.zero_thrust = zero_thrust
        self._heading: float | None = None  # rad, the last heading asked
        self.resting = True                 # thrusters off last frame (the controllers' state is stale)
        self._astern = False                # holding stern first to the water velocity

    def approach_speed(self, distance: float) -> float:
        """m/s over ground asked towards the point from ``distance`` m off."""
        return min(POSITION_GAIN * distance, self.max_speed)

    def reset(self) -> None:
        self._heading = None
        self._astern = False
        self.resting = True

    def command(self, s: NavState, dt: float, point: tuple[float, float], loiter: bool, behaviour: BehaviourMachine,
                drive: Drive, current: tuple[float, float], on_resume: Callable[[], None], rest: bool = True) -> Thrust:
        """This frame's thrust to keep station at ``point`` (NED m) in ``current`` (NED m/s);
        ``on_resume()`` when the thrusters take over again after resting (the controllers start afresh).
        ``rest`` False: never rest in still water (beside an obstacle, a boat with way on must be stopped)."""
        en, ee = point[0] - s.x, point[1] - s.y
        d = math.hypot(en, ee)
        if self.method == "drift-and-return":
            return self._drift_and_return(s, dt, d, en, ee, loiter, behaviour, drive, on_resume)
        cn, ce = current
        still = math.hypot(cn, ce) < STILL_WATER
        if not loiter or (rest and still and d <= 0.5 * self.radius):
            behaviour.to(Behaviour.COMPLETE)
            self._heading = None
            self.resting = True
            return self.zero_thrust
        if self.resting:
            self.resting = False
            on_resume()
        behaviour.to(Behaviour.RETURNING if d > self.radius else Behaviour.COMPLETE)
        k = min(POSITION_GAIN, self.max_speed / d) if d > 1e-9 else 0.0
        vn, ve = k * en, k * ee                       # ground velocity wanted
        wn, we = vn - cn, ve - ce                     # water velocity that gives it
        w = math.hypot(wn, we)
        if w >= TURN_HOLD or self._heading is None:
            axis = math.atan2(we, wn) if w > 1e-9 else s.psi
            ahead = math.cos(axis - s.psi)           # > 0: the bow is the nearer end to point along w
            fresh = self._heading is None             # no end chosen yet: the nearer one
            if math.hypot(cn, ce) > MAX_ASTERN or ahead > (0.0 if fresh else ASTERN_HYSTERESIS):
                self._astern = False
            elif ahead < (0.0 if fresh else -ASTERN_HYSTERESIS):
                self._astern = True
            self._heading = axis + math.pi if self._astern else axis
        if self._astern and w > MAX_ASTERN:
            # Stern first the way back is slower, not turned round: broadside to the current while it turned bow
            # first, a boat 2 m off the breakwater was set onto it (issue 31's chaos, in-process).
            f = _within(vn, ve, cn, ce, MAX_ASTERN)
            vn, ve = f * vn, f * ve
            self._heading = math.atan2(ve - ce, vn - cn) + math.pi
        psi = self._heading
        bow = (math.cos(s.psi), math.sin(s.psi))
        u_ref = vn * bow[0] + ve * bow[1]
        return drive(s, dt, psi, u_ref, cn * bow[0] + ce * bow[1])

    def _drift_and_return(self, s: NavState, dt: float, d: float, en: float, ee: float, loiter: bool,
                          behaviour: BehaviourMachine, drive: Drive, on_resume: Callable[[], None]) -> Thrust:
        """ArduRover's boat loiter: drift within LOIT_RADIUS; beyond it steer straight back, bow first, until
        within half the radius (the way back is the water just drifted across)."""
        if not loiter or d <= 0.5 * self.radius or (behaviour.state is Behaviour.COMPLETE and d <= self.radius):
            behaviour.to(Behaviour.COMPLETE)
            self.resting = True
            return self.zero_thrust
        behaviour.to(Behaviour.RETURNING)
        if self.resting:
            self.resting = False
            on_resume()
        return drive(s, dt, math.atan2(ee, en), min(self.max_speed, max(0.3, 0.5 * d)), 0.0)


def _within(vn: float, ve: float, cn: float, ce: float, limit: float) -> float:
    """The largest f in [0, 1] with |f v - c| <= ``limit`` (m/s; |c| below it): how much of the ground velocity
    wanted ``v`` a water speed of at most ``limit`` gives in the current ``c``."""
    vv, vc, cc = vn * vn + ve * ve, vn * cn + ve * ce, cn * cn + ce * ce
    if vv < 1e-12:
        return 1.0
    return min(max((vc + math.sqrt(max(vc * vc - vv * (cc - limit * limit), 0.0))) / vv, 0.0), 1.0)
