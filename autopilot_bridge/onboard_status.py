"""What the vessel computer knows of its own sensors and pack, for SYS_STATUS, GPS_RAW_INT and BATTERY_STATUS.

Health is the sensors' real state, per frame (times in s of vessel time):

* gyro and compass are healthy while the navigation filter accepted one of their measurements in the
  last :data:`SENSOR_TIMEOUT`; GPS while it accepted a fix in the last :data:`GPS_TIMEOUT` (a
  dropout, a receiver without a 3-D fix, or fixes the filter's gate refuses make it unhealthy);
* the accelerometer while HIL_SENSOR brings plausible accelerations (the filter does not use them,
  but they arrive; a ground station that does not see the 3-D accelerometer bit reads "not
  calibrated": MAVSDK's telemetry falls back to PX4's calibration parameter without it);
* AHRS while the filter has an estimate; the battery as :mod:`autopilot_bridge.battery_monitor` says.

A sensor is *present* once its data has arrived in this run and *enabled* from then on.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass

from autopilot_bridge.battery_monitor import BatteryMonitor, BatteryState
from autopilot_bridge.hil_link import GpsStatus, SensorFrame
from common.mavlink import MAV_TYPE as M

SENSOR_TIMEOUT = 0.5     # s: five IMU frames' worth of missing gyro/compass/accel data at the slowest 10 Hz
GPS_TIMEOUT = 1.0        # s: ten 10 Hz fixes (ArduPilot's GPS is unhealthy after a few missed fixes)

GYRO, ACCEL, MAG, GPS = (M.MAV_SYS_STATUS_SENSOR_3D_GYRO, M.MAV_SYS_STATUS_SENSOR_3D_ACCEL,
                         M.MAV_SYS_STATUS_SENSOR_3D_MAG, M.MAV_SYS_STATUS_SENSOR_GPS)
AHRS, BATTERY = M.MAV_SYS_STATUS_AHRS, M.MAV_SYS_STATUS_SENSOR_BATTERY
# The filter's update kind (NavigationFilter.stats.updates) that counts for each sensor.
_FUSED = ((GYRO, "gyro"), (MAG, "compass"), (GPS, "gps_pos"))
_TIMEOUTS = {GYRO: SENSOR_TIMEOUT, MAG: SENSOR_TIMEOUT, ACCEL: SENSOR_TIMEOUT, GPS: GPS_TIMEOUT}


@dataclass(frozen=True)
class OnboardStatus:
    """SYS_STATUS's sensor bitmasks, the receiver's last account of itself and the pack."""

    present: int
    enabled: int
    health: int
    gps: GpsStatus | None            # the newest HIL_GPS's fix type, satellites and fix (None: none yet)
    battery: BatteryState | None


class OnboardSensors:
    """Tracks, frame by frame, when each sensor last delivered accepted data."""

    def __init__(self, battery: BatteryMonitor) -> None:
        self.battery = battery
        self.reset()

    def reset(self) -> None:
        self.seen = 0                                # bits of sensors whose data arrived this run
        self.last_ok: dict[int, float] = {}          # bit -> vessel time of the last accepted datum
        self.gps: GpsStatus | None = None
        self._counts: dict[str, int] = {}
        self._stats_id = 0
        self.t = 0.0
        self.has_estimate = False
        self.battery.reset()

    def on_frame(self, f: SensorFrame, fused: Mapping[str, int], has_estimate: bool) -> None:
        """After the filter fused frame ``f``: ``fused`` is its counter of accepted updates by kind
        (a new filter's counter starts again from zero)."""
        t = f.t
        self.t, self.has_estimate = t, has_estimate
        last_ok = self.last_ok
        seen = self.seen
        if f.yaw_rate is not None:
            seen |= GYRO
        if f.heading is not None:
            seen |= MAG
        if f.accel is not None:
            seen |= ACCEL
            last_ok[ACCEL] = t
        if f.gps_status is not None:
            self.gps = f.gps_status
            if f.gps_status.fix_type > 0:
                seen |= GPS
        self.seen = seen
        if id(fused) != self._stats_id:            # a new filter (restart, numeric fault)
            self._stats_id, self._counts = id(fused), {}
        counts = self._counts
        for bit, kind in _FUSED:                   # data the filter accepted: present, and healthy for now
            n = fused.get(kind, 0)
            if n != counts.get(kind, 0):
                counts[kind] = n
                last_ok[bit] = t
                self.seen |= bit
        if f.battery is not None:
            self.seen |= BATTERY
            self.battery.on_reading(t, f.battery)

    def status(self) -> OnboardStatus:
        t = self.t
        health = 0
        for bit, timeout in _TIMEOUTS.items():
            if t - self.last_ok.get(bit, -math.inf) <= timeout + 1e-9:
                health |= bit
        if self.has_estimate:
            health |= AHRS
        present = self.seen | AHRS
        battery = self.battery.state(t)
        if battery is not None and battery.healthy:
            health |= BATTERY
        return OnboardStatus(present, present, health, self.gps, battery)
