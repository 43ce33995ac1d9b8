"""Who the vessel says it is on the ground-station link: its system id and the autopilot it identifies as.

``ardupilot`` (the default) says MAV_AUTOPILOT_ARDUPILOTMEGA with MAV_TYPE_SURFACE_BOAT, as ArduPilot
Rover does, so that QGroundControl loads its ArduPilot Rover plugin (mode names, parameter pages) and
MAVSDK and MAVProxy set and decode Rover's ``custom_mode`` numbers; with it comes ArduPilot's mission
convention (item 0 is home). ``generic`` says MAV_AUTOPILOT_GENERIC (clients then treat the modes as PX4's:
docs/gcs.md). AUTOPILOT_VERSION names the firmware and its capabilities.
"""

from __future__ import annotations

import subprocess
from pathlib import Path

from autopilot_bridge.gcs.context import VehicleView
from autopilot_bridge.parameters import Tunable
from common.mavlink import MAV_TYPE as M
from common.mavlink import Codec

FIRMWARE_VERSION = (0, 7, 0)   # major, minor, patch of this vessel computer (AUTOPILOT_VERSION flight_sw_version)
CAPABILITIES = (M.MAV_PROTOCOL_CAPABILITY_MISSION_INT | M.MAV_PROTOCOL_CAPABILITY_COMMAND_INT
                | M.MAV_PROTOCOL_CAPABILITY_MISSION_FENCE | M.MAV_PROTOCOL_CAPABILITY_MISSION_RALLY
                | M.MAV_PROTOCOL_CAPABILITY_PARAM_FLOAT | M.MAV_PROTOCOL_CAPABILITY_MAVLINK2
                | M.MAV_PROTOCOL_CAPABILITY_SET_POSITION_TARGET_GLOBAL_INT)


def _git_hash() -> bytes:
    """The first 8 hex digits of the checkout's commit (AUTOPILOT_VERSION flight_custom_version), else zeros."""
    try:
        out = subprocess.run(["git", "rev-parse", "--short=8", "HEAD"], cwd=Path(__file__).resolve().parent,
                             capture_output=True, text=True, timeout=2.0, check=False)
        h = out.stdout.strip()
        return h.encode()[:8] if out.returncode == 0 and len(h) >= 8 else b"\0" * 8
    except (OSError, subprocess.SubprocessError):
        return b"\0" * 8


class Identity:
    sysid = Tunable("SYSID_THISMAV", 1, 255, "", "MAVLink system id of this vehicle (ArduRover: SYSID_THISMAV)",
                    integer=True, notify="_apply_sysid")

    def __init__(self, kind: str, codec: Codec, view: VehicleView) -> None:
        self.kind = kind
        self.codec, self.view = codec, view
        self.sysid = view.sysid
        self.custom_version = _git_hash()

    def _apply_sysid(self, value: float) -> None:
        self.view.sysid = int(value)
        self.codec.mav.srcSystem = int(value)

    @property
    def autopilot(self) -> int:
        """HEARTBEAT's autopilot field."""
        return M.MAV_AUTOPILOT_ARDUPILOTMEGA if self.kind == "ardupilot" else M.MAV_AUTOPILOT_GENERIC

    @property
    def home_item(self) -> bool:
        """Mission item 0 is home (ArduPilot's convention)."""
        return self.kind == "ardupilot"

    @staticmethod
    def flight_sw_version() -> int:
        major, minor, patch = FIRMWARE_VERSION
        return (major << 24) | (minor << 16) | (patch << 8) | M.FIRMWARE_VERSION_TYPE_OFFICIAL
