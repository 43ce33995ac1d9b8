"""Who owns a mission upload, and when a rival ground station may take it over (issue 31).

The mission protocol lets one GCS upload at a time: another one's MISSION_COUNT is answered
MAV_MISSION_DENIED while the upload is under way. ArduPilot (libraries/GCS_MAVLink/
MissionItemProtocol.{h,cpp}) re-requests an item after 1 s and cancels an upload 8 s
(``upload_timeout_ms``) after the last item *or MISSION_COUNT* it received, so an owner that
re-sends MISSION_COUNT every second and never answers keeps the slot for ever. Here:

* the claim's clock is the owner's *progress*: its first MISSION_COUNT and each expected item
  that arrives; a re-sent MISSION_COUNT from the owner restarts the transfer but not the clock;
* a claim that has made no progress for ``stall_s`` (ArduPilot's 1 s re-request interval, or two
  item timeouts if that is longer) yields: a rival's MISSION_COUNT cancels it (the owner gets
  MAV_MISSION_OPERATION_CANCELLED) and starts the rival's upload.

So another GCS can upload at most ``stall_s`` after the owner stopped answering, whatever the owner sends.
"""

from __future__ import annotations

import math

UPLOAD_STALL_S = 1.0   # s (wall) without an expected item after which the upload yields to a rival


class UploadClaim:
    """The progress clock of the upload under way (the owner itself is the upload's partner)."""

    def __init__(self, item_timeout: float, stall_s: float = UPLOAD_STALL_S) -> None:
        self.stall_s = max(stall_s, 2.0 * item_timeout)
        self.progress_at = -math.inf

    def begin(self, now: float) -> None:
        """A new owner's first MISSION_COUNT (not the owner's re-sent one)."""
        self.progress_at = now

    def progress(self, now: float) -> None:
        """An expected item arrived."""
        self.progress_at = now

    def yields(self, now: float) -> bool:
        """Whether a rival may take the upload over now (its owner has stopped answering)."""
        return now - self.progress_at > self.stall_s
