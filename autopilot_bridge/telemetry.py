"""Telemetry from the vessel computer: now the ground-station link of :mod:`autopilot_bridge.gcs`.

``Telemetry`` is :class:`autopilot_bridge.gcs.link.GcsLink`: heartbeat, position, attitude and the
rest of the telemetry set to every ground station, STATUSTEXT events (:meth:`statustext`), any
message of the dialect sent with the vessel's ids (:meth:`forward`), and the `hil run` tap's copy
of all of it (``autopilot.telemetry_to``).
"""

from autopilot_bridge.gcs.link import GcsLink as Telemetry

__all__ = ["Telemetry"]
