"""Telemetry from the vessel computer: heartbeat, estimated position, events.

A separate UDP endpoint (not the HIL link) so that ground stations, loggers and the `hil run`
orchestrator receive the vessel's own view: HEARTBEAT (1 Hz, MAV_TYPE_SURFACE_BOAT),
LOCAL_POSITION_NED of the navigation estimate (10 Hz, ``time_boot_ms`` = simulated ms),
STATUSTEXT for events and MISSION_ITEM_REACHED when the final goal is reached.
"""

from __future__ import annotations

import math
from typing import Any

from common.mavlink import MAV_TYPE, Codec
from common.udp import UdpEndpoint


class Telemetry:
    def __init__(self, destinations: tuple[str, ...], system_id: int, component_id: int,
                 position_rate_hz: float = 10.0) -> None:
        self.ep = UdpEndpoint("127.0.0.1:0", list(destinations))
        self.codec = Codec(system_id, component_id)
        self.position_period = 1.0 / position_rate_hz
        self.next_position_t = 0.0
        self.next_heartbeat_t = 0.0
        self.sent = 0

    def _send(self, name: str, *args: Any) -> None:
        self.ep.send(self.codec.encode(name, *args))
        self.sent += 1

    def on_frame(self, t: float, s: Any, mode: str, cmd: Any) -> None:
        """Per control frame: heartbeat and position when due (simulated time ``t``)."""
        if t + 1e-9 >= self.next_heartbeat_t:
            self.next_heartbeat_t = t + 1.0
            self._send("heartbeat", MAV_TYPE.MAV_TYPE_SURFACE_BOAT, MAV_TYPE.MAV_AUTOPILOT_GENERIC,
                       MAV_TYPE.MAV_MODE_FLAG_SAFETY_ARMED | MAV_TYPE.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED, 0,
                       MAV_TYPE.MAV_STATE_ACTIVE)
        if t + 1e-9 >= self.next_position_t:
            self.next_position_t = t + self.position_period
            vn = s.u * math.cos(s.psi) - s.v * math.sin(s.psi)
            ve = s.u * math.sin(s.psi) + s.v * math.cos(s.psi)
            self._send("local_position_ned", int(round(t * 1000)), s.x, s.y, 0.0, vn, ve, 0.0)
            self._send("attitude", int(round(t * 1000)), 0.0, 0.0, s.psi, 0.0, 0.0, s.r)

    def forward(self, name: str, *fields: Any) -> None:
        """Send message ``name`` (e.g. ``"ais_vessel"``) built from its encode() ``fields``, with the
        vessel's ids, to the telemetry destinations (e.g. AIS traffic for the ground station)."""
        self._send(name, *fields)

    def statustext(self, text: str, severity: int = MAV_TYPE.MAV_SEVERITY_INFO) -> None:
        self._send("statustext", severity, text[:50].encode())

    def mission_item_reached(self, seq: int) -> None:
        self._send("mission_item_reached", seq)

    def service(self) -> None:
        """Called between frames (nothing to do yet; the ground-station link will answer requests here)."""

    def close(self) -> None:
        self.ep.close()
