"""The ground-station link: transports, telemetry, commands, mission and parameter microservices.

See :mod:`autopilot_bridge.gcs.link` (the object the autopilot talks to), :mod:`.transport`,
:mod:`.mission` (pure mission protocol state machine), :mod:`.params`, :mod:`.config`.
"""
