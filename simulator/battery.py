"""The boat's battery pack: the truth of its charge, voltage and current, owned by the simulator.

The pack is reported to the vessel computer as a smart battery's BMS would report it: one
BATTERY_STATUS in the HIL datagram at ``battery.rate_hz`` (docs/simulator.md, "The battery").

**Model** (an equivalent circuit of one resistance, the usual first model of a Li-ion pack, e.g.
G. Plett, *Battery Management Systems*, vol. 1, ch. 2): terminal voltage
``V = OCV(SoC) - I R`` with the cell's open-circuit-voltage curve scaled by the cells in series and
the pack's resistance ``R``; the pack delivers electrical power ``P`` (both thrusters plus the
hotel load), so the current solves ``R I^2 - OCV I + P = 0`` (the smaller root). The state of charge
falls by ``I dt / capacity``; consumed charge (mAh) and energy (J) integrate ``I`` and ``V I``.
At 0 % the BMS cuts the thrusters off (:attr:`Pack.depleted`); the electronics keep their supply.

**Figures** (configs/default.toml [battery]): 6S6P of 21700 Li-ion cells of the Samsung
INR21700-50E class (specification V1.0: 4.9 Ah rated, 3.63 V nominal, 4.2 V charge, 2.5 V cut-off,
9.8 A continuous): 29.4 Ah, 21.8 V nominal, 640 Wh, 58.8 A continuous (both thrusters at full
forward power draw ~48 A). Cell resistance 30 mOhm: the order of the 1 kHz impedance limits of
such datasheets (<= 25-30 mOhm); DC resistance is somewhat higher, pack wiring adds a little.
The OCV curve is a typical NMC curve (3.0 V at empty to 4.18 V full), a modelling choice, not a fit
of that cell. Pack resistance = cell resistance x series / parallel.

**Thruster power** (:func:`thruster_power`): the ESC model of [esc] (simulator/esc.py, which
reports it over CAN): power ~ rpm^3 with thrust ~ rpm^2, i.e. ``P = P_max (|T| / T_full)^1.5``,
momentum theory's exponent (ideal power ``T^1.5 / sqrt(2 rho A)``). At 119.68 N through a 0.15 m
disc the ideal power is 217 W; [esc] max_power = 500 W means 43 % from battery to water (motor
and ESC ~0.8, propeller figure of merit ~0.55), plausible for a small thruster.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import TYPE_CHECKING

from common.mavlink import MAV_TYPE as M
from common.params import param

if TYPE_CHECKING:
    from simulator.config import EscParams, VesselParams

# A typical NMC Li-ion cell's open-circuit voltage (V) at state of charge 0, 0.05, 0.1, ..., 1.0.
OCV_STEPS = 20
OCV_SOC = tuple(i / OCV_STEPS for i in range(OCV_STEPS + 1))
OCV_VOLTS = (3.00, 3.30, 3.45, 3.52, 3.57, 3.61, 3.64, 3.66, 3.68, 3.70, 3.72, 3.75, 3.78, 3.82, 3.86,
             3.90, 3.95, 4.00, 4.05, 4.11, 4.18)


@dataclass(frozen=True)
class BatteryParams:
    """The pack (defaults as configs/default.toml [battery])."""

    cells_series: int = param("cells in series", ge=1, le=14, default=6)
    cells_parallel: int = param("cells in parallel", ge=1, le=100, default=6)
    cell_capacity: float = param("rated capacity of one cell", "Ah", gt=0, le=1000, default=4.9)
    cell_resistance: float = param("internal (ohmic) resistance of one cell", "ohm", ge=0, le=1, default=0.030)
    initial_soc: float = param("state of charge at the start of a run", "", ge=0, le=1, default=1.0)
    hotel_power: float = param("electronics' constant draw (computer, GNSS, radio, lidar)", "W", ge=0, le=5000,
                               default=30.0)
    rate_hz: float = param("BATTERY_STATUS rate in the HIL datagram", "Hz", gt=0, le=100, default=2.0)

    @property
    def capacity_ah(self) -> float:
        return self.cell_capacity * self.cells_parallel

    @property
    def resistance(self) -> float:
        """Pack resistance (ohm)."""
        return self.cell_resistance * self.cells_series / self.cells_parallel


def cell_ocv(soc: float) -> float:
    """Open-circuit voltage (V) of one cell at state of charge ``soc`` (0..1, clamped), piecewise linear."""
    x = min(max(soc, 0.0), 1.0) * OCV_STEPS    # the grid is uniform: its interval directly
    i = min(int(x), OCV_STEPS - 1)
    v0 = OCV_VOLTS[i]
    return v0 + (OCV_VOLTS[i + 1] - v0) * (x - i)


class ThrusterPower:
    """Electrical power (W) one thruster draws at a thrust (N): [esc] max_power at full thrust either
    way, power ~ rpm^3, thrust ~ rpm^2."""

    def __init__(self, esc: EscParams, vessel: VesselParams) -> None:
        self.p_max, self.t_max, self.t_min = float(esc.max_power), float(vessel.T_max), float(vessel.T_min)

    def __call__(self, thrust: float) -> float:
        full = self.t_max if thrust >= 0 else self.t_min
        if not full:
            return 0.0
        ratio = thrust / full
        return self.p_max * (ratio * math.sqrt(ratio) if ratio < 1.0 else 1.0)


def thruster_power(thrust: float, esc: EscParams, vessel: VesselParams) -> float:
    """:class:`ThrusterPower` once."""
    return ThrusterPower(esc, vessel)(thrust)


class Pack:
    """The state of one pack; :meth:`draw` advances it, the properties read it."""

    def __init__(self, p: BatteryParams) -> None:
        self.p = p
        self.capacity_c = p.capacity_ah * 3600.0      # C
        self.resistance = p.resistance                # ohm, the pack's
        self.series = p.cells_series
        self.soc = p.initial_soc
        self.current = 0.0                            # A, discharge positive
        self.voltage = self.ocv                       # V at the terminals
        self.consumed_c = 0.0                         # C since the start of the run
        self.energy_j = 0.0                           # J delivered since the start
        self.depleted = self.soc <= 0.0
        n = p.cells_series
        self._unused = [65535] * max(0, 10 - n)       # BATTERY_STATUS voltages beyond the pack

    @property
    def ocv(self) -> float:
        """Open-circuit voltage of the pack now (V)."""
        return cell_ocv(self.soc) * self.series

    @property
    def consumed_mah(self) -> float:
        return self.consumed_c / 3.6

    def current_for(self, power: float) -> float:
        """Current (A) that delivers ``power`` W at the terminals now (at most the pack's maximum-power current)."""
        return self._current(power, self.ocv)

    def _current(self, power: float, e: float) -> float:
        r = self.resistance
        if power <= 0.0:
            return 0.0
        if r <= 0.0:
            return power / e
        disc = e * e - 4.0 * r * power
        if disc <= 0.0:     # beyond the pack's maximum power E^2 / 4R: it delivers that
            return e / (2.0 * r)
        return (e - math.sqrt(disc)) / (2.0 * r)

    def draw(self, power: float, dt: float) -> None:
        """Deliver ``power`` W (>= 0) for ``dt`` s: current and voltage held over the interval."""
        e = self.ocv
        i = self._current(power, e)
        v = e - i * self.resistance
        self.current, self.voltage = i, v
        charge = i * dt
        self.consumed_c += charge
        self.energy_j += v * i * dt
        self.soc = max(0.0, self.soc - charge / self.capacity_c)
        if self.soc <= 0.0:
            self.depleted = True

    def battery_status(self) -> dict[str, int | list[int]]:
        """Keyword arguments of pymavlink's battery_status_encode: MAVLink units (mV per cell, cA,
        mAh, hJ, %), cells balanced; cells beyond the pack UINT16_MAX as the message asks."""
        n = self.series
        cell_mv = max(0, min(65534, int(round(self.voltage / n * 1000))))
        cells = [cell_mv] * min(n, 10) + self._unused
        ext = [cell_mv if k < n - 10 else 0 for k in range(4)]
        state = (M.MAV_BATTERY_CHARGE_STATE_EMERGENCY if self.depleted else M.MAV_BATTERY_CHARGE_STATE_OK)
        return dict(id=0, battery_function=M.MAV_BATTERY_FUNCTION_ALL, type=M.MAV_BATTERY_TYPE_LION,
                    temperature=32767, voltages=cells, current_battery=max(-32768, min(32767, int(round(
                        self.current * 100)))), current_consumed=int(round(self.consumed_mah)),
                    energy_consumed=int(round(self.energy_j / 100.0)),
                    battery_remaining=int(math.floor(self.soc * 100.0 + 1e-9)),
                    time_remaining=self.time_remaining(), charge_state=state, voltages_ext=ext)

    def time_remaining(self) -> int:
        """Seconds until empty at the present current (0: not known, as BATTERY_STATUS has it)."""
        if self.current < 0.1:
            return 0
        return min(2**31 - 1, int(self.soc * self.capacity_c / self.current))
