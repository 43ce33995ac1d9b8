"""The parameter microservice's table: what every component declares (``parameters()``), in one index.

The declarations live with their owners: the autopilot (planning schedule, speed, controller gains,
planner overrides, waypoint radius; :meth:`autopilot_bridge.autopilot.Autopilot.parameters`) and the
ground-station link (failsafe; :meth:`autopilot_bridge.gcs.failsafe.GcsFailsafe.parameters`). This module only
collects them; PARAM_SET outside a parameter's range changes nothing (:class:`ParamTable`).
"""

from __future__ import annotations

from autopilot_bridge.parameters import Param, ParamTable

__all__ = ["Param", "ParamTable", "collect"]


def collect(*declarations: list[Param]) -> ParamTable:
    """One table of every component's declarations, in the order given (names must be unique)."""
    params = [p for group in declarations for p in group]
    names = [p.name for p in params]
    dup = sorted({n for n in names if names.count(n) > 1})
    if dup:
        raise ValueError(f"parameters declared twice: {', '.join(dup)}")
    return ParamTable(params)
