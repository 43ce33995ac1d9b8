"""The parameter microservice (https://mavlink.io/en/services/parameter.html) over the table that
:func:`autopilot_bridge.parameters.bind` makes from every component's declarations.

PARAM_REQUEST_LIST starts a dump that is paced: at most :data:`DUMP_PER_CALL` PARAM_VALUE per service
call (:meth:`ParameterService.tick`, at the end of the call), and one dump at a time. A list request
while a dump is pending or under way joins it (counted as ``param_list_coalesced``), so a datagram
packed with list requests costs one dump, not one per request.
PARAM_SET (a write: signed when signing is on) answers with the value in force, changed or not.
"""

from __future__ import annotations

from collections import Counter
from collections.abc import Callable

from autopilot_bridge.gcs.context import Outbox, VehicleView, text_of
from autopilot_bridge.parameters import ParamTable
from common.mavlink import MAV_TYPE as M
from common.mavlink import MavMessage

DUMP_PER_CALL = 16   # PARAM_VALUE of a list dump sent per service call


class ParameterService:
    def __init__(self, out: Outbox, view: VehicleView, security: Counter[str]) -> None:
        self.out, self.view = out, view
        self.security = security
        self.table: ParamTable | None = None
        self._dump_next: int | None = None   # index of the next PARAM_VALUE of the dump under way

    def attach(self, table: ParamTable) -> None:
        self.table = table

    def handlers(self) -> dict[str, Callable[[MavMessage, float], None]]:
        return {"PARAM_REQUEST_LIST": self._on_request_list, "PARAM_REQUEST_READ": self._on_request_read,
                "PARAM_SET": self._on_set}

    def _for_us(self, m: MavMessage) -> bool:
        return self.table is not None and getattr(m, "target_system", self.view.sysid) in (0, self.view.sysid)

    def _value(self, i: int) -> None:
        t = self.table
        assert t is not None
        p = t.params[i]
        self.out.send("param_value", p.name.encode(), float(p.get()), M.MAV_PARAM_TYPE_REAL32, len(t), i)

    def tick(self) -> None:
        """Send the next part of a dump under way."""
        if self._dump_next is None or self.table is None:
            return
        end = min(self._dump_next + DUMP_PER_CALL, len(self.table))
        for i in range(self._dump_next, end):
            self._value(i)
        self._dump_next = end if end < len(self.table) else None

    @property
    def dumping(self) -> bool:
        return self._dump_next is not None

    def _on_request_list(self, m: MavMessage, now: float) -> None:
        if not self._for_us(m):
            return
        if self._dump_next is not None:
            self.security["param_list_coalesced"] += 1
            return
        self._dump_next = 0   # sent from tick(), after every request of this service call joined it

    def _on_request_read(self, m: MavMessage, now: float) -> None:
        if not self._for_us(m):
            return
        t = self.table
        assert t is not None
        i = m.param_index if m.param_index >= 0 else t.index.get(text_of(m.param_id), -1)
        if 0 <= i < len(t):
            self._value(i)

    def _on_set(self, m: MavMessage, now: float) -> None:
        if not self._for_us(m):
            return
        t = self.table
        assert t is not None
        name = text_of(m.param_id)
        ok, why = t.set(name, float(m.param_value))
        if name in t.index:
            self._value(t.index[name])  # the value now in force, changed or not
        if not ok:
            self.out.statustext(why, M.MAV_SEVERITY_WARNING)
        else:
            self.out.log(f"gcs: {why}")
