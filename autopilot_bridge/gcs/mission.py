"""The vehicle side of the MAVLink mission microservice, as a pure state machine (no sockets, no clock).

Follows https://mavlink.io/en/services/mission.html:

* upload: MISSION_COUNT -> MISSION_REQUEST_INT (seq 0..count-1, addressed to the uploading GCS's
  system and component ids) -> MISSION_ITEM_INT -> MISSION_ACK. An item that does not arrive
  within ``item_timeout`` is re-requested, at most ``retries`` times; then the upload is cancelled
  (MISSION_ACK MAV_MISSION_OPERATION_CANCELLED). An out-of-sequence item is dropped and the expected
  one re-requested (the spec: recoverable); an item beyond the announced count is
  MAV_MISSION_INVALID_SEQUENCE. Every item is validated (frame, command, coordinates, acceptance
  radius, per command: :mod:`autopilot_bridge.mission_commands`); the first bad one ends the upload
  with its MAV_MISSION_RESULT code. Only a complete,
  valid upload replaces the mission, atomically; any error or timeout leaves the old one untouched.
* download: MISSION_REQUEST_LIST -> MISSION_COUNT, then each MISSION_REQUEST_INT is answered with
  MISSION_ITEM_INT exactly as uploaded (commands stored but not executed included).
* legacy: MISSION_ITEM is accepted like MISSION_ITEM_INT (float degrees); a GCS that uploads with
  it is asked with MISSION_REQUEST, and MISSION_REQUEST is answered with MISSION_ITEM.
* MISSION_CLEAR_ALL (and an upload of count 0) clears; MISSION_SET_CURRENT selects the item to go to.
* geofence and rally plans are not supported: their uploads are refused with MAV_MISSION_UNSUPPORTED
  and their downloads report 0 items (so a GCS that asks for them does not wait).

Inputs are decoded pymavlink messages plus the time ``now`` (s, any monotonic clock); outputs are
:class:`Out` records (message name and encode() arguments) for the link to send, and
:class:`MissionEvent` records for the vehicle (replaced, cleared, set current).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

from autopilot_bridge import mission_commands as mc
from autopilot_bridge.gcs.upload_claim import UploadClaim
from common.mavlink import MAV_TYPE as M

MISSION = M.MAV_MISSION_TYPE_MISSION
SUPPORTED_FRAMES = (M.MAV_FRAME_GLOBAL, M.MAV_FRAME_GLOBAL_RELATIVE_ALT, M.MAV_FRAME_GLOBAL_INT,
                    M.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT)
SUPPORTED_COMMANDS = tuple(sorted(mc.ACCEPTED))   # executed or stored-and-skipped: see mission_commands


@dataclass(frozen=True)
class MissionItem:
    """One item as uploaded (MISSION_ITEM_INT fields); lat/lon in degE7."""

    frame: int
    command: int
    autocontinue: int
    param1: float
    param2: float        # NAV_WAYPOINT: acceptance radius, m (0 or NaN: the default)
    param3: float
    param4: float
    x: int               # latitude, degE7
    y: int               # longitude, degE7
    z: float             # altitude, m

    @property
    def lat(self) -> float:
        return self.x * 1e-7

    @property
    def lon(self) -> float:
        return self.y * 1e-7

    def acceptance_radius(self, default: float) -> float:
        r = self.param2
        return default if not math.isfinite(r) or r <= 0.0 else float(r)


@dataclass(frozen=True)
class Out:
    """A message to send: pymavlink ``<name>_encode`` arguments."""

    name: str
    args: tuple


@dataclass(frozen=True)
class MissionEvent:
    kind: str                               # "replaced" | "set_current" | "rejected"
    items: tuple[MissionItem, ...] = ()
    seq: int = 0


@dataclass
class _Upload:
    partner: tuple[int, int]
    count: int
    legacy: bool
    items: list[MissionItem] = field(default_factory=list)
    last_request: float = 0.0
    retries: int = 0


def _same(a: float, b: float) -> bool:
    return (math.isnan(a) and math.isnan(b)) or a == b


# Validation: (code, text) for a bad item, None for a good one. ``position_check`` adds the chart test.
PositionCheck = Callable[[float, float], "tuple[int, str] | None"]
# The whole upload, once complete (route through the chart): (seq, code, text) of the first bad item, or None.
MissionCheck = Callable[[tuple["MissionItem", ...]], "tuple[int, int, str] | None"]


def validate_item(item: MissionItem, position_check: PositionCheck | None = None) -> tuple[int, str] | None:
    """Frame, command, coordinates and parameters of one item (mission_commands says which commands)."""
    cmd = item.command
    if cmd not in mc.ACCEPTED:
        return M.MAV_MISSION_UNSUPPORTED, f"command {cmd} not supported"
    if cmd == mc.DO_JUMP:
        if not math.isfinite(item.param1) or item.param1 < 0:
            return M.MAV_MISSION_INVALID_PARAM1, f"DO_JUMP target {item.param1} is not an item number"
        if not math.isfinite(item.param2) or item.param2 < -1:
            return M.MAV_MISSION_INVALID_PARAM2, f"DO_JUMP repeat count {item.param2} (-1: for ever)"
    if cmd == mc.NAV_LOITER_TIME and not (math.isfinite(item.param1) and item.param1 >= 0.0):
        return M.MAV_MISSION_INVALID_PARAM1, f"loiter time {item.param1} s must be >= 0"
    if cmd == mc.NAV_WAYPOINT and math.isfinite(item.param1) and item.param1 < 0.0:
        return M.MAV_MISSION_INVALID_PARAM1, f"hold time {item.param1} s must be >= 0"
    if not has_position(item):
        return None
    if item.frame not in SUPPORTED_FRAMES:
        return M.MAV_MISSION_UNSUPPORTED_FRAME, f"frame {item.frame} not supported (global frames only)"
    if not -90.0 <= item.lat <= 90.0 or (item.x == 0 and item.y == 0):
        return M.MAV_MISSION_INVALID_PARAM5_X, f"latitude {item.lat:.7f} out of range"
    if not -180.0 <= item.lon <= 180.0:
        return M.MAV_MISSION_INVALID_PARAM6_Y, f"longitude {item.lon:.7f} out of range"
    r = item.param2
    if cmd == mc.NAV_WAYPOINT and not math.isnan(r) and (r < 0.0 or not math.isfinite(r) or r > 1000.0):
        return M.MAV_MISSION_INVALID_PARAM2, f"acceptance radius {r} out of range 0-1000 m"
    if position_check is not None:
        return position_check(item.lat, item.lon)
    return None


def has_position(item: MissionItem) -> bool:
    """Whether the item's x/y are a position the vehicle goes to or uses: always for NAV_WAYPOINT; for
    loiters and DO_SET_HOME unless 0/0 ("here") or DO_SET_HOME param1 = 1; never for the others."""
    if item.command in mc.NEEDS_POSITION:
        return True
    if item.command in (mc.NAV_LOITER_UNLIM, mc.NAV_LOITER_TIME):
        return not (item.x == 0 and item.y == 0)
    if item.command == mc.DO_SET_HOME:
        return item.param1 != 1.0 and not (item.x == 0 and item.y == 0)
    return False


class MissionServer:
    """Vehicle side of the mission protocol for one vehicle (all GCS share it)."""

    def __init__(self, items: tuple[MissionItem, ...] = (), *, system_id: int = 1, component_id: int = 1,
                 max_items: int = 200, item_timeout: float = 0.25, retries: int = 5,
                 position_check: PositionCheck | None = None, mission_check: MissionCheck | None = None) -> None:
        self.items: tuple[MissionItem, ...] = tuple(items)
        self.mission_check = mission_check
        self.sysid, self.compid = system_id, component_id
        self.max_items, self.item_timeout, self.retries = max_items, item_timeout, retries
        self.position_check = position_check
        self.upload: _Upload | None = None
        self.claim = UploadClaim(item_timeout)   # the upload's owner and when it stops owning it (issue 31)
        self.events: list[MissionEvent] = []
        self.last_reject: tuple[int, str] | None = None  # (seq, why) of the last refused item
        self.stats: dict[str, int] = {}
        self._last_done: tuple[tuple[int, int], int, float] | None = None  # partner, count, time

    def _count(self, key: str) -> None:
        self.stats[key] = self.stats.get(key, 0) + 1

    def _for_us(self, msg: Any) -> bool:
        return msg.target_system in (0, self.sysid) and msg.target_component in (0, self.compid, M.MAV_COMP_ID_ALL)

    @staticmethod
    def _ack(to: tuple[int, int], code: int, mission_type: int = MISSION) -> Out:
        return Out("mission_ack", (to[0], to[1], code, mission_type))

    def _request(self, up: _Upload, now: float) -> Out:
        up.last_request = now
        name = "mission_request" if up.legacy else "mission_request_int"
        return Out(name, (up.partner[0], up.partner[1], len(up.items), MISSION))

    # -- inputs ------------------------------------------------------------------------------
    def handle(self, msg: Any, now: float) -> list[Out]:
        """React to one decoded message (types other than the mission protocol's are ignored)."""
        kind = msg.get_type()
        handler = getattr(self, f"_on_{kind.lower()}", None)
        if handler is None or not self._for_us(msg):
            return []
        sender = (msg.get_srcSystem(), msg.get_srcComponent())
        return handler(msg, sender, now)

    def tick(self, now: float) -> list[Out]:
        """Re-request an overdue item; cancel the upload after ``retries`` re-requests."""
        up = self.upload
        if up is None or now - up.last_request < self.item_timeout:
            return []
        if up.retries >= self.retries:
            self.upload = None
            self._count("upload_timeouts")
            return [self._ack(up.partner, M.MAV_MISSION_OPERATION_CANCELLED)]
        up.retries += 1
        self._count("re_requests")
        return [self._request(up, now)]

    def _on_mission_count(self, msg: Any, sender: tuple[int, int], now: float) -> list[Out]:
        mtype = getattr(msg, "mission_type", MISSION)
        if mtype != MISSION:
            self._count("unsupported_plan_type")
            return [self._ack(sender, M.MAV_MISSION_UNSUPPORTED, mtype)]
        taken: list[Out] = []
        if self.upload is not None and self.upload.partner != sender:
            if not self.claim.yields(now):
                self.claim.denied(sender, now)
                self._count("busy")
                return [self._ack(sender, M.MAV_MISSION_DENIED)]
            taken = [self._ack(self.upload.partner, M.MAV_MISSION_OPERATION_CANCELLED)]   # its owner went silent
            self._count("upload_taken_over")
            self.upload = None
        elif self.upload is None and not self.claim.admits(sender, now):
            self._count("reserved_for_rival")
            return [self._ack(sender, M.MAV_MISSION_DENIED)]
        if msg.count > self.max_items:
            self.upload = None
            self._count("rejected_no_space")
            return taken + [self._ack(sender, M.MAV_MISSION_NO_SPACE)]
        if msg.count == 0:
            self.upload = None
            return taken + self._replace((), sender, now)
        again = self.upload   # the owner re-sent MISSION_COUNT: a restart that renews neither its claim nor its retries
        if again is None:
            self.claim.begin(sender, now)
        self.upload = _Upload(sender, int(msg.count), legacy=False)
        request = self._request(self.upload, now)
        if again is not None:
            self.upload.retries, self.upload.last_request = again.retries, again.last_request
        return taken + [request]

    def _on_mission_item_int(self, msg: Any, sender: tuple[int, int], now: float, legacy: bool = False) -> list[Out]:
        mtype = getattr(msg, "mission_type", MISSION)
        up = self.upload
        if up is None or up.partner != sender:
            # Our final ACK may have been lost: the GCS re-sends its last item. Ack it again.
            done = self._last_done
            if done and done[0] == sender and msg.seq == done[1] - 1 and now - done[2] < 5.0:
                return [self._ack(sender, M.MAV_MISSION_ACCEPTED)]
            self._count("item_without_upload")
            return [self._ack(sender, M.MAV_MISSION_INVALID_SEQUENCE, mtype)]
        if mtype != MISSION:
            self.upload = None
            return [self._ack(sender, M.MAV_MISSION_UNSUPPORTED, mtype)]
        if msg.seq >= up.count:
            self.upload = None
            self._count("rejected_sequence")
            return [self._ack(sender, M.MAV_MISSION_INVALID_SEQUENCE)]
        up.legacy = up.legacy or legacy
        if msg.seq != len(up.items):
            self._count("out_of_sequence")  # recoverable: drop it, ask again for the expected one
            return [self._request(up, now)]
        if legacy:
            x, y = int(round(msg.x * 1e7)), int(round(msg.y * 1e7))
        else:
            x, y = int(msg.x), int(msg.y)
        item = MissionItem(int(msg.frame), int(msg.command), int(msg.autocontinue), float(msg.param1),
                           float(msg.param2), float(msg.param3), float(msg.param4), x, y, float(msg.z))
        bad = validate_item(item, self.position_check)
        if bad is not None:
            self.upload = None
            self._count("rejected_item")
            self.events.append(MissionEvent("rejected", seq=int(msg.seq)))
            self.last_reject = (int(msg.seq), bad[1])
            return [self._ack(sender, bad[0])]
        up.items.append(item)
        up.retries = 0
        self.claim.progress(now)
        if len(up.items) < up.count:
            return [self._request(up, now)]
        self.upload = None
        whole = self.mission_check(tuple(up.items)) if self.mission_check is not None else None
        if whole is not None:   # e.g. an item inside an obstacle or unreachable: the old mission stays
            seq, code, why = whole
            self._count("rejected_item")
            self.events.append(MissionEvent("rejected", seq=int(seq)))
            self.last_reject = (int(seq), why)
            return [self._ack(sender, code)]
        return self._replace(tuple(up.items), sender, now)

    def _on_mission_item(self, msg: Any, sender: tuple[int, int], now: float) -> list[Out]:
        return self._on_mission_item_int(msg, sender, now, legacy=True)

    def _replace(self, items: tuple[MissionItem, ...], sender: tuple[int, int], now: float) -> list[Out]:
        self.items = items
        self._last_done = (sender, len(items), now)
        self._count("uploads_accepted")
        self.events.append(MissionEvent("replaced", items))
        return [self._ack(sender, M.MAV_MISSION_ACCEPTED)]

    def _on_mission_request_list(self, msg: Any, sender: tuple[int, int], now: float) -> list[Out]:
        mtype = getattr(msg, "mission_type", MISSION)
        count = len(self.items) if mtype == MISSION else 0
        return [Out("mission_count", (sender[0], sender[1], count, mtype))]

    def _on_mission_request_int(self, msg: Any, sender: tuple[int, int], now: float, legacy: bool = False) -> list[Out]:
        mtype = getattr(msg, "mission_type", MISSION)
        if mtype != MISSION or not 0 <= msg.seq < len(self.items):
            return [self._ack(sender, M.MAV_MISSION_INVALID_SEQUENCE, mtype)]
        it = self.items[msg.seq]
        if legacy:
            return [Out("mission_item", (sender[0], sender[1], msg.seq, it.frame, it.command, 0, it.autocontinue,
                                         it.param1, it.param2, it.param3, it.param4, it.x * 1e-7, it.y * 1e-7,
                                         it.z, MISSION))]
        return [Out("mission_item_int", (sender[0], sender[1], msg.seq, it.frame, it.command, 0, it.autocontinue,
                                         it.param1, it.param2, it.param3, it.param4, it.x, it.y, it.z, MISSION))]

    def _on_mission_request(self, msg: Any, sender: tuple[int, int], now: float) -> list[Out]:
        return self._on_mission_request_int(msg, sender, now, legacy=True)

    def _on_mission_clear_all(self, msg: Any, sender: tuple[int, int], now: float) -> list[Out]:
        mtype = getattr(msg, "mission_type", MISSION)
        if mtype not in (MISSION, M.MAV_MISSION_TYPE_ALL):
            return [self._ack(sender, M.MAV_MISSION_UNSUPPORTED, mtype)]
        if self.upload is not None and self.upload.partner != sender:
            return [self._ack(sender, M.MAV_MISSION_DENIED, mtype)]
        self.upload = None
        out = self._replace((), sender, now)
        return [self._ack(sender, M.MAV_MISSION_ACCEPTED, mtype)] if mtype != MISSION else out

    def _on_mission_set_current(self, msg: Any, sender: tuple[int, int], now: float) -> list[Out]:
        if not 0 <= msg.seq < len(self.items):
            self._count("set_current_rejected")
            return [Out("statustext", (M.MAV_SEVERITY_WARNING, f"mission: no item {msg.seq}".encode()))]
        self.events.append(MissionEvent("set_current", seq=int(msg.seq)))
        return []

    def _on_mission_ack(self, msg: Any, sender: tuple[int, int], now: float) -> list[Out]:
        return []  # the GCS's ack at the end of a download: nothing left to do

    def take_events(self) -> list[MissionEvent]:
        ev, self.events = self.events, []
        return ev


def same_items(a: MissionItem, b: MissionItem) -> bool:
    """Field-by-field equality where NaN equals NaN (unused parameters are often NaN)."""
    return all(_same(getattr(a, f), getattr(b, f)) if isinstance(getattr(a, f), float)
               else getattr(a, f) == getattr(b, f) for f in MissionItem.__dataclass_fields__)
