"""The root of the configuration: one frozen dataclass per TOML section of configs/default.toml.

A configuration file is complete: every section and key must be present (copy
``configs/default.toml`` and edit it, or use ``--set section.key=value``).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

from autopilot_bridge.ais_tracking import TrackerParams
from autopilot_bridge.config import AutopilotParams
from autopilot_bridge.control import ControlParams
from autopilot_bridge.gcs.config import GcsParams
from autopilot_bridge.navigation import NavigationParams
from common.can_params import CanParams
from hil import config
from planner.colregs import ColregsParams
from planner.params import PlannerParams
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


def load(path: str | Path | None = None, overrides: list[str] | None = None) -> HilConfig:
    """Load and validate a whole configuration (default: configs/default.toml)."""
    return config.load(HilConfig, path, overrides)
