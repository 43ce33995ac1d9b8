"""The vessel computer's battery monitor and its low-battery failsafe, with ArduPilot's parameter names.

The pack's truth lives in the simulator (simulator/battery.py); this end learns it as a real vessel
computer learns a smart battery: from its BMS's BATTERY_STATUS (decoded by
:mod:`autopilot_bridge.hil_link`). It keeps the newest reading for the ground station (SYS_STATUS,
BATTERY_STATUS) and runs ArduPilot's low-battery failsafe (AP_BattMonitor; parameter meanings as
https://ardupilot.org/rover/docs/parameters.html lists them under BATT_):

* BATT_LOW_VOLT: the pack's voltage below this for BATT_LOW_TIMER seconds running (a sag under
  load shorter than that does not count), 0 = off;
* BATT_LOW_MAH: remaining capacity, BATT_CAPACITY minus the consumed mAh, below this, 0 = off;
* BATT_FS_LOW_ACT: what the boat does then (Rover's values 0 None, 1 RTL, 2 Hold, here holding
  station in LOITER as the GCS failsafe's hold; the others, SmartRTL and Terminate, the boat does not have).

Once triggered the failsafe stays triggered (as ArduPilot's, until a reboot: the pack does not
recover). It sends one STATUSTEXT (critical), records an event, and calls ``on_low(action)``: the
vessel decides what the action means for its modes.

Defaults (configs/default.toml [battery_monitor]) where they differ from ArduRover's, and why: a boat
in a current that runs its pack flat drifts where the current takes it, so the voltage failsafe is on
(19.8 V, 3.3 V a Li-ion cell under load: 6.7 % left on the OCV curve of simulator/battery.py at the
~10 A of cruising at 1.5 m/s) and its action is RTL; BATT_CAPACITY is the pack's label rather than 3300 mAh.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

from autopilot_bridge.hil_link import BatteryReading
from autopilot_bridge.parameters import Tunable
from common.mavlink import MAV_TYPE as M
from common.params import param

STALE_AFTER = 2.0        # s of vessel time without a reading: the monitor is unhealthy
FS_NONE, FS_RTL, FS_HOLD = 0, 1, 2
FS_ACTIONS = {FS_NONE: "none", FS_RTL: "RTL", FS_HOLD: "Hold"}


@dataclass(frozen=True)
class BatteryMonitorParams:
    """The [battery_monitor] section: ArduPilot's BATT_* parameters' start values."""

    capacity_mah: float = param("BATT_CAPACITY: the pack's capacity", "mAh", gt=0, le=1e6, default=29400.0)
    low_volt: float = param("BATT_LOW_VOLT: low-battery voltage; 0 = off", "V", ge=0, le=100, default=19.8)
    low_mah: float = param("BATT_LOW_MAH: low-battery remaining capacity; 0 = off", "mAh", ge=0, le=1e6, default=0.0)
    low_timer: float = param("BATT_LOW_TIMER: seconds below BATT_LOW_VOLT before the failsafe", "s", ge=0, le=120,
                             default=10.0)
    fs_low_act: int = param("BATT_FS_LOW_ACT: 0 none, 1 RTL, 2 Hold", ge=0, le=2, default=1)


@dataclass(frozen=True)
class BatteryState:
    """What the ground station is told of the pack (SI units; None: unknown)."""

    voltage: float                  # V
    cells: tuple[int, ...]          # mV per cell as the BMS reported them
    current: float | None           # A
    consumed_mah: float | None      # mAh
    energy_j: float | None          # J
    remaining: int | None           # %
    time_remaining: int             # s, 0 unknown
    charge_state: int               # MAV_BATTERY_CHARGE_STATE
    healthy: bool                   # readings arrive and the failsafe has not triggered
    failsafe: bool


class BatteryMonitor:
    """Newest reading, failsafe state and the BATT_* parameters of one pack."""

    capacity_mah = Tunable("BATT_CAPACITY", 1.0, 1e6, "mAh",
                           "capacity of the pack (remaining = BATT_CAPACITY - consumed)")
    low_volt = Tunable("BATT_LOW_VOLT", 0.0, 100.0, "V", "low-battery failsafe voltage (for BATT_LOW_TIMER); 0 = off")
    low_mah = Tunable("BATT_LOW_MAH", 0.0, 1e6, "mAh", "low-battery failsafe remaining capacity; 0 = off")
    low_timer = Tunable("BATT_LOW_TIMER", 0.0, 120.0, "s", "time below BATT_LOW_VOLT before the failsafe")
    fs_low_act = Tunable("BATT_FS_LOW_ACT", 0.0, 2.0, "", "low-battery failsafe action: 0 none, 1 RTL, 2 Hold",
                         integer=True)

    def __init__(self, p: BatteryMonitorParams, on_low: Callable[[int], None],
                 event: Callable[[float, str, bool], None]) -> None:
        self.capacity_mah, self.low_volt, self.low_mah = p.capacity_mah, p.low_volt, p.low_mah
        self.low_timer, self.fs_low_act = p.low_timer, p.fs_low_act
        self.on_low, self.event = on_low, event
        self.reading: BatteryReading | None = None
        self.read_t = -math.inf
        self.low_since: float | None = None       # vessel time the voltage first fell below BATT_LOW_VOLT
        self.failsafe = False
        self.failsafe_t: float | None = None
        self.readings = 0

    def reset(self) -> None:
        """A restarted simulator: a new run, a new pack."""
        self.reading, self.read_t, self.low_since = None, -math.inf, None
        self.failsafe, self.failsafe_t = False, None

    def remaining_mah(self) -> float | None:
        """BATT_CAPACITY minus the consumed mAh (ArduPilot's definition), or None before a reading."""
        r = self.reading
        if r is None or r.consumed_mah is None:
            return None
        return self.capacity_mah - r.consumed_mah

    def on_reading(self, t: float, r: BatteryReading) -> None:
        self.reading, self.read_t = r, t
        self.readings += 1
        if self.failsafe:
            return
        why = None
        if self.low_volt > 0 and r.voltage < self.low_volt:
            if self.low_since is None:
                self.low_since = t
            if t - self.low_since >= self.low_timer - 1e-9:
                why = f"{r.voltage:.2f}V"
        else:
            self.low_since = None
        left = self.remaining_mah()
        if why is None and self.low_mah > 0 and left is not None and left < self.low_mah:
            why = f"{left:.0f} mAh left"
        if why is not None:
            self._trigger(t, why)

    def _trigger(self, t: float, why: str) -> None:
        self.failsafe, self.failsafe_t = True, t
        act = int(self.fs_low_act)
        used = self.reading.consumed_mah if self.reading is not None else None
        used_text = "" if used is None else f" used {used:.0f} mAh"
        self.event(t, f"Battery 1 is low {why}{used_text}: failsafe {FS_ACTIONS.get(act, str(act))}", True)
        self.on_low(act)

    def state(self, t: float) -> BatteryState | None:
        """The pack as of vessel time ``t`` (None before any reading)."""
        r = self.reading
        if r is None:
            return None
        remaining = r.remaining
        if remaining is None and r.consumed_mah is not None:
            remaining = max(0, min(100, int(100.0 * (1.0 - r.consumed_mah / self.capacity_mah))))
        charge = r.charge_state
        if self.failsafe and charge in (M.MAV_BATTERY_CHARGE_STATE_UNDEFINED, M.MAV_BATTERY_CHARGE_STATE_OK):
            charge = M.MAV_BATTERY_CHARGE_STATE_LOW
        fresh = t - self.read_t <= STALE_AFTER
        return BatteryState(r.voltage, r.cells, r.current, r.consumed_mah, r.energy_j, remaining, r.time_remaining,
                            charge, fresh and not self.failsafe, self.failsafe)
