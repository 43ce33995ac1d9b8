"""Mission commands as the vessel stores them: one per mission item, positions in NED metres.

Which MAV_CMD a mission may hold, in three groups (ArduPilot Rover's own lists are the model):

* **executed** (:data:`EXECUTED`): NAV_WAYPOINT, NAV_LOITER_UNLIM, NAV_LOITER_TIME,
  NAV_RETURN_TO_LAUNCH, DO_CHANGE_SPEED, DO_JUMP, DO_SET_HOME
  (:mod:`autopilot_bridge.mission_executor` runs them);
* **stored and skipped** (:data:`STORED_ONLY`): commands ArduRover accepts into a mission (servos,
  relays, cameras, conditions, ...) but this boat has nothing to do them with. They upload, read back
  unchanged and, at execution, are skipped with a STATUSTEXT, as ArduPilot skips a command its vehicle
  does not run;
* anything else is refused at upload (MAV_MISSION_UNSUPPORTED).
"""

from __future__ import annotations

from dataclasses import dataclass

from common.mavlink import MAV_TYPE as M

NAV_WAYPOINT = M.MAV_CMD_NAV_WAYPOINT
NAV_LOITER_UNLIM = M.MAV_CMD_NAV_LOITER_UNLIM
NAV_LOITER_TIME = M.MAV_CMD_NAV_LOITER_TIME
NAV_RETURN_TO_LAUNCH = M.MAV_CMD_NAV_RETURN_TO_LAUNCH
DO_CHANGE_SPEED = M.MAV_CMD_DO_CHANGE_SPEED
DO_JUMP = M.MAV_CMD_DO_JUMP
DO_SET_HOME = M.MAV_CMD_DO_SET_HOME

EXECUTED = frozenset({NAV_WAYPOINT, NAV_LOITER_UNLIM, NAV_LOITER_TIME, NAV_RETURN_TO_LAUNCH, DO_CHANGE_SPEED,
                      DO_JUMP, DO_SET_HOME})
_STORED_NAMES = (
    "NAV_DELAY", "NAV_SET_YAW_SPEED", "NAV_GUIDED_ENABLE", "NAV_SCRIPT_TIME", "CONDITION_DELAY",
    "CONDITION_DISTANCE", "CONDITION_YAW", "DO_SET_SERVO", "DO_SET_RELAY", "DO_REPEAT_SERVO", "DO_REPEAT_RELAY",
    "DO_SET_REVERSE", "DO_DIGICAM_CONTROL", "DO_DIGICAM_CONFIGURE", "DO_SET_CAM_TRIGG_DIST", "DO_MOUNT_CONTROL",
    "DO_SET_ROI", "DO_SET_ROI_LOCATION", "DO_SET_ROI_NONE", "DO_FENCE_ENABLE", "DO_AUX_FUNCTION", "DO_GRIPPER",
    "DO_SPRAYER", "DO_SEND_SCRIPT_MESSAGE", "DO_ENGINE_CONTROL", "DO_GUIDED_LIMITS", "IMAGE_START_CAPTURE",
    "IMAGE_STOP_CAPTURE", "VIDEO_START_CAPTURE", "VIDEO_STOP_CAPTURE", "DO_SET_RESUME_REPEAT_DIST", "DO_WINCH",
    "DO_GIMBAL_MANAGER_PITCHYAW", "JUMP_TAG", "DO_JUMP_TAG",
)
STORED_ONLY = frozenset(getattr(M, f"MAV_CMD_{n}") for n in _STORED_NAMES if hasattr(M, f"MAV_CMD_{n}"))
ACCEPTED = EXECUTED | STORED_ONLY

# NAV commands move the boat (MISSION_CURRENT shows the active one); the others are DO/CONDITION commands,
# started when the NAV command before them starts (ArduPilot's AP_Mission order).
NAV_COMMANDS = frozenset({NAV_WAYPOINT, NAV_LOITER_UNLIM, NAV_LOITER_TIME, NAV_RETURN_TO_LAUNCH} |
                         {c for c in STORED_ONLY if M.enums["MAV_CMD"][c].name.startswith("MAV_CMD_NAV_")})
# Commands whose item must carry a position (latitude/longitude) to be executed.
NEEDS_POSITION = frozenset({NAV_WAYPOINT})


def command_name(command: int) -> str:
    entry = M.enums["MAV_CMD"].get(int(command))
    return entry.name.removeprefix("MAV_CMD_") if entry is not None else f"command {int(command)}"


@dataclass(frozen=True)
class MissionCommand:
    """One mission item, as the vehicle executes it.

    ``north``/``east`` (m, NED) are None where the item gives no position (DO commands, RTL, a loiter
    at 0/0 meaning "here"). ``p1``..``p4`` are the item's param1..param4 as uploaded (MAVLink units:
    NAV_WAYPOINT p1 hold time s, p2 acceptance radius m; NAV_LOITER_TIME p1 time s; DO_CHANGE_SPEED p2
    speed m/s; DO_JUMP p1 target item, p2 repeat count; DO_SET_HOME p1 1 = here)."""

    command: int
    north: float | None = None
    east: float | None = None
    p1: float = 0.0
    p2: float = 0.0
    p3: float = 0.0
    p4: float = 0.0

    @property
    def is_nav(self) -> bool:
        return self.command in NAV_COMMANDS

    @property
    def position(self) -> tuple[float, float] | None:
        return None if self.north is None or self.east is None else (self.north, self.east)

    def required_position(self) -> tuple[float, float]:
        """The position of an item that must have one (ValueError if it has none)."""
        if self.north is None or self.east is None:
            raise ValueError(f"mission item {self.command} has no position")
        return (self.north, self.east)


def waypoint(north: float, east: float, radius: float, hold: float = 0.0) -> MissionCommand:
    """A NAV_WAYPOINT (hold s, acceptance radius m)."""
    return MissionCommand(NAV_WAYPOINT, float(north), float(east), float(hold), float(radius))
