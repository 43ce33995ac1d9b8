"""The battery pack the simulator owns (simulator/battery.py), the BATTERY_STATUS it sends, and the
seeded GPS satellite count: energy balance, voltage against charge and load, the BMS cut-off."""

from __future__ import annotations

import math

import numpy as np
import pytest

from autopilot_bridge.hil_link import HilLink
from common.geodesy import LocalFrame
from hil import settings
from hil.assembly.simulator import simulator_settings
from simulator.battery import OCV_SOC, BatteryParams, Pack, cell_ocv, thruster_power
from simulator.core import Command, SimulatorCore
from simulator.sensors import Satellites

PACK = BatteryParams()


def test_consumed_charge_and_energy_are_the_integrals_of_current_and_power():
    pack = Pack(PACK)
    rng = np.random.default_rng(3)
    dt, charge, energy = 0.01, 0.0, 0.0
    for _ in range(20_000):
        pack.draw(float(rng.uniform(0.0, 1100.0)), dt)
        charge += pack.current * dt
        energy += pack.voltage * pack.current * dt
    assert pack.consumed_mah == pytest.approx(charge / 3.6, rel=1e-12)
    assert pack.energy_j == pytest.approx(energy, rel=1e-12)
    # The state of charge fell by exactly the charge drawn.
    assert pack.soc == pytest.approx(1.0 - charge / (PACK.capacity_ah * 3600.0), rel=1e-12)
    assert 0.0 < pack.soc < 1.0


def test_the_terminal_voltage_delivers_the_power_asked():
    pack = Pack(BatteryParams(initial_soc=0.5))
    for power in (0.0, 50.0, 400.0, 1030.0):
        ocv = pack.ocv    # over the interval: the open-circuit voltage at its start
        pack.draw(power, 1e-6)
        assert pack.voltage * pack.current == pytest.approx(power, rel=1e-9, abs=1e-9)
        assert pack.voltage == pytest.approx(ocv - pack.current * PACK.resistance, rel=1e-12)


def test_voltage_falls_with_the_state_of_charge_and_under_load():
    volts = [cell_ocv(s) for s in OCV_SOC]
    assert all(b > a for a, b in zip(volts, volts[1:], strict=False))
    assert cell_ocv(1.0) == pytest.approx(4.18) and cell_ocv(0.0) == pytest.approx(3.0)

    def terminal(soc: float, power: float) -> float:
        pack = Pack(BatteryParams(initial_soc=soc))
        pack.draw(power, 1e-6)
        return pack.voltage

    for power in (30.0, 200.0, 1030.0):
        assert terminal(0.9, power) > terminal(0.5, power) > terminal(0.1, power)
    for soc in (0.9, 0.5, 0.1):
        assert terminal(soc, 30.0) > terminal(soc, 200.0) > terminal(soc, 1030.0)
    # Both thrusters at full forward power and the hotel load on a full pack: ~44 A, ~1.3 V of sag.
    pack = Pack(PACK)
    pack.draw(2 * 500.0 + PACK.hotel_power, 0.01)
    assert 40.0 < pack.current < 48.0 and 1.0 < 6 * 4.18 - pack.voltage < 1.6


def test_thruster_power_follows_momentum_theory_exponent():
    cfg = settings.load(None, [])
    esc, v = cfg.esc, cfg.vessel
    assert thruster_power(v.T_max, esc, v) == pytest.approx(esc.max_power)
    assert thruster_power(v.T_min, esc, v) == pytest.approx(esc.max_power)
    assert thruster_power(v.T_max / 4, esc, v) == pytest.approx(esc.max_power / 8)
    assert thruster_power(0.0, esc, v) == 0.0


def test_an_empty_pack_cuts_the_thrusters_off():
    pack = Pack(BatteryParams(initial_soc=1e-5))
    for _ in range(100):
        pack.draw(1000.0, 0.01)
    assert pack.depleted and pack.soc == 0.0
    cfg = settings.load(None, ["battery.initial_soc=0.0"])
    core = SimulatorCore(simulator_settings(cfg))
    core.apply(Command(core.time_usec, 1.0, 1.0))
    assert core.thrusts() == (0.0, 0.0)
    full = SimulatorCore(simulator_settings(settings.load(None, [])))
    full.apply(Command(full.time_usec, 1.0, 1.0))
    assert full.thrusts()[0] > 100.0


def test_battery_status_reaches_the_vessel_computer_as_the_pack_is():
    """The simulator's BATTERY_STATUS (2 Hz) decoded by the vessel computer's link equals the pack."""
    cfg = settings.load(None, [])
    core = SimulatorCore(simulator_settings(cfg))
    link = HilLink.open("127.0.0.1:0", (), LocalFrame(cfg.geodesy.lat0, cfg.geodesy.lon0, 0.0))
    readings = []
    try:
        for _ in range(500):
            core.apply(Command(core.time_usec, 0.8, 0.6))
            f = link.decode(core.frame())
            assert f is not None
            if f.battery is not None:
                readings.append((f.battery, core.battery.voltage, core.battery.current, core.battery.consumed_mah,
                                 core.battery.soc))
            core.step()
    finally:
        link.close()
    assert len(readings) == 10                      # 5 s at 2 Hz
    assert core.messages_sent["BATTERY_STATUS"] == 10
    for r, volts, amps, mah, soc in readings:
        assert len(r.cells) == 6 and r.voltage == pytest.approx(volts, abs=6e-3)    # mV per cell
        assert r.current == pytest.approx(amps, abs=0.006)                          # cA
        assert r.consumed_mah == round(mah) and r.remaining == math.floor(soc * 100)
    consumed = [r.consumed_mah for r, *_ in readings]
    assert consumed == sorted(consumed) and consumed[-1] > 0
    assert readings[-1][0].current > 10.0         # both thrusters pushing
    assert link.rejects == {}


def test_satellite_count_is_seeded_bounded_and_changes():
    def run(seed: int) -> list[int]:
        s = Satellites(12, 90.0, np.random.default_rng(seed), 0.01)
        out = []
        for _ in range(360_000):       # an hour at 100 Hz
            s.advance()
            out.append(s.count)
        return out

    a, b, c = run(1), run(1), run(2)
    assert a == b and a != c
    assert min(a) >= 8 and max(a) <= 16
    changes = sum(1 for x, y in zip(a, a[1:], strict=False) if x != y)
    assert 20 <= changes <= 60                    # ~40 rise/set events in an hour at one per 90 s
    assert abs(np.mean(a) - 12) < 2.0


def test_hil_gps_carries_the_satellite_count_and_none_in_a_dropout():
    cfg = settings.load(None, ["sensors.gps.dropouts=[[1.0, 1.0]]", "sensors.gps.satellite_interval=1.0"])
    core = SimulatorCore(simulator_settings(cfg))
    link = HilLink.open("127.0.0.1:0", (), LocalFrame(cfg.geodesy.lat0, cfg.geodesy.lon0, 0.0))
    seen = []
    try:
        for _ in range(400):
            f = link.decode(core.frame())
            if f is not None and f.gps_status is not None:
                seen.append((f.t, f.gps_status))
            core.step()
    finally:
        link.close()
    in_dropout = [g for t, g in seen if 1.0 <= t < 2.0]
    outside = [g for t, g in seen if not 1.0 <= t < 2.0]
    assert in_dropout and all(g.fix_type == 0 and g.satellites == 0 for g in in_dropout)
    assert all(g.fix_type == 3 and 8 <= g.satellites <= 16 for g in outside)
    assert len({g.satellites for g in outside}) > 1   # one event a second: the count moves


def test_the_link_drops_an_implausible_pack_or_accelerometer_and_keeps_the_frame():
    from common.mavlink import MAV_TYPE as M
    from common.mavlink import Codec

    cfg = settings.load(None, [])
    sim = Codec(cfg.link.system_id, cfg.link.component_id)
    link = HilLink.open("127.0.0.1:0", (), LocalFrame(cfg.geodesy.lat0, cfg.geodesy.lon0, 0.0),
                   sim_ids=(cfg.link.system_id, cfg.link.component_id))

    def frame(k: int, acc: float, cells: list[int], current: int) -> bytes:
        return (sim.encode("hil_sensor", k * 10_000, acc, 0.0, -9.8, 0.0, 0.0, 0.01, 0.2, 0.0, 0.0, 0, 0, 0, 0, 0x1FF)
                + sim.encode("battery_status", 0, M.MAV_BATTERY_FUNCTION_ALL, M.MAV_BATTERY_TYPE_LION, 32767,
                             cells + [65535] * (10 - len(cells)), current, 10, 100, 90))

    try:
        good = link.decode(frame(0, 0.1, [4000] * 6, 850))
        assert good is not None and good.accel == pytest.approx((0.1, 0.0, -9.8))
        assert good.battery is not None and good.battery.voltage == pytest.approx(24.0)
        assert good.battery.current == pytest.approx(8.5) and good.battery.remaining == 90
        for k, (acc, cells, amps) in enumerate([(float("nan"), [65535] * 6, 100), (1e4, [11_000] * 10, 100),
                                                (0.0, [4000] * 6, 32_500)], start=1):
            f = link.decode(frame(k, acc, cells, amps))
            assert f is not None and f.battery is None and f.heading is not None   # the rest of the frame kept
        assert link.rejects["implausible_battery"] == 3 and link.rejects["implausible_accel"] == 2
    finally:
        link.close()
