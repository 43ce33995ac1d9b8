"""MAVLink 2 framing of one ground-station peer: bytes in, decoded messages and reject reasons out.

Stream transports (TCP, serial) keep a partial frame between reads; datagrams do not. At most
``max_frames`` messages are decoded per call: what a datagram holds beyond that is dropped and
reported (the caller counts it as the frame budget's refusal), so one 64 KB datagram packed with
requests costs a bounded amount of work.
"""

from __future__ import annotations

from dataclasses import dataclass, field

from autopilot_bridge.gcs.signing import ReplayGuard
from common.mavlink import MALFORMED, TRUNCATED, UNKNOWN_MESSAGE, MavMessage, bad_data_reason, mavlink2, reset_parser

BUFFER_LIMIT = 1 << 16   # bytes of a stream's unparsed backlog before it is dropped


@dataclass
class Parsed:
    """One call's result: decoded messages, reject reasons, and bytes dropped by the frame budget."""

    msgs: list[MavMessage] = field(default_factory=list)
    rejects: list[str] = field(default_factory=list)
    over_budget_bytes: int = 0


class FrameParser:
    """One peer's pymavlink parser; with a :class:`ReplayGuard`, signatures are verified (shared state)."""

    def __init__(self, guard: ReplayGuard | None) -> None:
        self.mav = mavlink2.MAVLink(None, 0, 0)
        self.mav.robust_parsing = True
        if guard is not None:
            guard.install(self.mav)

    def _reset(self) -> None:
        reset_parser(self.mav)

    def defer(self, data: bytes) -> bool:
        """Keep a stream's bytes for a later :meth:`parse` (no decoding now); False (and nothing kept)
        when the backlog would exceed BUFFER_LIMIT."""
        if self.mav.buf_len() + len(data) > BUFFER_LIMIT:
            self._reset()
            return False
        self.mav.buf.extend(data)
        return True

    def parse(self, data: bytes, keep: bool, max_frames: int) -> Parsed:
        mav = self.mav
        out = Parsed()
        try:
            m = mav.parse_char(data)
            while m is not None:
                if isinstance(m, mavlink2.MAVLink_bad_data):
                    out.rejects.append(bad_data_reason(m))
                elif isinstance(m, mavlink2.MAVLink_unknown):
                    out.rejects.append(UNKNOWN_MESSAGE)
                else:
                    out.msgs.append(m)
                if len(out.msgs) + len(out.rejects) >= max_frames:
                    break
                m = mav.parse_char(b"")
        except Exception:
            out.rejects.append(MALFORMED)
            keep = False
        left = mav.buf_len()
        if left > 0 and len(out.msgs) + len(out.rejects) >= max_frames:
            out.over_budget_bytes = left
            if not keep or left > BUFFER_LIMIT:
                self._reset()
            return out
        if not keep:
            if left > 0:
                out.rejects.append(TRUNCATED)
            self._reset()
        elif left > BUFFER_LIMIT:  # a stream of garbage: do not let the buffer grow
            mav.buf, mav.buf_index = bytearray(), 0
        return out
