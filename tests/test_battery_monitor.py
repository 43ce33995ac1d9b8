"""The vessel computer's battery monitor (BATT_* parameters, low-battery failsafe) and the sensor health
it reports with the others (autopilot_bridge/battery_monitor.py, autopilot_bridge/onboard_status.py)."""

from __future__ import annotations

from autopilot_bridge.battery_monitor import FS_HOLD, FS_RTL, BatteryMonitor, BatteryMonitorParams
from autopilot_bridge.hil_link import BatteryReading, GpsStatus, SensorFrame
from autopilot_bridge.onboard_status import ACCEL, AHRS, BATTERY, GPS, GYRO, MAG, OnboardSensors
from autopilot_bridge.parameters import ParamTable, bind
from common.mavlink import MAV_TYPE as M


def _reading(volts: float, consumed: float = 100.0, amps: float = 9.0) -> BatteryReading:
    return BatteryReading(volts, (int(volts / 6 * 1000),) * 6, amps, consumed, consumed * 3.6 * volts, 50, 0,
                          M.MAV_BATTERY_CHARGE_STATE_OK)


class Recorder:
    def __init__(self) -> None:
        self.actions: list[int] = []
        self.events: list[tuple[float, str, bool]] = []

    def monitor(self, **kw: float) -> BatteryMonitor:
        return BatteryMonitor(BatteryMonitorParams(**kw), self.actions.append,
                              lambda t, text, warn: self.events.append((t, text, warn)))


def test_voltage_failsafe_needs_the_timer_running_and_fires_once():
    rec = Recorder()
    mon = rec.monitor(low_volt=19.8, low_timer=10.0, fs_low_act=FS_RTL)
    t = 0.0
    # A 5 s sag under load, then back above: no failsafe.
    for _ in range(50):
        mon.on_reading(t, _reading(19.6))
        t += 0.1
    mon.on_reading(t, _reading(20.5))
    assert not mon.failsafe and rec.actions == []
    # 10 s below: the failsafe, once, with the action, a warning and the charge state LOW.
    start = t + 0.1
    while t < start + 15.0:
        t += 0.1
        mon.on_reading(t, _reading(19.5))
    assert mon.failsafe and rec.actions == [FS_RTL] and len(rec.events) == 1
    assert 10.0 - 1e-6 <= mon.failsafe_t - start <= 10.2
    t_ev, text, warning = rec.events[0]
    assert warning and text.startswith("Battery 1 is low 19.50V used 100 mAh") and "RTL" in text
    state = mon.state(t)
    assert state is not None and state.failsafe and not state.healthy
    assert state.charge_state == M.MAV_BATTERY_CHARGE_STATE_LOW
    # It latches, as ArduPilot's does: a recovered voltage does not clear it.
    mon.on_reading(t + 1, _reading(24.0))
    assert mon.failsafe and rec.actions == [FS_RTL]


def test_capacity_failsafe_on_remaining_mah_and_off_when_zero():
    rec = Recorder()
    mon = rec.monitor(low_volt=0.0, capacity_mah=1000.0, low_mah=200.0, fs_low_act=FS_HOLD)
    mon.on_reading(0.0, _reading(22.0, consumed=790.0))
    assert not mon.failsafe and mon.remaining_mah() == 210.0
    mon.on_reading(0.1, _reading(22.0, consumed=801.0))
    assert mon.failsafe and rec.actions == [FS_HOLD] and "199 mAh left" in rec.events[0][1]
    rec2 = Recorder()
    off = rec2.monitor(low_volt=0.0, low_mah=0.0)
    off.on_reading(0.0, _reading(1.0, consumed=1e6))
    assert not off.failsafe


def test_batt_parameters_change_the_monitor_live_and_refuse_what_it_cannot_do():
    rec = Recorder()
    mon = rec.monitor()
    table = ParamTable(bind(mon))
    assert {p.name for p in table.params} == {"BATT_CAPACITY", "BATT_LOW_VOLT", "BATT_LOW_MAH", "BATT_LOW_TIMER",
                                              "BATT_FS_LOW_ACT"}
    assert table.set("BATT_LOW_VOLT", 21.0)[0] and mon.low_volt == 21.0
    assert table.set("BATT_LOW_TIMER", 0.0)[0]
    mon.on_reading(0.0, _reading(20.9))
    assert mon.failsafe            # 21 V now, no timer
    assert table.set("BATT_FS_LOW_ACT", 2)[0] and mon.fs_low_act == 2
    assert not table.set("BATT_FS_LOW_ACT", 1.5)[0] and mon.fs_low_act == 2    # not an action
    assert not table.set("BATT_FS_LOW_ACT", 5)[0]                                # Terminate: not on this boat
    assert not table.set("BATT_CAPACITY", float("nan"))[0]
    assert table.set("BATT_CAPACITY", 5000)[0] and table.get("BATT_CAPACITY").get() == 5000.0


def _frame(t: float, *, gyro: bool = True, compass: bool = True, accel: bool = True,
           gps: GpsStatus | None = None, battery: BatteryReading | None = None) -> SensorFrame:
    return SensorFrame(int(round(t * 1e6)), 0.01 if gyro else None, 0.5 if compass else None, None, False, None,
                       None, (0.0, 0.0, -9.8) if accel else None, gps, battery)


FIX = GpsStatus(3, 11, 389200000, 1216500000, 0, 50, 100, 150, 9000)
NO_FIX = GpsStatus(0, 0, 0, 0, 0, 65535, 65535, 0, 65535)


def test_health_follows_what_the_filter_accepts_and_what_arrives():
    rec = Recorder()
    onboard = OnboardSensors(rec.monitor())
    fused = {"gyro": 0, "compass": 0, "gps_pos": 0}
    t = 0.0
    # Nothing arrived yet: nothing present but the AHRS, nothing healthy.
    s = onboard.status()
    assert s.present == AHRS and s.health == 0 and s.gps is None and s.battery is None
    for k in range(100):                    # 1 s: everything arrives and is fused
        t = k * 0.01
        fused["gyro"] += 1
        fused["compass"] += 1
        gps = FIX if k % 10 == 0 else None
        if gps:
            fused["gps_pos"] += 1
        onboard.on_frame(_frame(t, gps=gps, battery=_reading(24.0) if k % 10 == 0 else None), fused, True)
    s = onboard.status()
    every = GYRO | ACCEL | MAG | GPS | AHRS | BATTERY
    assert s.present & every == every and s.enabled == s.present
    assert s.health & every == every
    assert s.gps == FIX and s.battery is not None and s.battery.voltage == 24.0
    # A GPS dropout (fix 0, no satellites), a compass the filter's gate refuses and no pack reading, 2.5 s.
    for k in range(100, 350):
        t = k * 0.01
        fused["gyro"] += 1
        onboard.on_frame(_frame(t, gps=NO_FIX if k % 10 == 0 else None), fused, True)
    s = onboard.status()
    assert not s.health & GPS and not s.health & MAG and not s.health & BATTERY   # stale pack reading too
    assert s.health & GYRO and s.health & ACCEL and s.present & GPS
    assert s.gps is not None and (s.gps.fix_type, s.gps.satellites) == (0, 0)
    # The accelerometer's data stop arriving (implausible values are dropped by the link): unhealthy.
    for k in range(350, 420):
        fused["gyro"] += 1
        onboard.on_frame(_frame(k * 0.01, accel=False), fused, True)
    assert not onboard.status().health & ACCEL and onboard.status().present & ACCEL


def test_a_new_filter_counts_from_zero_without_faking_health():
    onboard = OnboardSensors(Recorder().monitor())
    old = {"gyro": 500, "compass": 500, "gps_pos": 50}
    onboard.on_frame(_frame(0.0), old, True)
    new: dict[str, int] = {}                # a restarted filter that has fused nothing yet
    for k in range(1, 121):
        onboard.on_frame(_frame(k * 0.01), new, False)
    s = onboard.status()
    assert not s.health & (GYRO | MAG | GPS | AHRS)
