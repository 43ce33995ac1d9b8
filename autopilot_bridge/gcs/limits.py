"""Bounded work per service call on the ground-station port (docs/security.md, "Reads stall control").

* A frame budget: at most :data:`FRAME_BUDGET` MAVLink frames are decoded and handled per service
  call, over all transports; reading stops once it is spent (the rest waits in the socket, where the
  kernel drops what overflows). What a datagram holds beyond the budget is dropped and counted.
* Rate limits on read requests: a token bucket per request kind (:data:`READ_LIMITS`), shared by every
  peer, in wall time. A request without a token is dropped unanswered and counted
  (``rate_limited_<KIND>``): no reply larger than the request is ever sent for it.
"""

from __future__ import annotations

from collections import Counter
from dataclasses import dataclass

from common.mavlink import MAV_TYPE as M
from common.mavlink import MavMessage

FRAME_BUDGET = 32   # frames decoded and handled per service call, all transports together (~30 µs each)


@dataclass(frozen=True)
class Rate:
    """A token bucket: ``burst`` requests at once, then ``per_s`` requests per wall second."""

    burst: float
    per_s: float


# Requests that read (answered with one or more messages). Generous for a real GCS: a 200-item mission
# download (one MISSION_REQUEST_INT per item) takes about 1 s; a parameter refresh every 2 s.
READ_LIMITS: dict[str, Rate] = {
    "PARAM_REQUEST_LIST": Rate(2, 0.5),
    "PARAM_REQUEST_READ": Rate(32, 64),
    "MISSION_REQUEST_LIST": Rate(4, 2),
    "MISSION_REQUEST_INT": Rate(64, 256),
    "MISSION_REQUEST": Rate(64, 256),
    "PING": Rate(8, 10),
    "READ_COMMAND": Rate(16, 32),   # COMMAND_LONG/INT of READ_COMMANDS
}
READ_COMMANDS = frozenset({M.MAV_CMD_REQUEST_MESSAGE, M.MAV_CMD_GET_MESSAGE_INTERVAL,
                           M.MAV_CMD_REQUEST_AUTOPILOT_CAPABILITIES, M.MAV_CMD_GET_HOME_POSITION})


class _Bucket:
    def __init__(self, rate: Rate) -> None:
        self.rate = rate
        self.tokens = float(rate.burst)
        self.at: float | None = None

    def take(self, now: float) -> bool:
        if self.at is not None:
            self.tokens = min(float(self.rate.burst), self.tokens + max(0.0, now - self.at) * self.rate.per_s)
        self.at = now
        if self.tokens >= 1.0:
            self.tokens -= 1.0
            return True
        return False


class ReadLimiter:
    """Whether a read request may be answered now; refusals counted in ``counts``."""

    def __init__(self, counts: Counter[str], limits: dict[str, Rate] | None = None) -> None:
        self.counts = counts
        self.buckets = {kind: _Bucket(rate) for kind, rate in (limits or READ_LIMITS).items()}

    @staticmethod
    def kind_of(m: MavMessage, kind: str) -> str | None:
        if kind in ("COMMAND_LONG", "COMMAND_INT"):
            return "READ_COMMAND" if m.command in READ_COMMANDS else None
        return kind

    def allows(self, m: MavMessage, kind: str, now: float) -> bool:
        key = self.kind_of(m, kind)
        bucket = self.buckets.get(key) if key is not None else None
        if bucket is None or bucket.take(now):
            return True
        self.counts[f"rate_limited_{key}"] += 1
        return False
