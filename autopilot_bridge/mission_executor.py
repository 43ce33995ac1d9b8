"""The AUTO mode's mission executor (pure logic: no I/O, no clock of its own; positions NED metres).

Follows ArduPilot's AP_Mission order:

* one NAV command is active at a time (MISSION_CURRENT shows it); the DO commands that follow it, up to
  the next NAV command or DO_JUMP, run when it is reached (those before the first NAV command when the
  mission starts), so every item takes effect, and is reported reached, in mission order. (ArduPilot's
  AP_Mission starts them when the NAV command before them starts; for DO_CHANGE_SPEED after waypoint B
  that is on the way to B, where a planner of missions expects it at B.) With ``first`` = 1, item 0 is
  home (ArduPilot's convention) and never executed;
* DO_JUMP is followed when the mission advances to its next NAV command: param1 is the target item,
  param2 the number of repeats (-1: for ever); once its repeats are used up it is passed over;
* NAV_WAYPOINT completes within its acceptance radius (param2; 0: the default), or when the boat has
  passed the line through it perpendicular to the leg into it (the first item's leg begins where the
  boat was; not for the last point of a leg sequence);
  with a hold time (param1, s) the boat keeps station there that long;
* NAV_LOITER_TIME keeps station at its position (or, at 0/0, where the boat is) for param1 s;
  NAV_LOITER_UNLIM for ever (until the mode or the mission changes);
* NAV_RETURN_TO_LAUNCH goes home (the first fix, or the last DO_SET_HOME) and completes there;
* DO_CHANGE_SPEED sets the speed set-point (param2, m/s; -1 or 0: unchanged) until the mode changes;
* DO_SET_HOME sets home: here (param1 = 1) or at the item's position;
* a command stored but not executed (:data:`autopilot_bridge.mission_commands.STORED_ONLY`) is skipped
  with a STATUSTEXT.

Consecutive waypoints without hold times form one leg sequence: the planner gets them as one global
reference path ``[position, wp_k, wp_k+1, ...]``, as before mission commands existed. Every item
executed or skipped is reported once (MISSION_ITEM_REACHED); ArduPilot reports NAV items only.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import Protocol

from autopilot_bridge import mission_commands as mc
from autopilot_bridge.mission_commands import MissionCommand


class MissionHost(Protocol):
    """What the executor needs from the vehicle."""

    home: tuple[float, float] | None

    def new_route(self, path: list[tuple[float, float]], goal_radius: float, loiter: bool) -> None: ...

    def set_speed(self, speed: float) -> None: ...

    def note(self, text: str, warning: bool = False) -> None: ...

    def reached_item(self, seq: int) -> None: ...


class MissionExecutor:
    """Runs a tuple of :class:`MissionCommand` for a :class:`MissionHost`."""

    def __init__(self, commands: tuple[MissionCommand, ...], default_radius: Callable[[], float],
                 first: int = 0) -> None:
        """``default_radius()``: WP_RADIUS now (m; the vehicle owns it); ``first``: the first item
        executed (1 where item 0 is home, ArduPilot's convention)."""
        self.commands = tuple(commands)
        self._default_radius = default_radius
        self.first = first
        self.current = first if len(commands) > first else 0   # the active NAV item (MISSION_CURRENT)
        self.complete = False
        self.jumps: dict[int, int] = {}        # DO_JUMP item -> jumps done
        self.loiter_until: float | None = None  # s of vehicle time; inf: NAV_LOITER_UNLIM
        self.mission_speed: float | None = None  # m/s, the last DO_CHANGE_SPEED run (kept on resume)
        self._leg: list[int] = []              # NAV items of the active leg sequence, in order
        self._leg_points: list[tuple[float, float]] = []
        self._leg_index = 0                    # the leg item to reach next
        self._after_do = 0                     # first item after the active NAV's DO commands
        self._position: tuple[float, float] = (0.0, 0.0)
        self._leg_start: tuple[float, float] = (0.0, 0.0)   # where the boat was when the leg began

    # -- helpers ------------------------------------------------------------------------------------
    @property
    def default_radius(self) -> float:
        return self._default_radius()

    def radius(self, c: MissionCommand) -> float:
        r = c.p2 if c.command == mc.NAV_WAYPOINT else 0.0
        return float(r) if math.isfinite(r) and r > 0.0 else self.default_radius

    @staticmethod
    def _loiter_time(c: MissionCommand) -> float | None:
        """Station-keeping time (s) at the end of ``c``, inf for ever, None for none."""
        if c.command == mc.NAV_LOITER_UNLIM:
            return math.inf
        t = c.p1 if math.isfinite(c.p1) else 0.0
        if c.command == mc.NAV_LOITER_TIME:
            return max(0.0, t)
        if c.command == mc.NAV_WAYPOINT and t > 0.0:
            return t
        return None

    def _joins_leg(self, c: MissionCommand) -> bool:
        return c.command in (mc.NAV_WAYPOINT, mc.NAV_LOITER_TIME, mc.NAV_LOITER_UNLIM) and c.position is not None

    # -- starting -----------------------------------------------------------------------------------
    def start(self, seq: int, host: MissionHost, position: tuple[float, float], t: float) -> None:
        """Run from item ``seq`` (a mission start, MISSION_SET_CURRENT, entering AUTO)."""
        self._position = position
        self.complete, self.loiter_until = False, None
        nxt = self._next_nav(max(seq, self.first), host, run_do=True)
        self._begin(nxt, host, t)

    def adopt_leg(self, items: list[int], points: list[tuple[float, float]]) -> None:
        """A route that is already set (the scenario's own reference path) runs through ``items``."""
        self.complete, self.loiter_until = False, None
        self._leg, self._leg_points, self._leg_index = list(items), list(points), 0
        self._leg_start = points[0] if points else (0.0, 0.0)
        self.current = items[0] if items else 0
        self._after_do = self.current + 1

    def _next_nav(self, i: int, host: MissionHost, run_do: bool) -> int | None:
        """The next NAV item from ``i``, following DO_JUMPs; DO items met on the way run if ``run_do``."""
        n = len(self.commands)
        for _ in range(4 * n + 16):            # a DO_JUMP loop without NAV items ends here
            if i >= n:
                return None
            c = self.commands[i]
            if c.command == mc.DO_JUMP:
                target, repeat = int(c.p1) if math.isfinite(c.p1) else -1, int(c.p2) if math.isfinite(c.p2) else 0
                done = self.jumps.get(i, 0)
                host.reached_item(i)
                if not 0 <= target < n:
                    host.note(f"mission item {i}: DO_JUMP to {target}: no such item, skipped", warning=True)
                    i += 1
                elif repeat < 0 or done < repeat:
                    self.jumps[i] = done + 1
                    host.note(f"mission: jump to item {target} ({done + 1}/{'inf' if repeat < 0 else repeat})")
                    i, run_do = max(target, self.first), True
                else:
                    i += 1
                continue
            if c.is_nav:
                return i
            if run_do:
                self._do(i, host)
            i += 1
        host.note("mission: DO_JUMP loop without a NAV command, mission ended", warning=True)
        return None

    def _do(self, i: int, host: MissionHost) -> None:
        c = self.commands[i]
        if c.command == mc.DO_CHANGE_SPEED:
            if math.isfinite(c.p2) and c.p2 > 0.0:
                host.set_speed(float(c.p2))
                self.mission_speed = float(c.p2)
        elif c.command == mc.DO_SET_HOME:
            here = c.p1 == 1.0 or c.position is None
            host.home = self._position if here else c.position
            host.note(f"mission item {i}: home set {'here' if here else 'at the item'}")
        elif c.command != mc.DO_JUMP:
            host.note(f"mission item {i}: {mc.command_name(c.command)} skipped (stored, not executed here)",
                      warning=True)
        host.reached_item(i)

    def _run_dos_after(self, k: int, host: MissionHost) -> None:
        j = k + 1
        while j < len(self.commands) and not self.commands[j].is_nav and self.commands[j].command != mc.DO_JUMP:
            self._do(j, host)
            j += 1
        self._after_do = j

    def _begin(self, k: int | None, host: MissionHost, t: float) -> None:
        """Make NAV item ``k`` active and give the host its route (None: the mission is complete)."""
        self.loiter_until = None
        if k is None:
            self.complete = True
            self._leg, self._leg_points = [], []
            return
        self.current = k
        self._leg_start = self._position
        c = self.commands[k]
        if c.command not in mc.EXECUTED:        # a stored-only NAV command (NAV_DELAY, ...)
            host.note(f"mission item {k}: {mc.command_name(c.command)} skipped (stored, not executed here)",
                      warning=True)
            host.reached_item(k)
            self._begin(self._next_nav(k + 1, host, run_do=True), host, t)
            return
        if c.command == mc.NAV_RETURN_TO_LAUNCH:
            home = host.home if host.home is not None else self._position
            self._leg, self._leg_points = [k], [home]
            host.new_route([self._position, home], self.default_radius, loiter=False)
            self._leg_index = 0
            return
        leg, points = [k], [c.position if c.position is not None else self._position]
        # Consecutive waypoints join one leg sequence (no DO_JUMP in between: it is decided on arrival);
        # the DO commands between them run as the boat reaches the waypoint before them.
        n, j = len(self.commands), k + 1
        while self._loiter_time(self.commands[leg[-1]]) is None:
            while j < n and not self.commands[j].is_nav and self.commands[j].command != mc.DO_JUMP:
                j += 1
            if j >= n or not self._joins_leg(self.commands[j]):
                break
            leg.append(j)
            points.append(self.commands[j].required_position())  # _joins_leg: it has one
            j += 1
        self._leg, self._leg_points, self._leg_index = leg, points, 0
        end = self.commands[leg[-1]]
        host.new_route([self._position, *points], self.radius(end), loiter=self._loiter_time(end) is not None)

    # -- per frame ----------------------------------------------------------------------------------
    def update(self, host: MissionHost, north: float, east: float, t: float) -> None:
        """Progress from the position at vehicle time ``t`` (s)."""
        self._position = (north, east)
        if self.complete or not self._leg:
            return
        if self.loiter_until is not None:
            if t >= self.loiter_until:
                self._advance(host, t)
            return
        while self._leg_index < len(self._leg):
            k = self._leg[self._leg_index]
            c = self.commands[k]
            tn, te = self._leg_points[self._leg_index]
            last = self._leg_index == len(self._leg) - 1
            passed = False
            if not last:
                # Passed the line through the item perpendicular to the leg into it (ArduRover's test
                # too): the first item's leg starts where the boat was when the leg began.
                pn, pe = self._leg_points[self._leg_index - 1] if self._leg_index > 0 else self._leg_start
                passed = (north - tn) * (tn - pn) + (east - te) * (te - pe) > 0.0
            if math.hypot(tn - north, te - east) > self.radius(c) and not passed:
                return
            self._arrive(host, t)
            if self.loiter_until is not None or self.complete or self._leg_index == 0:
                return  # loitering, finished, or a new leg sequence began

    def _arrive(self, host: MissionHost, t: float) -> None:
        k = self._leg[self._leg_index]
        host.reached_item(k)
        if self._leg_index < len(self._leg) - 1:
            self._run_dos_after(k, host)   # the DO items between k and the next waypoint, in mission order
            self._leg_index += 1
            self.current = self._leg[self._leg_index]
            return
        hold = self._loiter_time(self.commands[k])
        if hold is not None and hold > 0.0:
            self.loiter_until = t + hold
            host.note(f"mission item {k}: loiter {'unlimited' if math.isinf(hold) else f'{hold:g} s'}")
            return
        self._advance(host, t)

    def _advance(self, host: MissionHost, t: float) -> None:
        """NAV item ``current`` is done (reached, its loiter over): its DO items, then the next NAV item."""
        self._begin(self._next_nav(self.current + 1, host, run_do=True), host, t)

    def finish_leg(self, host: MissionHost, t: float) -> None:
        """The boat is at the end of the leg sequence (the planner's goal): items of it not yet reported
        (the passing test can miss one on a curving path) count as reached."""
        if self.complete or self.loiter_until is not None:
            return
        while self._leg and self._leg_index < len(self._leg) - 1:
            self._arrive(host, t)
        if self._leg and not self.complete and self.loiter_until is None:
            self._arrive(host, t)
