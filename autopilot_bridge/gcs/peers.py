"""Who the ground-station link answers: a bounded table of peers that earned their place (issue 31).

A sender becomes a peer only once one of its frames has passed the security gate
(:meth:`autopilot_bridge.gcs.signing.SecurityGate.peer_rank` gives the frame's rank):

* :data:`RANK_SIGNED` - a frame signed with the link's key, with a fresh timestamp;
* :data:`RANK_GCS` - without signing: a frame that talks to the vessel as a ground station does
  (a HEARTBEAT of type MAV_TYPE_GCS, or a write the gate let through);
* :data:`RANK_STRANGER` - any other valid frame that passed the gate (a read request, a HEARTBEAT
  of another type; with signing on, every unsigned frame).

A full table admits a newcomer only in place of a peer of a lower rank, or of a peer not heard for
:data:`PEER_STALE_S` (a ground station sends a HEARTBEAT every second; five missed ones mean it has
gone): the least recently heard of the lowest rank goes first. A newcomer that finds no such peer
is refused (``peer_table_full``) and the peers keep their places: strangers can never push out a
ground station that keeps talking, and with signing on they never outrank a signed one.
"""

from __future__ import annotations

from collections import Counter
from collections.abc import Callable, Hashable, Iterator
from dataclasses import dataclass

RANK_STRANGER = 0
RANK_GCS = 1
RANK_SIGNED = 2
PEER_STALE_S = 5.0   # s (wall) without a frame after which a peer may give its place to anyone


@dataclass
class _Entry:
    rank: int
    heard_at: float   # s, the table's clock


class PeerTable:
    """At most ``capacity`` peers, each with the highest rank it earned and when it was last heard."""

    def __init__(self, capacity: int, clock: Callable[[], float], counts: Counter[str] | None = None,
                 stale_s: float = PEER_STALE_S) -> None:
        if capacity < 1:
            raise ValueError(f"peer table capacity {capacity} must be >= 1")
        self.capacity = capacity
        self.clock = clock
        self.stale_s = stale_s
        self.counts: Counter[str] = counts if counts is not None else Counter()
        self._entries: dict[Hashable, _Entry] = {}

    def __contains__(self, peer: Hashable) -> bool:
        return peer in self._entries

    def __iter__(self) -> Iterator[Hashable]:
        return iter(list(self._entries))

    def __len__(self) -> int:
        return len(self._entries)

    def rank(self, peer: Hashable) -> int | None:
        e = self._entries.get(peer)
        return e.rank if e is not None else None

    def heard_at(self, peer: Hashable) -> float | None:
        e = self._entries.get(peer)
        return e.heard_at if e is not None else None

    def earn(self, peer: Hashable, rank: int) -> tuple[bool, Hashable | None]:
        """Record a frame of ``rank`` from ``peer``: (whether it is a peer now, the peer it displaced or None)."""
        now = self.clock()
        e = self._entries.get(peer)
        if e is not None:
            e.rank, e.heard_at = max(e.rank, rank), now
            return True, None
        victim = None
        if len(self._entries) >= self.capacity:
            victim = self._victim(rank, now)
            if victim is None:
                self.counts["peer_table_full"] += 1
                return False, None
            del self._entries[victim]
            self.counts["peer_displaced"] += 1
        self._entries[peer] = _Entry(rank, now)
        return True, victim

    def _victim(self, rank: int, now: float) -> Hashable | None:
        best: tuple[int, float] | None = None
        victim = None
        for peer, e in self._entries.items():
            if e.rank >= rank and now - e.heard_at <= self.stale_s:
                continue   # an equal or better peer that still talks keeps its place
            key = (e.rank, e.heard_at)
            if best is None or key < best:
                best, victim = key, peer
        return victim

    def drop(self, peer: Hashable) -> None:
        self._entries.pop(peer, None)

    def idle(self, idle_s: float) -> list[Hashable]:
        """Peers not heard for more than ``idle_s`` (s)."""
        now = self.clock()
        return [p for p, e in self._entries.items() if now - e.heard_at > idle_s]
