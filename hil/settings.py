"""The root of the configuration: one frozen dataclass per TOML section of configs/default.toml.

``configs/default.toml`` holds every key; a ``--config`` file holds only the keys it changes and
is laid over it (several in order), then the ``--set section.key=value`` overrides
(:func:`hil.config.load`).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path

from autopilot_bridge.ais_tracking import TrackerParams
from autopilot_bridge.battery_monitor import BatteryMonitorParams
from autopilot_bridge.config import AutopilotParams
from autopilot_bridge.control import ControlParams
from autopilot_bridge.gcs.config import GcsParams
from autopilot_bridge.navigation import NavigationParams
from common.can_params import CanParams
from hil import config
from planner.colregs import ColregsParams
from planner.params import PlannerParams
from simulator.battery import BatteryParams
from simulator.config import (
    CurrentParams,
    EscParams,
    GeodesyParams,
    LinkParams,
    SensorParams,
    SimParams,
    VesselParams,
    WaveParams,
)
from simulator.traffic import AisParams


@dataclass(frozen=True)
class HilConfig:
    vessel: VesselParams
    waves: WaveParams
    current: CurrentParams
    sensors: SensorParams
    sim: SimParams
    link: LinkParams
    geodesy: GeodesyParams
    planner: PlannerParams
    autopilot: AutopilotParams
    navigation: NavigationParams
    control: ControlParams
    # Ship traffic (issue 7); defaults let configuration files from before it load unchanged.
    traffic: AisParams = field(default_factory=AisParams)
    tracking: TrackerParams = field(default_factory=TrackerParams)
    colregs: ColregsParams = field(default_factory=ColregsParams)
    # The CAN actuator path (issue 5); optional like the sections above.
    esc: EscParams = field(default_factory=EscParams)
    can: CanParams = field(default_factory=CanParams)
    # The ground-station link (issue 6); defaults as configs/default.toml's [gcs].
    gcs: GcsParams = field(default_factory=GcsParams)
    # The battery pack (simulator) and the vessel computer's monitor of it (issue 36).
    battery: BatteryParams = field(default_factory=BatteryParams)
    battery_monitor: BatteryMonitorParams = field(default_factory=BatteryMonitorParams)

    def __post_init__(self) -> None:
        # Connection strings of the HIL links (common.connection): refused here, naming the key,
        # rather than silently sending nowhere.
        from common import connection as c

        for key, values, role in (("link.state_to", self.link.state_to, c.SEND_UDP),
                                  ("link.commands_on", (self.link.commands_on,), c.RECEIVE_UDP),
                                  ("autopilot.listen", (self.autopilot.listen,), c.RECEIVE_UDP),
                                  ("autopilot.actuators_to", self.autopilot.actuators_to, c.SEND_UDP),
                                  ("autopilot.telemetry_to", self.autopilot.telemetry_to, c.SEND_UDP),
                                  ("autopilot.telemetry_from", (self.autopilot.telemetry_from,), c.RECEIVE_UDP)):
            for v in values:
                try:
                    c.parse(v, role)
                except ValueError as exc:
                    raise ValueError(f"{key}: {exc}") from None


def load(path: str | Path | Sequence[str | Path] | None = None, overrides: list[str] | None = None) -> HilConfig:
    """The defaults, the ``--config`` file(s) laid over them, then ``overrides``; validated."""
    return config.load(HilConfig, path, overrides)
