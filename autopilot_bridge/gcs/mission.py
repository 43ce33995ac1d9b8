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
* geofence and rally plans (``mission_type`` FENCE and RALLY) travel the same way, each stored on its
  own: fence items are inclusion/exclusion polygon vertices and circles (MAV_CMD_NAV_FENCE_*), rally
  items are MAV_CMD_NAV_RALLY_POINT; each type has its own whole-plan check (``plan_checks``), cleared
  with MISSION_CLEAR_ALL of its type (or MAV_MISSION_TYPE_ALL).

Inputs are decoded pymavlink messages plus the time ``now`` (s, any monotonic clock); outputs are
:class:`Out` records (message name and encode() arguments) for the link to send, and
:class:`MissionEvent` records for the vehicle (replaced, cleared, set current).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field

from autopilot_bridge import mission_commands as mc
from autopilot_bridge.gcs.upload_claim import UploadClaim
from common.mavlink import MAV_TYPE as M
from common.mavlink import MavMessage

MISSION = M.MAV_MISSION_TYPE_MISSION
FENCE = M.MAV_MISSION_TYPE_FENCE
RALLY = M.MAV_MISSION_TYPE_RALLY
PLAN_TYPES = (MISSION, FENCE, RALLY)
FENCE_COMMANDS = (M.MAV_CMD_NAV_FENCE_POLYGON_VERTEX_INCLUSION, M.MAV_CMD_NAV_FENCE_POLYGON_VERTEX_EXCLUSION,
                  M.MAV_CMD_NAV_FENCE_CIRCLE_INCLUSION, M.MAV_CMD_NAV_FENCE_CIRCLE_EXCLUSION,
                  M.MAV_CMD_NAV_FENCE_RETURN_POINT)
RALLY_COMMANDS = (M.MAV_CMD_NAV_RALLY_POINT,)
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
    mission_type: int = MISSION


@dataclass
class _Upload:
    partner: tuple[int, int]
    count: int
    legacy: bool
    mission_type: int = MISSION
    items: list[MissionItem] = field(default_factory=list)
    last_request: float = 0.0
    retries: int = 0


def _same(a: float, b: float) -> bool:
    return (math.isnan(a) and math.isnan(b)) or a == b


# Validation: (code, text) for a bad item, None for a good one. ``position_check`` adds the chart test.
PositionCheck = Callable[[float, float], "tuple[int, str] | None"]
# The whole upload, once complete (route through the chart): (seq, code, text) of the first bad item, or None.
MissionCheck = Callable[[tuple["MissionItem", ...]], "tuple[int, int, str] | None"]


def validate_fence_or_rally(item: MissionItem, mission_type: int,
                            position_check: PositionCheck | None = None) -> tuple[int, str] | None:
    """One fence or rally item: its command, coordinates and radius or vertex count."""
    cmd = item.command
    allowed = FENCE_COMMANDS if mission_type == FENCE else RALLY_COMMANDS
    if cmd not in allowed:
        return M.MAV_MISSION_UNSUPPORTED, f"command {cmd} is not a {'fence' if mission_type == FENCE else 'rally'} item"
    if not -90.0 <= item.lat <= 90.0 or (item.x == 0 and item.y == 0):
        return M.MAV_MISSION_INVALID_PARAM5_X, f"latitude {item.lat:.7f} out of range"
    if not -180.0 <= item.lon <= 180.0:
        return M.MAV_MISSION_INVALID_PARAM6_Y, f"longitude {item.lon:.7f} out of range"
    if cmd in (M.MAV_CMD_NAV_FENCE_CIRCLE_INCLUSION, M.MAV_CMD_NAV_FENCE_CIRCLE_EXCLUSION) and \
            not (math.isfinite(item.param1) and 0.0 < item.param1 <= 100e3):
        return M.MAV_MISSION_INVALID_PARAM1, f"fence circle radius {item.param1} m"
    if cmd in (M.MAV_CMD_NAV_FENCE_POLYGON_VERTEX_INCLUSION, M.MAV_CMD_NAV_FENCE_POLYGON_VERTEX_EXCLUSION) and \
            not (math.isfinite(item.param1) and 3 <= item.param1 <= 1000 and item.param1 == int(item.param1)):
        return M.MAV_MISSION_INVALID_PARAM1, f"fence polygon vertex count {item.param1} (3 or more)"
    if mission_type == RALLY and position_check is not None:
        return position_check(item.lat, item.lon)
    return None


def fence_polygons(items: tuple[MissionItem, ...]) -> tuple[list[tuple[int, list[MissionItem]]], str | None]:
    """The fence items' polygons as (command, vertices) runs, each as long as its vertices' count; or why not."""
    polys: list[tuple[int, list[MissionItem]]] = []
    i = 0
    while i < len(items):
        it = items[i]
        if it.command in (M.MAV_CMD_NAV_FENCE_POLYGON_VERTEX_INCLUSION, M.MAV_CMD_NAV_FENCE_POLYGON_VERTEX_EXCLUSION):
            n = int(it.param1)
            run = list(items[i:i + n])
            if len(run) < n or any(v.command != it.command or int(v.param1) != n for v in run):
                return polys, f"fence item {i}: a polygon of {n} vertices needs {n} such items in a row"
            polys.append((it.command, run))
            i += n
        else:
            i += 1
    return polys, None


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
    if cmd == mc.DO_CHANGE_SPEED and not (math.isfinite(item.param2) and (item.param2 >= 0.0
                                                                       or item.param2 in (-1.0, -2.0))):
        return M.MAV_MISSION_INVALID_PARAM2, f"DO_CHANGE_SPEED speed {item.param2} m/s (-1: unchanged)"
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
                 position_check: PositionCheck | None = None, mission_check: MissionCheck | None = None,
                 home: Callable[[], MissionItem | None] | None = None,
                 plan_checks: dict[int, MissionCheck] | None = None) -> None:
        """``home``: where item 0 is home (ArduPilot's convention), the current home as an item (None
        before there is one); an uploaded item 0 is then stored as it came and not checked, and a
        download's item 0 is the home in force. ``plan_checks``: the whole-plan check of the FENCE and
        RALLY types (the MISSION type's is ``mission_check``)."""
        self.plans: dict[int, tuple[MissionItem, ...]] = {MISSION: tuple(items), FENCE: (), RALLY: ()}
        self.home = home
        self.plan_checks = dict(plan_checks or {})
        self.mission_check = mission_check
        if mission_check is not None:
            self.plan_checks[MISSION] = mission_check
        self._sysid, self.compid = system_id, component_id
        self.system_id: Callable[[], int] = lambda: self._sysid   # the link sets it to read SYSID_THISMAV live
        self.max_items, self.item_timeout, self.retries = max_items, item_timeout, retries
        self.position_check = position_check
        self.upload: _Upload | None = None
        self.claim = UploadClaim(item_timeout)   # the upload's owner and when it stops owning it (issue 31)
        self.events: list[MissionEvent] = []
        self.last_reject: tuple[int, str] | None = None  # (seq, why) of the last refused item
        self.stats: dict[str, int] = {}
        self._last_done: tuple[tuple[int, int], int, float] | None = None  # partner, count, time

    @property
    def items(self) -> tuple[MissionItem, ...]:
        """The mission (MISSION type)."""
        return self.plans[MISSION]

    @items.setter
    def items(self, items: tuple[MissionItem, ...]) -> None:
        self.plans[MISSION] = tuple(items)

    @property
    def sysid(self) -> int:
        return self.system_id()

    def _count(self, key: str) -> None:
        self.stats[key] = self.stats.get(key, 0) + 1

    def _for_us(self, msg: MavMessage) -> bool:
        return (msg.target_system in (0, self.system_id())
                and msg.target_component in (0, self.compid, M.MAV_COMP_ID_ALL))

    @staticmethod
    def _ack(to: tuple[int, int], code: int, mission_type: int = MISSION) -> Out:
        return Out("mission_ack", (to[0], to[1], code, mission_type))

    def _request(self, up: _Upload, now: float) -> Out:
        up.last_request = now
        name = "mission_request" if up.legacy else "mission_request_int"
        return Out(name, (up.partner[0], up.partner[1], len(up.items), up.mission_type))

    # -- inputs ------------------------------------------------------------------------------
    def handle(self, msg: MavMessage, now: float) -> list[Out]:
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
            return [self._ack(up.partner, M.MAV_MISSION_OPERATION_CANCELLED, up.mission_type)]
        up.retries += 1
        self._count("re_requests")
        return [self._request(up, now)]

    def _on_mission_count(self, msg: MavMessage, sender: tuple[int, int], now: float) -> list[Out]:
        mtype = getattr(msg, "mission_type", MISSION)
        if mtype not in PLAN_TYPES:
            self._count("unsupported_plan_type")
            return [self._ack(sender, M.MAV_MISSION_UNSUPPORTED, mtype)]
        taken: list[Out] = []
        if self.upload is not None and self.upload.partner != sender:
            if not self.claim.yields(now):
                self.claim.denied(sender, now)
                self._count("busy")
                return [self._ack(sender, M.MAV_MISSION_DENIED, mtype)]
            # its owner went silent
            taken = [self._ack(self.upload.partner, M.MAV_MISSION_OPERATION_CANCELLED, self.upload.mission_type)]
            self._count("upload_taken_over")
            self.upload = None
        elif self.upload is None and not self.claim.admits(sender, now):
            self._count("reserved_for_rival")
            return [self._ack(sender, M.MAV_MISSION_DENIED, mtype)]
        if msg.count > self.max_items:
            self.upload = None
            self._count("rejected_no_space")
            return taken + [self._ack(sender, M.MAV_MISSION_NO_SPACE, mtype)]
        if msg.count == 0:
            self.upload = None
            return taken + self._replace((), sender, now, mtype)
        again = self.upload   # the owner re-sent MISSION_COUNT: a restart that renews neither its claim nor its retries
        if again is None:
            self.claim.begin(sender, now)
        self.upload = _Upload(sender, int(msg.count), legacy=False, mission_type=mtype)
        request = self._request(self.upload, now)
        if again is not None:
            self.upload.retries, self.upload.last_request = again.retries, again.last_request
        return taken + [request]

    def _on_mission_item_int(self, msg: MavMessage, sender: tuple[int, int], now: float,
                             legacy: bool = False) -> list[Out]:
        mtype = getattr(msg, "mission_type", MISSION)
        up = self.upload
        if up is None or up.partner != sender:
            # Our final ACK may have been lost: the GCS re-sends its last item. Ack it again.
            done = self._last_done
            if done and done[0] == sender and msg.seq == done[1] - 1 and now - done[2] < 5.0:
                return [self._ack(sender, M.MAV_MISSION_ACCEPTED)]
            self._count("item_without_upload")
            return [self._ack(sender, M.MAV_MISSION_INVALID_SEQUENCE, mtype)]
        if mtype != up.mission_type:
            self.upload = None
            return [self._ack(sender, M.MAV_MISSION_INVALID_SEQUENCE, mtype)]
        if msg.seq >= up.count:
            self.upload = None
            self._count("rejected_sequence")
            return [self._ack(sender, M.MAV_MISSION_INVALID_SEQUENCE, mtype)]
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
        if mtype != MISSION:
            bad = validate_fence_or_rally(item, mtype, self.position_check)
        elif self.home is not None and msg.seq == 0:
            bad = None
        else:
            bad = validate_item(item, self.position_check)
        if bad is not None:
            self.upload = None
            self._count("rejected_item")
            self.events.append(MissionEvent("rejected", seq=int(msg.seq), mission_type=mtype))
            self.last_reject = (int(msg.seq), bad[1])
            return [self._ack(sender, bad[0], mtype)]
        up.items.append(item)
        up.retries = 0
        self.claim.progress(now)
        if len(up.items) < up.count:
            return [self._request(up, now)]
        self.upload = None
        whole = self._check_plan(tuple(up.items), mtype)
        if whole is not None:   # e.g. an item inside an obstacle or unreachable: the old plan stays
            seq, code, why = whole
            self._count("rejected_item")
            self.events.append(MissionEvent("rejected", seq=int(seq), mission_type=mtype))
            self.last_reject = (int(seq), why)
            return [self._ack(sender, code, mtype)]
        return self._replace(tuple(up.items), sender, now, mtype)

    def _check_plan(self, items: tuple[MissionItem, ...], mtype: int) -> tuple[int, int, str] | None:
        if mtype == FENCE:
            _, why = fence_polygons(items)
            if why is not None:
                return 0, M.MAV_MISSION_INVALID_PARAM1, why
        check = self.plan_checks.get(mtype)
        return check(items) if check is not None else None

    def _on_mission_item(self, msg: MavMessage, sender: tuple[int, int], now: float) -> list[Out]:
        return self._on_mission_item_int(msg, sender, now, legacy=True)

    def _replace(self, items: tuple[MissionItem, ...], sender: tuple[int, int], now: float,
                 mtype: int = MISSION) -> list[Out]:
        self.plans[mtype] = items
        if mtype == MISSION:
            self._last_done = (sender, len(items), now)
        self._count("uploads_accepted" if mtype == MISSION else f"{_TYPE_NAMES[mtype]}_uploads_accepted")
        self.events.append(MissionEvent("replaced", items, mission_type=mtype))
        return [self._ack(sender, M.MAV_MISSION_ACCEPTED, mtype)]

    def _on_mission_request_list(self, msg: MavMessage, sender: tuple[int, int], now: float) -> list[Out]:
        mtype = getattr(msg, "mission_type", MISSION)
        count = len(self.plans.get(mtype, ()))
        return [Out("mission_count", (sender[0], sender[1], count, mtype))]

    def _on_mission_request_int(self, msg: MavMessage, sender: tuple[int, int], now: float,
                                legacy: bool = False) -> list[Out]:
        mtype = getattr(msg, "mission_type", MISSION)
        plan = self.plans.get(mtype, ())
        if not 0 <= msg.seq < len(plan):
            return [self._ack(sender, M.MAV_MISSION_INVALID_SEQUENCE, mtype)]
        it = plan[msg.seq]
        if mtype == MISSION and msg.seq == 0 and self.home is not None:
            it = self.home() or it
        if legacy:
            return [Out("mission_item", (sender[0], sender[1], msg.seq, it.frame, it.command, 0, it.autocontinue,
                                         it.param1, it.param2, it.param3, it.param4, it.x * 1e-7, it.y * 1e-7,
                                         it.z, mtype))]
        return [Out("mission_item_int", (sender[0], sender[1], msg.seq, it.frame, it.command, 0, it.autocontinue,
                                         it.param1, it.param2, it.param3, it.param4, it.x, it.y, it.z, mtype))]

    def _on_mission_request(self, msg: MavMessage, sender: tuple[int, int], now: float) -> list[Out]:
        return self._on_mission_request_int(msg, sender, now, legacy=True)

    def _on_mission_clear_all(self, msg: MavMessage, sender: tuple[int, int], now: float) -> list[Out]:
        mtype = getattr(msg, "mission_type", MISSION)
        if mtype not in (*PLAN_TYPES, M.MAV_MISSION_TYPE_ALL):
            return [self._ack(sender, M.MAV_MISSION_UNSUPPORTED, mtype)]
        if self.upload is not None and self.upload.partner != sender:
            return [self._ack(sender, M.MAV_MISSION_DENIED, mtype)]
        self.upload = None
        for t in (PLAN_TYPES if mtype == M.MAV_MISSION_TYPE_ALL else (mtype,)):
            if t == MISSION or self.plans[t]:
                self._replace((), sender, now, t)
        return [self._ack(sender, M.MAV_MISSION_ACCEPTED, mtype)]

    def _on_mission_set_current(self, msg: MavMessage, sender: tuple[int, int], now: float) -> list[Out]:
        if not 0 <= msg.seq < len(self.items):
            self._count("set_current_rejected")
            return [Out("statustext", (M.MAV_SEVERITY_WARNING, f"mission: no item {msg.seq}".encode()))]
        self.events.append(MissionEvent("set_current", seq=int(msg.seq)))
        return []

    def _on_mission_ack(self, msg: MavMessage, sender: tuple[int, int], now: float) -> list[Out]:
        return []  # the GCS's ack at the end of a download: nothing left to do

    def take_events(self) -> list[MissionEvent]:
        ev, self.events = self.events, []
        return ev


_TYPE_NAMES = {MISSION: "mission", FENCE: "fence", RALLY: "rally"}


def same_items(a: MissionItem, b: MissionItem) -> bool:
    """Field-by-field equality where NaN equals NaN (unused parameters are often NaN)."""
    return all(_same(getattr(a, f), getattr(b, f)) if isinstance(getattr(a, f), float)
               else getattr(a, f) == getattr(b, f) for f in MissionItem.__dataclass_fields__)
