"""The GCS-heartbeat failsafe (wall time: it watches a real link), with ArduRover's parameters.

Armed, in any mode but HOLD and RTL (as ArduRover's), no heartbeat from a ground station
(MAV_TYPE_GCS; signed when signing is on) for FS_GCS_TIMEOUT seconds triggers FS_ACTION: 1 RTL (to
the nearest rally point inside the fence, else home), 2 hold, 0 nothing. Hold is station keeping
(LOITER), never ArduRover's zero-thrust HOLD, which drifts with the current (a harbour run drifted
onto the breakwater 146 s after such a failsafe: issue 33); where RTL is refused (no home), it holds
too. FS_GCS_ENABLE 0 turns it off; 2 lets a mission in AUTO go on. A mode change, a mission start or
a goto by a GCS clears the failsafe.

ArduRover ships FS_GCS_ENABLE = 0; a boat in a current that loses its operator should not carry on
blind or drift, so it is on here by default (``[gcs] failsafe_action``, ``failsafe_timeout``).
"""

from __future__ import annotations

from collections.abc import Callable

from autopilot_bridge.gcs.context import Outbox, VehicleView
from autopilot_bridge.modes import Mode
from autopilot_bridge.parameters import Tunable
from common.mavlink import MAV_TYPE as M
from common.mavlink import MavMessage

FS_NOTHING, FS_RTL, FS_HOLD = 0, 1, 2     # FS_ACTION, ArduRover's numbers
ACTION_OF_CONFIG = {"none": FS_NOTHING, "rtl": FS_RTL, "hold": FS_HOLD}


class GcsFailsafe:
    enable = Tunable("FS_GCS_ENABLE", 0, 2, "", "GCS failsafe: 0 off, 1 on, 2 on but a mission in AUTO goes on",
                     integer=True)
    timeout = Tunable("FS_GCS_TIMEOUT", 1.0, 120.0, "s", "no GCS heartbeat for this long triggers the failsafe")
    action = Tunable("FS_ACTION", 0, 2, "",
                     "failsafe action: 0 nothing, 1 RTL (nearest rally point inside the fence, else home), "
                     "2 hold station (LOITER; ArduRover's Hold drifts)", integer=True)

    def __init__(self, out: Outbox, view: VehicleView, timeout: float, action: str,
                 require_signed: bool) -> None:
        self.out, self.view = out, view
        self.timeout = timeout            # s of wall time
        self.action = ACTION_OF_CONFIG[action]
        self.enable = 1
        self.require_signed = require_signed
        self.active = False
        self.events = 0
        self.last_heartbeat: float | None = None

    def handlers(self) -> dict[str, Callable[[MavMessage, float], None]]:
        return {"HEARTBEAT": self._on_heartbeat}

    def _on_heartbeat(self, m: MavMessage, now: float) -> None:
        if m.type == M.MAV_TYPE_GCS and (not self.require_signed or getattr(m, "_signed", False)):
            self.last_heartbeat = now

    def clear(self) -> None:
        self.active = False

    def check(self, now: float) -> None:
        """Trigger once when the heartbeat has been lost (``now``: wall s, the link's clock)."""
        st, api = self.view.status, self.view.api
        if api is None or st is None or self.last_heartbeat is None or not self.enable \
                or self.action == FS_NOTHING:
            return
        if now - self.last_heartbeat <= self.timeout:
            return
        if self.active or not st.armed or st.mode in (Mode.HOLD, Mode.RTL):
            return
        if self.enable == 2 and st.mode == Mode.AUTO:
            return
        self.active = True
        self.events += 1
        # ArduRover's Hold (FS_ACTION 2) lets a boat drift with the current; here it keeps station (LOITER).
        target = Mode.RTL if self.action == FS_RTL and st.home is not None else Mode.LOITER
        r = api.set_mode(target)
        if not r.ok and target == Mode.RTL:
            target = Mode.LOITER
            api.set_mode(target)
        what = "holding station (LOITER)" if target == Mode.LOITER else target.name
        msg = f"GCS failsafe: no heartbeat {now - self.last_heartbeat:.1f}s: {what}"
        self.out.log(f"gcs: {msg}")
        self.out.statustext(msg, M.MAV_SEVERITY_CRITICAL)
        api.record_event(msg)
