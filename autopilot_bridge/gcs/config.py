"""Typed configuration of the ground-station link (the TOML section [gcs])."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Literal

from common import connection
from common.connection import Connection
from common.params import param
from common.tables import derived


@dataclass(frozen=True)
class GcsParams:
    """The [gcs] section: endpoints, failsafe, mission protocol timing, security."""

    endpoints: tuple[str, ...] = param(
        "ground-station endpoints: udpout:HOST:PORT (send there, answer whoever talks back), udpin:HOST:PORT "
        "(listen, answer every peer heard), tcpin:HOST:PORT (accept TCP connections)",
        default=("udpout:127.0.0.1:14550",))
    identity: Literal["ardupilot", "generic"] = param(
        "how the boat identifies itself: ardupilot (MAV_AUTOPILOT_ARDUPILOTMEGA, as ArduPilot Rover does, so that "
        "QGroundControl, MAVSDK and MAVProxy use Rover's modes and mission conventions: item 0 is home) or generic "
        "(MAV_AUTOPILOT_GENERIC: the mission starts at item 0; docs/gcs.md)", default="ardupilot")
    wait_for_arm: bool = param("start disarmed in HOLD and wait for a GCS to arm and start the mission",
                               default=False)
    pace_speedup: float = param(
        "lockstep with wait_for_arm (a ground station attached): simulated time passes at most this many times "
        "as fast as wall time, so a person can follow the boat (hil run --speedup)", gt=0, default=1.0)
    failsafe_timeout: float = param("in AUTO, no GCS heartbeat for this long (wall time) triggers the failsafe", "s",
                                    gt=0, default=5.0)
    failsafe_action: Literal["hold", "rtl", "none"] = param("what the GCS failsafe does: hold, rtl or none",
                                                            default="hold")
    mission_timeout: float = param("mission upload: re-request an item not received within this time (wall)", "s",
                                   gt=0, default=0.25)
    mission_retries: int = param("mission upload: re-requests of one item before the upload is cancelled", ge=0,
                                 default=5)
    max_mission_items: int = param("largest mission accepted (MAV_MISSION_NO_SPACE above)", ge=1, le=65535,
                                   default=200)
    signing_key_file: str = param("MAVLink 2 signing key file (32 raw bytes, 64 hex digits, or a passphrase "
                                  "hashed with SHA-256 as MAVProxy does); empty = signing off", default="")
    allowed_sysids: tuple[int, ...] = param("system ids allowed to command the boat (empty = any)", ge=1, le=255,
                                            default=())
    max_peers: int = param("ground stations answered at once per endpoint (places earned past the security gate, "
                           "docs/security.md)", ge=1, le=64,
                           default=8)

    # The endpoints parsed once, as the section is read (a bad one is a one-line error then, not when
    # the link opens): what the link's devices open (autopilot_bridge.gcs.devices).
    connections: tuple[Connection, ...] = field(default=(), init=False, repr=False, compare=False,
                                                metadata=derived())

    def __post_init__(self) -> None:
        parsed = []
        for e in self.endpoints:
            try:
                parsed.append(connection.parse(e, connection.GCS))
            except ValueError as exc:
                raise ValueError(f"endpoints: {exc}") from None
        object.__setattr__(self, "connections", tuple(parsed))
