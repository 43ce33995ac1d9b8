"""How the vessel follows its route: the planned/fallback behaviour as an explicit state machine.

``WAITING`` until navigation has a fix; ``IDLE`` while no mode drives the thrusters (disarmed, HOLD,
MANUAL, no route); under way ``FALLBACK`` (reactive avoidance, :mod:`autopilot_bridge.reactive`) until a
valid local path arrives, then ``PLANNED`` (line-of-sight along it); at the route's end ``COMPLETE``
(station keeping: drifting within ``loiter_radius``) and ``RETURNING`` (steering back to the end point).
A transition not in :data:`TRANSITIONS` is a bug and raises.
"""

from __future__ import annotations

from enum import Enum


class Behaviour(Enum):
    WAITING = "waiting_for_navigation"
    IDLE = "idle"
    FALLBACK = "fallback"
    PLANNED = "planned"
    COMPLETE = "complete"
    RETURNING = "returning"


B = Behaviour
UNDER_WAY = frozenset({B.FALLBACK, B.PLANNED})
STATION = frozenset({B.COMPLETE, B.RETURNING})
TRANSITIONS: dict[Behaviour, frozenset[Behaviour]] = {
    B.WAITING: frozenset({B.IDLE}),
    B.IDLE: frozenset({B.FALLBACK, B.PLANNED, B.COMPLETE, B.RETURNING}),
    B.FALLBACK: frozenset({B.PLANNED, B.COMPLETE}),
    B.PLANNED: frozenset({B.FALLBACK, B.COMPLETE}),
    B.COMPLETE: frozenset({B.RETURNING, B.FALLBACK}),
    B.RETURNING: frozenset({B.COMPLETE, B.FALLBACK}),
}


class BehaviourMachine:
    """The current :class:`Behaviour`; ``pause()``/``resume()`` go to IDLE and back to where it was."""

    def __init__(self, start: Behaviour = B.WAITING) -> None:
        self.state = start
        self._resume = B.FALLBACK

    def to(self, new: Behaviour) -> bool:
        """Go to ``new``; True if that is a change. Any state may go back to WAITING (simulator restart)
        or pause into IDLE."""
        if new == self.state:
            return False
        if new is B.IDLE:
            return self.pause()
        if new is not B.WAITING and new not in TRANSITIONS[self.state]:
            raise ValueError(f"behaviour: {self.state.name} -> {new.name} is not a transition")
        self.state = new
        return True

    def pause(self) -> bool:
        if self.state is B.IDLE:
            return False
        if self.state is not B.WAITING:
            self._resume = self.state
        self.state = B.IDLE
        return True

    def new_route(self) -> None:
        """A new route: under way again from FALLBACK (when IDLE, that is where it resumes)."""
        if self.state is B.IDLE:
            self._resume = B.FALLBACK
        elif self.state is not B.WAITING:
            self.to(B.FALLBACK)

    def resume(self) -> Behaviour:
        """From IDLE back to the behaviour it left (FALLBACK after WAITING)."""
        if self.state is B.IDLE:
            self.state = self._resume
        return self.state
