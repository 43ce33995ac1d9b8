"""The ground-station link, one module per MAVLink microservice.

:mod:`.link` (:class:`~.link.GcsLink`, the object the autopilot talks to: a thin composition),
:mod:`.transport`, :mod:`.framing`, :mod:`.signing`, :mod:`.limits`, :mod:`.telemetry`, :mod:`.command`,
:mod:`.mission_service` over :mod:`.mission` (pure mission protocol state machine), :mod:`.parameter`
over :mod:`.params`, :mod:`.failsafe`; shared pieces in :mod:`.context`; configuration in :mod:`.config`.
"""
