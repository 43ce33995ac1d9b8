"""The vessel computer's command API and the status it publishes each frame.

A ground-station link (or any other client) depends on :class:`VehicleApi`, a Protocol, never on the
:class:`autopilot_bridge.autopilot.Autopilot` class: it commands through these few methods and reads the
frozen :class:`VehicleStatus` snapshot published with every control frame.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import TYPE_CHECKING, Protocol

from autopilot_bridge.behaviour import Behaviour
from autopilot_bridge.mission_commands import MissionCommand
from autopilot_bridge.modes import Mode
from autopilot_bridge.navigation import NavState
from autopilot_bridge.onboard_status import OnboardStatus
from autopilot_bridge.parameters import Param

if TYPE_CHECKING:
    from autopilot_bridge.gcs.mission import MissionItem
    from planner.fence import Fence


@dataclass(frozen=True)
class Result:
    """A command's outcome: ``ok``; ``text`` says why (or what was done); ``temporary``: try again later."""

    ok: bool
    text: str = ""
    temporary: bool = False


@dataclass(frozen=True)
class VehicleStatus:
    """One control frame's state (positions NED m, times s of vehicle time, speeds m/s)."""

    t: float
    armed: bool
    mode: Mode
    mode_flags: int                        # HEARTBEAT base_mode flags the mode adds
    behaviour: Behaviour
    nav: NavState | None                   # the navigation estimate (None before the first fix)
    home: tuple[float, float] | None
    mission_count: int
    mission_current: int                   # the active NAV item
    mission_complete: bool
    speed_setpoint: float                  # what the controllers aim at along the path
    thrust: tuple[float, float] | None     # port, starboard command (-1..1) of this frame
    local_paths: int = 0                   # local paths accepted so far
    local_path: tuple[tuple[float, float], ...] = ()   # the newest one, NED
    reached: tuple[int, ...] = ()          # mission items reached since the last snapshot
    changed: bool = False                  # mode, arming or current item changed since the last snapshot

    @property
    def position(self) -> tuple[float, float] | None:
        return None if self.nav is None else (self.nav.x, self.nav.y)


class VehicleApi(Protocol):
    """What a ground station may do to the vessel."""

    def arm(self, on: bool, force: bool = False) -> Result: ...   # force: param2 21196 (disarm anywhere)

    def set_mode(self, mode: Mode) -> Result: ...

    def set_param(self, name: str, value: float) -> Result: ...

    def goto(self, north: float, east: float) -> Result: ...   # GUIDED to a point, NED m

    def set_speed(self, speed: float | None) -> Result: ...   # m/s over ground until the mode changes; None: default

    def set_home(self, north: float | None, east: float | None) -> Result: ...  # NED m; None: where the boat is

    def start_mission(self, first: int) -> Result: ...

    def set_mission_current(self, seq: int) -> Result: ...

    def replace_mission(self, commands: tuple[MissionCommand, ...]) -> None: ...

    def mission(self) -> tuple[MissionCommand, ...]: ...

    def check_mission(self, items: tuple[MissionItem, ...],
                      to_ned: Callable[[float, float], tuple[float, float]]) -> tuple[int, int, str] | None:
        """The first upload item (``gcs.mission.MissionItem``) off the chart, in an obstacle or
        unreachable by water, as ``(seq, MAV_MISSION_RESULT, reason)``; None when the route is good.
        ``to_ned(lat, lon)`` -> (north, east) m."""
        ...

    def replace_fence(self, fence: Fence) -> None: ...          # map frame m; empty: no fence

    def fence(self) -> Fence: ...

    def replace_rally(self, points: tuple[tuple[float, float], ...]) -> None: ...   # NED m

    def check_rally(self, points: tuple[tuple[float, float], ...]) -> tuple[int, str] | None: ...

    def manual_input(self, x: float, r: float, wall_time: float) -> None: ...  # each -1..1

    def record_event(self, text: str) -> None: ...

    def parameters(self) -> list[Param]: ...

    def esc_telemetry(self) -> list[dict[str, float] | None]: ...

    def onboard_status(self) -> OnboardStatus: ...   # sensor health, GPS receiver, battery

    def status(self) -> VehicleStatus | None: ...
