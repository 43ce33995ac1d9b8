"""The thrusters' back-end: one small interface (as python-can's ``BusABC``), two implementations.

* :class:`MavlinkActuators` - HIL_ACTUATOR_CONTROLS on the simulator's HIL link (the default);
* :class:`autopilot_bridge.can_actuators.CanActuators` - DroneCAN ``esc.RawCommand`` on a CAN bus, with
  the ESCs' ``esc.Status`` read back.

Commands are normalised thrusts in [-1, 1] (port, starboard) answering the sensor frame at ``time_usec``.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Protocol

from autopilot_bridge.hil_link import SensorLink

if TYPE_CHECKING:
    from autopilot_bridge.can_actuators import CanPathSummary


class Actuators(Protocol):
    def send_controls(self, time_usec: int, port: float, stdb: float, armed: bool = True) -> None: ...

    def service(self) -> None:
        """Handle what the back-end received (ESC status); called between frames."""
        ...

    def esc_telemetry(self) -> list[dict[str, float] | None]:
        """Per ESC (port, starboard): its newest status, or None; [] where the back-end has none."""
        ...

    def alarms(self) -> list[str]:
        """What the back-end found wrong since the last call (a node-ID conflict on CAN), as warnings."""
        ...

    def summary(self) -> CanPathSummary | None:
        """The back-end's counters for the run summary (None: nothing beyond the HIL link's)."""
        ...


class MavlinkActuators:
    """HIL_ACTUATOR_CONTROLS on the HIL link (its counters are the link's own)."""

    def __init__(self, link: SensorLink) -> None:
        self.link = link

    def send_controls(self, time_usec: int, port: float, stdb: float, armed: bool = True) -> None:
        self.link.send_controls(time_usec, port, stdb, armed)

    def service(self) -> None:
        return None

    def esc_telemetry(self) -> list[dict[str, float] | None]:
        return []

    def alarms(self) -> list[str]:
        return []

    def summary(self) -> CanPathSummary | None:
        return None
