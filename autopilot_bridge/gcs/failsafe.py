"""The GCS-heartbeat failsafe (wall time: it watches a real link).

In AUTO and armed, no heartbeat from a ground station (MAV_TYPE_GCS; signed when signing is on) for
``FS_GCS_TIMEOUT`` seconds switches to HOLD, or to RTL when ``FS_GCS_ACTION`` = 2 and a home is set.
It declares its own parameters (:meth:`GcsFailsafe.parameters`). A mode change, a mission start or a
goto by a GCS clears the failsafe.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

from autopilot_bridge.gcs.context import Outbox, VehicleView
from autopilot_bridge.modes import Mode
from autopilot_bridge.parameters import Param
from common.mavlink import MAV_TYPE as M

ACTIONS = ("none", "hold", "rtl")


class GcsFailsafe:
    def __init__(self, out: Outbox, view: VehicleView, timeout: float, action: str,
                 require_signed: bool) -> None:
        self.out, self.view = out, view
        self.timeout = timeout            # s of wall time
        self.action = action              # one of ACTIONS
        self.require_signed = require_signed
        self.active = False
        self.events = 0
        self.last_heartbeat: float | None = None

    def handlers(self) -> dict[str, Callable[[Any, float], None]]:
        return {"HEARTBEAT": self._on_heartbeat}

    def _on_heartbeat(self, m: Any, now: float) -> None:
        if m.type == M.MAV_TYPE_GCS and (not self.require_signed or getattr(m, "_signed", False)):
            self.last_heartbeat = now

    def clear(self) -> None:
        self.active = False

    def parameters(self) -> list[Param]:
        """FS_GCS_TIMEOUT and FS_GCS_ACTION (ArduPilot's names)."""

        def set_action(v: float) -> None:
            if v != int(v):
                raise ValueError("must be 0, 1 or 2")
            self.action = ACTIONS[int(round(v))]

        def set_timeout(v: float) -> None:
            self.timeout = v

        return [
            Param("FS_GCS_TIMEOUT", lambda: self.timeout, set_timeout,
                  1.0, 120.0, "no GCS heartbeat for this long in AUTO triggers the failsafe", "s"),
            Param("FS_GCS_ACTION", lambda: float(ACTIONS.index(self.action)), set_action,
                  0.0, 2.0, "GCS failsafe action: 0 none, 1 hold, 2 return to launch"),
        ]

    def check(self, now: float) -> None:
        """Trigger once when the heartbeat has been lost in AUTO (``now``: wall s, the link's clock)."""
        st, api = self.view.status, self.view.api
        if api is None or st is None or self.last_heartbeat is None or self.action == "none":
            return
        if now - self.last_heartbeat <= self.timeout:
            return
        if self.active or not st.armed or st.mode != Mode.AUTO:
            return
        self.active = True
        self.events += 1
        target = Mode.RTL if self.action == "rtl" and st.home is not None else Mode.HOLD
        api.set_mode(target)
        msg = f"GCS failsafe: no heartbeat {now - self.last_heartbeat:.1f}s: {target.name}"
        self.out.log(f"gcs: {msg}")
        self.out.statustext(msg, M.MAV_SEVERITY_CRITICAL)
        api.record_event(msg)
