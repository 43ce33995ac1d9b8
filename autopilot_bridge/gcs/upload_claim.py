"""Who owns a mission upload, and when another ground station gets its turn (issue 31).

The mission protocol lets one GCS upload at a time: another one's MISSION_COUNT is answered
MAV_MISSION_DENIED while the upload is under way. ArduPilot (libraries/GCS_MAVLink/
MissionItemProtocol.{h,cpp}) re-requests an item after 1 s and cancels an upload 8 s
(``upload_timeout_ms``) after the last item *or MISSION_COUNT* it received, so an owner that
re-sends MISSION_COUNT every second and never answers keeps the slot for ever (the issue measured
14 denials of 14 tries in 6 s). Here:

* the claim's clock is the owner's *progress*: its first MISSION_COUNT and each expected item that
  arrives; a re-sent MISSION_COUNT from the owner restarts the transfer but not the clock;
* a claim yields to a rival once its owner has sent no expected item for ``stall_s`` (ArduPilot's
  1 s re-request interval, or two item timeouts if that is longer), or once it has lasted
  ``hold_s`` (ArduPilot's 8 s upload timeout) whatever the owner does: a rival's MISSION_COUNT then
  cancels it (the owner gets MAV_MISSION_OPERATION_CANCELLED) and starts the rival's upload;
* a rival that was denied is owed the next turn for ``reserve_s``: nobody else may start an upload
  meanwhile (``reserved_for_rival``), so an owner cannot start a fresh claim each time its last one
  ends.

So a GCS that was denied gets the upload on a retry made between ``stall_s`` and ``reserve_s`` after
the denial, as long as the owner has stopped answering; at worst ``hold_s`` after the owner began.
"""

from __future__ import annotations

import math
from collections.abc import Hashable

UPLOAD_STALL_S = 1.0    # s (wall) without an expected item after which the upload yields to a rival
UPLOAD_HOLD_S = 8.0     # s (wall) after which any upload yields to a rival (ArduPilot's upload_timeout_ms)
RIVAL_RESERVE_S = 5.0   # s (wall) a denied rival is owed the next turn


class UploadClaim:
    """The progress clock of the upload under way and the rival owed the next turn."""

    def __init__(self, item_timeout: float, stall_s: float = UPLOAD_STALL_S, hold_s: float = UPLOAD_HOLD_S,
                 reserve_s: float = RIVAL_RESERVE_S) -> None:
        self.stall_s = max(stall_s, 2.0 * item_timeout)
        self.hold_s = max(hold_s, self.stall_s)
        self.reserve_s = max(reserve_s, 2.0 * self.stall_s)
        self.started_at = self.progress_at = -math.inf
        self.rival: Hashable | None = None
        self.rival_until = -math.inf

    def admits(self, sender: Hashable, now: float) -> bool:
        """Whether ``sender`` may start an upload now (none under way): no other rival is owed the turn."""
        return self.rival is None or self.rival == sender or now > self.rival_until

    def begin(self, owner: Hashable, now: float) -> None:
        """A new owner's first MISSION_COUNT (not the owner's re-sent one)."""
        self.started_at = self.progress_at = now
        if self.rival == owner:
            self.rival = None

    def progress(self, now: float) -> None:
        """An expected item arrived."""
        self.progress_at = now

    def yields(self, now: float) -> bool:
        """Whether a rival may take the upload over now."""
        return now - self.progress_at > self.stall_s or now - self.started_at > self.hold_s

    def denied(self, rival: Hashable, now: float) -> None:
        """``rival`` was refused while the upload was under way: it is owed the next turn (the first one
        refused keeps it until it expires)."""
        if self.rival is None or now > self.rival_until:
            self.rival, self.rival_until = rival, now + self.reserve_s
