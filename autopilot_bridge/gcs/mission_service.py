"""The mission microservice on the link: :class:`autopilot_bridge.gcs.mission.MissionServer` (the pure
protocol state machine) wired to the vessel's command API, with conversions between upload items
(geodetic) and the vessel's stored commands (NED m)."""

from __future__ import annotations

import math
from collections.abc import Callable

import numpy as np

from autopilot_bridge import mission_commands as mc
from autopilot_bridge.gcs.context import Outbox, VehicleView
from autopilot_bridge.gcs.mission import FENCE, MISSION, RALLY, MissionItem, MissionServer, fence_polygons, has_position
from autopilot_bridge.mission_commands import MissionCommand
from autopilot_bridge.modes import Mode
from common.mavlink import MAV_TYPE as M
from common.mavlink import MavMessage
from planner.fence import Circle, Fence

# Every MISSION_* message the protocol state machine has a handler for.
MISSION_MESSAGES = tuple(sorted(name[len("_on_"):].upper() for name in vars(MissionServer)
                                if name.startswith("_on_mission")))
MISSION_WRITES = frozenset({"MISSION_COUNT", "MISSION_ITEM", "MISSION_ITEM_INT", "MISSION_CLEAR_ALL"})
GUIDED_GOTO = 2     # MISSION_ITEM(_INT).current: ArduPilot's guided "fly to" request, not an upload's item


class MissionService:
    def __init__(self, out: Outbox, view: VehicleView, on_changed: Callable[[], None], *, max_items: int,
                 item_timeout: float, retries: int, home_item: bool = False) -> None:
        self.out, self.view = out, view
        self.home_item = home_item       # item 0 is home (ArduPilot's convention)
        self.on_changed = on_changed     # the current item or the mission changed: MISSION_CURRENT
        self.server: MissionServer | None = None
        self._limits = (max_items, item_timeout, retries)

    def attach(self, commands: tuple[MissionCommand, ...]) -> None:
        max_items, item_timeout, retries = self._limits
        self.server = MissionServer(tuple(self.item_of(c) for c in commands), system_id=self.view.sysid,
                                    component_id=self.view.compid, max_items=max_items, item_timeout=item_timeout,
                                    retries=retries, position_check=self.view.on_chart,
                                    mission_check=self._check_mission,
                                    home=self._home_item if self.home_item else None,
                                    plan_checks={RALLY: self._check_rally})
        self.server.system_id = lambda: self.view.sysid   # SYSID_THISMAV read live, never copied

    def _home_item(self) -> MissionItem | None:
        """The home in force as mission item 0 (a NAV_WAYPOINT at home, as ArduPilot sends it)."""
        st = self.view.status
        if st is None or st.home is None:
            return None
        lat, lon = self.view.geo.sea_level_to_geodetic(*st.home)
        return MissionItem(M.MAV_FRAME_GLOBAL, M.MAV_CMD_NAV_WAYPOINT, 1, 0.0, 0.0, 0.0, 0.0,
                           int(round(lat * 1e7)), int(round(lon * 1e7)), float(self.view.geo.alt0))

    def handlers(self) -> dict[str, Callable[[MavMessage, float], None]]:
        return {name: self._on_message for name in MISSION_MESSAGES}

    def total(self) -> int:
        return len(self.server.items) if self.server is not None else 0

    def item_of(self, c: MissionCommand) -> MissionItem:
        """A stored command as a MISSION_ITEM_INT (for a mission the vessel started with)."""
        lat = lon = 0.0
        if c.position is not None:
            lat, lon = self.view.geo.sea_level_to_geodetic(*c.position)
        return MissionItem(M.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT, c.command, 1, c.p1, c.p2, c.p3, c.p4,
                           int(round(lat * 1e7)), int(round(lon * 1e7)), 0.0)

    def command_of(self, it: MissionItem) -> MissionCommand:
        north = east = None
        if has_position(it):
            north, east = self.view.geo.geodetic_to_sea_level(it.lat, it.lon)
        return MissionCommand(it.command, north, east, it.param1, it.param2, it.param3, it.param4)

    def fence_of(self, items: tuple[MissionItem, ...]) -> Fence:
        """Fence items (checked: whole polygons) as planning geometry, map frame (x east, y north) m."""
        def xy(it: MissionItem) -> tuple[float, float]:
            n, e = self.view.geo.geodetic_to_sea_level(it.lat, it.lon)
            return e, n

        polys, _ = fence_polygons(items)
        inc, exc = (tuple(np.array([xy(v) for v in run]) for cmd, run in polys if cmd == kind)
                    for kind in (M.MAV_CMD_NAV_FENCE_POLYGON_VERTEX_INCLUSION,
                                 M.MAV_CMD_NAV_FENCE_POLYGON_VERTEX_EXCLUSION))
        circles = {c: tuple(Circle(*xy(it), float(it.param1)) for it in items if it.command == c)
                   for c in (M.MAV_CMD_NAV_FENCE_CIRCLE_INCLUSION, M.MAV_CMD_NAV_FENCE_CIRCLE_EXCLUSION)}
        return Fence(inc, exc, circles[M.MAV_CMD_NAV_FENCE_CIRCLE_INCLUSION],
                     circles[M.MAV_CMD_NAV_FENCE_CIRCLE_EXCLUSION])

    def rally_of(self, items: tuple[MissionItem, ...]) -> tuple[tuple[float, float], ...]:
        return tuple(self.view.geo.geodetic_to_sea_level(it.lat, it.lon) for it in items)

    def _check_rally(self, items: tuple[MissionItem, ...]) -> tuple[int, int, str] | None:
        api = self.view.api
        bad = None if api is None else api.check_rally(self.rally_of(items))
        return None if bad is None else (bad[0], M.MAV_MISSION_INVALID, bad[1])

    def _check_mission(self, items: tuple[MissionItem, ...]) -> tuple[int, int, str] | None:
        """A complete upload's route through the chart: ``(seq, MAV_MISSION_RESULT, reason)`` or None."""
        api = self.view.api
        return None if api is None else api.check_mission(items, self.view.geo.geodetic_to_sea_level)

    def refuse(self, m: MavMessage) -> None:
        """A write refused by the security gate: MISSION_DENIED to its sender (mission writes only)."""
        if m.get_type() in MISSION_WRITES:
            self.out.send("mission_ack", m.get_srcSystem(), m.get_srcComponent(), M.MAV_MISSION_DENIED,
                          getattr(m, "mission_type", 0))

    def _on_message(self, m: MavMessage, now: float) -> None:
        if self.server is None:
            return
        if m.get_type() in ("MISSION_ITEM", "MISSION_ITEM_INT") and m.current == GUIDED_GOTO and \
                getattr(m, "mission_type", MISSION) == MISSION:
            self._guided_goto(m)
            return
        for o in self.server.handle(m, now):
            self.out.send(o.name, *o.args)
        self._events()

    def _guided_goto(self, m: MavMessage) -> None:
        """ArduPilot's guided "fly to": a NAV_WAYPOINT item with current = 2, outside any upload (MAVProxy's
        ``guided LAT LON ALT``, QGroundControl's "Go to location" on an ArduPilot vehicle). Taken in GUIDED
        only, as ArduRover takes it, and checked as any GUIDED target; answered with MISSION_ACK."""
        api, st = self.view.api, self.view.status
        if m.get_type() == "MISSION_ITEM_INT":
            lat, lon = m.x * 1e-7, m.y * 1e-7
        else:
            lat, lon = float(m.x), float(m.y)
        why = None
        if api is None or st is None:
            why = "guided goto: no vessel yet"
        elif m.command != M.MAV_CMD_NAV_WAYPOINT:
            why = f"guided goto: command {m.command} is not NAV_WAYPOINT"
        elif st.mode is not Mode.GUIDED:
            why = f"guided goto: in {st.mode.name}, not GUIDED (switch to GUIDED first, as on ArduRover)"
        elif not (math.isfinite(lat) and math.isfinite(lon)) or not (-90.0 <= lat <= 90.0 and -180.0 <= lon <= 180.0):
            why = "guided goto: bad latitude/longitude"
        else:
            off = self.view.on_chart(lat, lon)
            if off is not None:
                why = f"guided goto: {off[1]}"
            else:
                r = api.goto(*self.view.geo.geodetic_to_sea_level(lat, lon))
                why = None if r.ok else r.text
        result = M.MAV_MISSION_ACCEPTED if why is None else M.MAV_MISSION_ERROR
        if why is not None:
            self.out.statustext(why, M.MAV_SEVERITY_WARNING)
        self.out.send("mission_ack", m.get_srcSystem(), m.get_srcComponent(), result, MISSION)

    def tick(self, now: float) -> None:
        """Re-requests and timeouts of an upload under way."""
        if self.server is None:
            return
        for o in self.server.tick(now):
            self.out.send(o.name, *o.args)
        self._events()

    def _events(self) -> None:
        server, api = self.server, self.view.api
        assert server is not None
        for ev in server.take_events():
            if ev.kind == "replaced" and api is not None and ev.mission_type == FENCE:
                fence = self.fence_of(ev.items)
                api.replace_fence(fence)
                self.out.statustext(f"fence: {len(ev.items)} items accepted" if ev.items else "fence cleared")
            elif ev.kind == "replaced" and api is not None and ev.mission_type == RALLY:
                api.replace_rally(self.rally_of(ev.items))
                self.out.statustext(f"rally: {len(ev.items)} points accepted" if ev.items else "rally points cleared")
            elif ev.kind == "replaced" and api is not None and ev.mission_type == MISSION:
                commands = tuple(self.command_of(it) for it in ev.items)
                api.replace_mission(commands)
                skipped = sum(c.command in mc.STORED_ONLY for c in commands)
                self.out.statustext((f"mission: {len(commands)} items accepted"
                                     + (f" ({skipped} stored, not executed)" if skipped else ""))
                                    if commands else "mission cleared")
                self.on_changed()
            elif ev.kind == "set_current" and api is not None:
                api.set_mission_current(ev.seq)
                self.on_changed()
            elif ev.kind == "rejected" and server.last_reject is not None:
                seq, why = server.last_reject
                kind = {FENCE: "fence", RALLY: "rally"}.get(ev.mission_type, "mission")
                self.out.statustext(f"{kind} item {seq} rejected: {why}", M.MAV_SEVERITY_WARNING)
