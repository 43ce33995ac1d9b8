"""Assembly of the simulator: its parts built from a configuration, the scenario's world and traffic.

`hil sim` (and through it every `hil run`) calls :func:`scenario_world` and :func:`build_simulator`;
the command module parses options, handles signals and runs the loop, as `hil autopilot` does with
:func:`hil.assembly.computer.build`. The HIL configuration is mapped once onto the simulator's own
root (:func:`simulator_settings`, a :class:`simulator.config.SimulatorSettings`), as the vessel
computer's is onto :class:`autopilot_bridge.assembly.ComputerSettings`.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import TYPE_CHECKING

from hil.errors import ConfigError, UsageError

if TYPE_CHECKING:
    from common.udp import UdpEndpoint
    from hil.settings import HilConfig
    from simulator.config import SimulatorSettings
    from simulator.esc import EscBank
    from simulator.rangefinder import WorldMap
    from simulator.server import SimulatorServer
    from simulator.traffic import ShipSpec


def simulator_settings(cfg: HilConfig) -> SimulatorSettings:
    """The root of the simulator's configuration from the HIL configuration: its own sections, and the
    vessel computer's MAVLink ids (the one peer whose commands it applies)."""
    from simulator.config import PeerIds, SimulatorSettings

    return SimulatorSettings(vessel=cfg.vessel, waves=cfg.waves, current=cfg.current, sensors=cfg.sensors,
                             sim=cfg.sim, link=cfg.link, geodesy=cfg.geodesy, esc=cfg.esc, can=cfg.can,
                             traffic=cfg.traffic, battery=cfg.battery,
                             computer=PeerIds(cfg.autopilot.system_id, cfg.autopilot.component_id))


@dataclass(frozen=True)
class ScenarioWorld:
    """What a fixed scenario gives the simulator: ``--set`` overrides that put the vessel at the
    scenario's start in its current, the true obstacles for the range sensor, and the ships."""

    overrides: list[str]
    world: WorldMap
    traffic: tuple[ShipSpec, ...]


def scenario_world(name: str, base: HilConfig) -> ScenarioWorld:
    """The simulator's share of scenario ``name`` under the user's configuration ``base``
    (UsageError for a random scenario: it draws a map per run)."""
    from hil import scenario as scenarios
    from simulator.rangefinder import WorldMap

    spec = scenarios.load_spec(name)
    if spec.kind != "fixed":
        raise UsageError(f"--scenario {name}: draws a new map per run; hil sim needs a fixed scenario")
    scen = scenarios.instance(spec, None, base.current, geodesy=base.geodesy)
    return ScenarioWorld(scenarios.simulator_overrides(scen, base.current),
                         WorldMap(scen.truth_occ(), scen.resolution), tuple(scen.traffic))


@dataclass
class SimulatorParts:
    """The simulator built: the server that runs the loop, and the sockets and bus it owns."""

    server: SimulatorServer
    endpoint: UdpEndpoint
    esc: EscBank | None = None

    def close(self, can_record: str | None = None) -> None:
        """Close the command socket and the CAN bus; save the RawCommand apply times to ``can_record``."""
        self.endpoint.close()
        if self.esc is not None:
            self.esc.bus.shutdown()
            if can_record:
                self.esc.applied_times.save(can_record)


def build_simulator(cfg: HilConfig, world: WorldMap | None, traffic: tuple[ShipSpec, ...],
                    command_source: str | None = None, can_record: str | None = None,
                    progress: Callable[[str], None] = lambda _m: None) -> SimulatorParts:
    """The simulator's truth (vessel, waves, current, ships, sensors), its UDP endpoint, its ESCs on
    CAN when ``can.actuators = "can"``, and the server that runs them; one-line errors
    (ConfigError, UsageError) for what the configuration cannot give, nothing left open."""
    from common.udp import UdpEndpoint
    from simulator.core import SimulatorCore
    from simulator.server import SimulatorServer

    settings = simulator_settings(cfg)
    try:
        core = SimulatorCore(settings, world, traffic)
        check_covers = getattr(core.current, "check_covers", None)   # a current file: its time span
        if check_covers is not None and settings.sim.duration > 0:
            check_covers(t=(0.0, settings.sim.duration))
    except ValueError as exc:
        raise ConfigError(str(exc)) from None
    # The parts of common/ first (the socket, the CAN bus), then the devices built on them.
    try:
        endpoint = UdpEndpoint(settings.link.commands_on, settings.link.state_to)
    except ValueError as exc:
        raise UsageError(str(exc)) from None
    esc: EscBank | None = None
    try:
        if settings.can.actuators == "can":
            from common.can_params import kernel_filters, open_bus
            from simulator.esc import EscBank

            can = settings.can
            bus = open_bus(can, can_filters=kernel_filters(can, from_node=can.autopilot_node_id))
            esc = EscBank(bus, can, settings.esc, core.vessel)
            if can_record:
                esc.applied_times.start(spill_to=can_record)
        server = SimulatorServer(core, endpoint, lockstep=settings.sim.lockstep, duration=settings.sim.duration,
                                 speedup=settings.sim.speedup, lockstep_resend=settings.sim.lockstep_resend,
                                 progress=progress, esc=esc, can_lockstep_wait=settings.can.lockstep_wait,
                                 command_source=command_source, busy_poll=settings.sim.lockstep_busy_poll,
                                 pipeline=settings.sim.lockstep_pipeline)
    except ValueError as exc:
        endpoint.close()
        if esc is not None:
            esc.bus.shutdown()
        raise UsageError(str(exc)) from None
    return SimulatorParts(server, endpoint, esc)
